"""Comparing a run with its ground truth (docs/metrics.md), one JSON per comparison.

Every figure comes from `pnet compare` (cpp/pnet/metrics/: the same code for every family):
  mpm       iou.csv: per frame soft IoU of the B-spline mass fields at dx and 4 dx, binary IoU, the
            deposit's spread and height (of the last common frame)
  fem       nodal.csv: per frame mean and max nodal distance of the deformable mesh, m and % of the
            scene's bounding-box diagonal; and the distance to a same-step reference at the last common frame
  coupling  the sand as mpm, the body's nodal distance (% of its rest size), and the particles inside
            the body (crossing number in 2D, winding number in 3D; must be 0)

Every metric also carries the run's own figures: seconds per frame, steps, Newton, line-search,
fixed-point and CG iterations per step, unconverged steps (stats.csv, steps.csv).
"""
from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import numpy as np

from .plan import Plan


def read_csv(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path) as f:
        return list(csv.DictReader(f))


def run_figures(run: Path) -> dict:
    """A run's cost and solver figures from its stats.csv (per frame) and steps.csv (per step)."""
    frames = read_csv(run / "frames" / "stats.csv")
    steps = read_csv(run / "frames" / "steps.csv")
    n = max(len(steps), 1)

    def mean(key):
        return sum(float(s[key]) for s in steps) / n if steps and key in steps[0] else 0.0

    def total(key):
        return sum(float(s[key]) for s in steps) if steps and key in steps[0] else 0.0

    wall = total("wall_s")
    done = json.loads((run / "done.json").read_text()) if (run / "done.json").exists() else {}
    return {
        "frames": len(frames),
        "failed": bool(done.get("failed", False)),
        "seconds_per_frame": sum(float(f["wall_s"]) for f in frames) / max(len(frames), 1),
        "steps_per_frame": len(steps) / max(len(frames), 1),
        "newton_per_step": mean("newton_iterations"),
        "cg_per_step": mean("cg_iterations"),
        "fixed_point_per_step": mean("fixed_point_iterations"),
        "line_search_per_step": mean("line_search_steps"),
        "kinematic_stages_per_step": mean("kinematic_stages"),
        "energy_seconds_share": total("energy_s") / wall if wall > 0 else 0.0,
        "cg_seconds_share": total("cg_s") / wall if wall > 0 else 0.0,
        "unconverged_steps": sum(1 for s in steps if s.get("converged") == "0"),
        "min_contact_distance_m": min((float(f["min_distance_m"]) for f in frames if "min_distance_m" in f),
                                      default=float("nan")),
    }


def pnet_compare(plan: Plan, gt: Path, run: Path, out: Path, dx: float | None = None) -> dict[str, list[dict]]:
    """`pnet compare`'s per-frame rows of a run against the ground truth: "iou" (iou.csv: particles) and
    "nodal" (nodal.csv: the meshes' body), each empty where the runs have none."""
    cmd = [plan.pnet, "compare", str(gt / "frames"), str(run / "frames"), "--out", str(out)]
    if dx is not None:
        cmd += ["--dx", repr(dx)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed (exit {done.returncode}):\n{done.stderr}")
    return {name: [{k: float(v) for k, v in row.items()} for row in read_csv(out / f"{name}.csv")]
            for name in ("iou", "nodal")}


def mpm_metric(plan: Plan, gt: Path, run: Path, dx: float, compare_dir: Path) -> dict:
    rows = pnet_compare(plan, gt, run, compare_dir, dx)["iou"]
    out = {"rows": rows}
    if rows:
        soft = [r["soft_iou"] for r in rows]
        coarse = [r["soft_iou_coarse"] for r in rows]
        binary = [r["binary_iou"] for r in rows]
        last = rows[-1]  # the deposit at the last common frame
        out.update({"soft_iou_min": min(soft), "soft_iou_mean": sum(soft) / len(soft),
                    "binary_iou_min": min(binary), "binary_iou_mean": sum(binary) / len(binary),
                    "soft_iou_coarse_min": min(coarse), "soft_iou_coarse_mean": sum(coarse) / len(coarse),
                    "spread_m": last["spread_b_m"], "spread_gt_m": last["spread_a_m"],
                    "spread_error": last["spread_b_m"] / last["spread_a_m"] - 1.0,
                    "height_m": last["height_b_m"], "height_gt_m": last["height_a_m"],
                    "height_error": last["height_b_m"] / last["height_a_m"] - 1.0,
                    "compared_frames": len(rows)})
    return out


def fem_metric(plan: Plan, gt: Path, run: Path, reference: Path | None, frame_dt: float, compare_dir: Path) -> dict:
    nodal = [r for r in pnet_compare(plan, gt, run, compare_dir)["nodal"] if r["frame"] > 0]
    diagonal = json.loads((gt / "frames" / "run.json").read_text())["bbox_diagonal"]
    curve = [{"frame": int(r["frame"]), "time_s": r["frame"] * frame_dt, "mean_m": r["mean_m"], "max_m": r["max_m"],
              "mean_pct": r["mean_pct"], "max_pct": r["max_pct"]} for r in nodal]
    out = {"curve": curve, "diagonal_m": diagonal}
    if curve:
        out.update({"final_mean_pct": curve[-1]["mean_pct"], "final_max_pct": curve[-1]["max_pct"],
                    "worst_mean_pct": max(c["mean_pct"] for c in curve), "last_frame": curve[-1]["frame"]})
    if reference is not None:
        # The same-step reference at the last frame both have; its size is the ground truth's (run.json).
        to_reference = pnet_compare(plan, reference, run, compare_dir / "reference")["nodal"]
        if to_reference:
            last = to_reference[-1]
            out["ref_mean_pct"], out["ref_max_pct"] = 100 * last["mean_m"] / diagonal, 100 * last["max_m"] / diagonal
    return out


def coupling_metric(plan: Plan, gt: Path, run: Path, frame_dt: float, compare_dir: Path) -> dict:
    compared = pnet_compare(plan, gt, run, compare_dir)
    sand = {int(r["frame"]): r for r in compared["iou"]}
    body = [r for r in compared["nodal"] if r["frame"] > 0]
    size = body[0]["size_m"] if body else float("nan")
    rows = []
    for r in body:
        f = int(r["frame"])
        j = sand.get(f, {"soft_iou": 1.0, "soft_iou_coarse": 1.0})
        rows.append({"frame": f, "time_s": f * frame_dt, "jaccard": j["soft_iou"], "jaccard_4dx": j["soft_iou_coarse"],
                     "disk_mean_m": r["mean_m"], "disk_max_m": r["max_m"], "disk_mean_pct": r["mean_pct"],
                     "disk_max_pct": r["max_pct"], "penetrations": int(r["penetrations"])})
    out = {"rows": rows, "body_size_m": size}
    if rows:
        out.update({"jaccard_min": min(r["jaccard"] for r in rows),
                    "jaccard_mean": float(np.mean([r["jaccard"] for r in rows])),
                    "jaccard_4dx_min": min(r["jaccard_4dx"] for r in rows),
                    "jaccard_4dx_mean": float(np.mean([r["jaccard_4dx"] for r in rows])),
                    "disk_mean_pct_last": rows[-1]["disk_mean_pct"],
                    "disk_mean_pct_worst": max(r["disk_mean_pct"] for r in rows),
                    "disk_max_pct_worst": max(r["disk_max_pct"] for r in rows),
                    "penetrations": max(r["penetrations"] for r in rows), "compared_frames": len(rows)})
    return out


def compute(plan: Plan, key: str) -> Path:
    """Writes the metric plan.metrics[key] to its JSON file (atomically) and returns the path."""
    job = plan.metrics[key]
    run, gt = plan.run_dir(job.run_key), plan.run_dir(job.gt_key)
    content = plan.runs[job.run_key].scene_content
    frame_dt = float(content.get("frame_dt", 0.02))
    compare_dir = plan.compare_dir(key)  # pnet compare's iou.csv and iou.png
    if job.family == "mpm":
        values = mpm_metric(plan, gt, run, float(content["dx"]), compare_dir)
    elif job.family == "fem":
        reference = plan.run_dir(job.reference_key) if job.reference_key else None
        values = fem_metric(plan, gt, run, reference, frame_dt, compare_dir)
    else:
        values = coupling_metric(plan, gt, run, frame_dt, compare_dir)
    values.update({"scene": job.scene, "run": job.run, "run_key": job.run_key, "gt_key": job.gt_key,
                   "reference_key": job.reference_key, "figures": run_figures(run)})
    path = plan.metric_file(key)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(values, indent=1))
    tmp.replace(path)
    return path
