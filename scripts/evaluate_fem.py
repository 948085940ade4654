#!/usr/bin/python3
"""Accuracy and speed of the FEM integrators on the metal frames (issue 15; docs/scenes.md, docs/metrics.md).

For each scene it runs `pnet simulate` with
  gt                       explicit, dt = 1e-5 s (the ground truth)
  explicit_2e-5            explicit at 2e-5 s (the noise floor: ground truth against itself)
  explicit_cfl             explicit at its CFL step (the elements' wave speed)
  analytic_1e-2            the closed-form ECI energy (StVK-Hencky + von Mises only)
  plasticitynet_1e-2, plasticitynet_1e-3, lagged_1e-2
  plasticitynet_1e-2_w0    the regularizer off (w = 0; paper Fig. 12), metal_frame_2d, 30 frames
  plasticitynet_1e-2_exact_rm   metal_nh_frame_2d with the material's exact root-find return
                           mapping instead of the learned one the model ships
and compares every frame's deformable nodes with the ground truth (and the implicit runs with
analytic_1e-2, or on metal_nh_frame_2d with plasticitynet_1e-2_exact_rm): mean and max nodal
distance, m and % of the scene's bounding-box diagonal.

Outputs (under --results, default notebooks/results/fem_eval):
  summary.csv, summary.md            per scene and run: dt, s/frame, Newton and fixed-point solves
                                     per step, error at the last frame and worst over frames
  <scene>/nodal_error.csv, .png      per frame and run: mean / max distance to the ground truth
  <scene>/<run>_final.png, <run>_stats.csv
Runs stay in --work (default out/fem_eval) and are reused while the command and scene are the
same (--force re-runs them). Timings: the runs' own wall clock (stats.csv); take speed ratios
from bench_table1, measured on a quiet machine in one run.

    /usr/bin/python3 scripts/evaluate_fem.py [--scenes metal_frame_2d metal_nh_frame_2d]
        [--runs gt plasticitynet_1e-2 ...] [--frames N] [--threads 2] [--force]
"""
import argparse
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "scripts"))
from evaluate_implicit import read_csv, run_dir_complete, run_marker  # noqa: E402
from plasticitynet.mesh_ply import read_mesh_ply  # noqa: E402

PNET = ROOT / "build" / "cpp" / "pnet"
SCENES = ["metal_frame_2d", "metal_nh_frame_2d", "metal_frame_3d"]

# name: (integrator, dt, extra options, scenes it applies to (None: all))
# The regularizer ablation runs the first FRAMES_CAP frames only (w = 0 took ~10x the solves:
# 11.7 s/frame against 1.3 at 1 thread).
FRAMES_CAP = {"plasticitynet_1e-2_w0": 30}
RUNS = {
    "gt": ("explicit", 1e-5, [], None),
    "explicit_2e-5": ("explicit", 2e-5, [], None),
    "explicit_cfl": ("explicit", 0.0, [], None),
    "analytic_1e-2": ("analytic", 1e-2, [], {"metal_frame_2d", "metal_frame_3d"}),
    "plasticitynet_1e-2": ("plasticitynet", 1e-2, [], None),
    "plasticitynet_1e-3": ("plasticitynet", 1e-3, [], None),
    "lagged_1e-2": ("lagged", 1e-2, [], None),
    "plasticitynet_1e-2_w0": ("plasticitynet", 1e-2, ["--regularizer", "0"], {"metal_frame_2d"}),
    "plasticitynet_1e-2_exact_rm": ("plasticitynet", 1e-2, ["--return-map", "exact"], {"metal_nh_frame_2d"}),
    # BDF2 (issue 34) beside the backward-Euler runs above.
    "plasticitynet_1e-2_bdf2": ("plasticitynet", 1e-2, ["--time-integrator", "bdf2"], None),
    "analytic_1e-2_bdf2": ("analytic", 1e-2, ["--time-integrator", "bdf2"], {"metal_frame_2d", "metal_frame_3d"}),
    "lagged_1e-2_bdf2": ("lagged", 1e-2, ["--time-integrator", "bdf2"], None),
}
# The same-dt reference each implicit run is also compared with.
REFERENCE = {"metal_frame_2d": "analytic_1e-2", "metal_nh_frame_2d": "plasticitynet_1e-2_exact_rm",
             "metal_frame_3d": "analytic_1e-2"}


def simulate(scene: str, name: str, frames: int, threads: int, work: Path, force: bool) -> Path:
    integrator, dt, extra, _ = RUNS[name]
    frames = min(frames, FRAMES_CAP.get(name, frames))
    out = work / scene / name
    command = [str(PNET), "simulate", str(ROOT / "scenes" / f"{scene}.json"), "--integrator", integrator,
               "--dt", repr(dt), "--frames", str(frames), "--threads", str(threads), "--out", str(out)] + extra
    marker = run_marker(scene, command, integrator == "explicit")
    failed_before = (out / "failed.txt").exists() and (out / "command.json").exists() and all(
        json.loads((out / "command.json").read_text()).get(k) == marker[k] for k in ("command", "scene_sha256"))
    if not force and (run_dir_complete(out, marker, frames) or failed_before):
        print(f"[{scene}/{name}] reusing {out}{' (a run that failed)' if failed_before else ''}", flush=True)
        return out
    if out.exists():
        shutil.rmtree(out)
    print(f"[{scene}/{name}] " + " ".join(command), flush=True)
    result = subprocess.run(command)
    if result.returncode != 0:
        print(f"[{scene}/{name}] pnet simulate exited with {result.returncode}; the frames it wrote are compared",
              flush=True)
        (out / "failed.txt").write_text(f"exit status {result.returncode}\n")
    (out / "command.json").write_text(json.dumps(marker))
    return out


def frames_of(run: Path) -> list:
    return sorted(int(p.stem.split("_")[1]) for p in run.glob("frame_*.ply"))


def nodal_distance(a: Path, b: Path, frame: int, nodes: int) -> tuple:
    pa = read_mesh_ply(a / f"frame_{frame:05d}.ply").position[:nodes]
    pb = read_mesh_ply(b / f"frame_{frame:05d}.ply").position[:nodes]
    d = ((pa - pb) ** 2).sum(axis=1) ** 0.5
    return float(d.mean()), float(d.max())


def run_figures(run: Path) -> dict:
    frames = read_csv(run / "stats.csv") if (run / "stats.csv").exists() else []
    steps = read_csv(run / "steps.csv") if (run / "steps.csv").exists() else []
    n = max(len(steps), 1)
    mean = lambda key: sum(float(s[key]) for s in steps) / n
    return {
        "frames": len(frames),
        "seconds_per_frame": sum(float(f["wall_s"]) for f in frames) / max(len(frames), 1),
        "steps_per_frame": len(steps) / max(len(frames), 1),
        "newton_per_step": mean("newton_iterations") if steps else 0.0,
        "solves_per_step": mean("fixed_point_iterations") if steps else 0.0,
        "kinematic_stages_per_step": mean("kinematic_stages") if steps else 0.0,
        "unconverged_steps": sum(1 for s in steps if s["converged"] == "0"),
        "min_contact_distance_m": min((float(f["min_distance_m"]) for f in frames), default=float("nan")),
        "failed": (run / "failed.txt").exists(),
    }


def plot(scene: str, curves: dict, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), dpi=100)
    for name, rows in curves.items():
        t = [r["time_s"] for r in rows]
        axes[0].plot(t, [r["mean_pct"] for r in rows], label=name)
        axes[1].plot(t, [r["max_pct"] for r in rows], label=name)
    for ax, what in zip(axes, ("mean", "max")):
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{what} nodal distance to explicit 1e-5 (% of diagonal)")
        ax.grid(alpha=0.3)
    axes[0].axhline(0.5, color="grey", linestyle=":", linewidth=1)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{scene}: nodal error against the ground truth")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", default=SCENES, choices=SCENES)
    parser.add_argument("--runs", nargs="+", default=list(RUNS), choices=list(RUNS))
    parser.add_argument("--frames", type=int, default=0, help="frames (0: the scene's)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "fem_eval")
    parser.add_argument("--results", type=Path, default=ROOT / "notebooks" / "results" / "fem_eval")
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args()
    if not PNET.exists():
        sys.exit(f"{PNET} not found: build first (./scripts/setup.sh)")
    summary = []
    for scene in args.scenes:
        scene_json = json.loads((ROOT / "scenes" / f"{scene}.json").read_text())
        frames = args.frames or scene_json["frames"]
        runs = {}
        for name in args.runs:
            if RUNS[name][3] is None or scene in RUNS[name][3]:
                runs[name] = simulate(scene, name, frames, args.threads, args.work, args.force)
        if "gt" not in runs:
            runs["gt"] = args.work / scene / "gt"
        gt = runs["gt"]
        info = json.loads((gt / "run.json").read_text())
        nodes, diagonal = info["mesh_first_node"][1], info["bbox_diagonal"]  # meshes[0]: the frame
        reference = runs.get(REFERENCE[scene])
        results = args.results / scene
        results.mkdir(parents=True, exist_ok=True)
        curves, rows = {}, []
        for name, run in runs.items():
            figures = run_figures(run)
            common = [f for f in frames_of(run) if f > 0 and (gt / f"frame_{f:05d}.ply").exists()]
            curve = []
            for f in common:
                mean, worst = nodal_distance(run, gt, f, nodes) if name != "gt" else (0.0, 0.0)
                curve.append({"frame": f, "time_s": f * scene_json["frame_dt"], "mean_m": mean, "max_m": worst,
                              "mean_pct": 100 * mean / diagonal, "max_pct": 100 * worst / diagonal})
            if name != "gt":
                curves[name] = curve
            row = {"scene": scene, "run": name, "integrator": RUNS[name][0], "dt": RUNS[name][1], **figures}
            if curve:
                row["final_mean_pct"], row["final_max_pct"] = curve[-1]["mean_pct"], curve[-1]["max_pct"]
                row["worst_mean_pct"] = max(c["mean_pct"] for c in curve)
                row["last_frame"] = curve[-1]["frame"]
            if reference is not None and name not in ("gt", REFERENCE[scene]) and RUNS[name][0] != "explicit":
                last = min(frames_of(run)[-1], frames_of(reference)[-1])
                mean, worst = nodal_distance(run, reference, last, nodes)
                row["ref_mean_pct"], row["ref_max_pct"] = 100 * mean / diagonal, 100 * worst / diagonal
            rows.append(row)
            if figures["frames"] > 0 and name != "gt":
                final = sorted(run.glob("frame_*.png"))[-1]
                shutil.copyfile(final, results / f"{name}_final.png")
            if (run / "stats.csv").exists():
                shutil.copyfile(run / "stats.csv", results / f"{name}_stats.csv")
        with open(results / "nodal_error.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["run", "frame", "time_s", "mean_m", "max_m", "mean_pct_diagonal", "max_pct_diagonal"])
            for name, curve in curves.items():
                for c in curve:
                    w.writerow([name, c["frame"], c["time_s"], f"{c['mean_m']:.6g}", f"{c['max_m']:.6g}",
                                f"{c['mean_pct']:.5f}", f"{c['max_pct']:.5f}"])
        plot(scene, curves, results / "nodal_error.png")
        summary += rows
    write_summary(args.results, summary)
    return 0


def write_summary(results: Path, rows: list):
    # Keep the rows of runs not made this time (other scenes, or runs left out with --runs).
    path = results / "summary.csv"
    made = {(row["scene"], row["run"]) for row in rows}
    old = [r for r in read_csv(path) if (r["scene"], r["run"]) not in made] if path.exists() else []
    keys = ["scene", "run", "integrator", "dt", "frames", "failed", "seconds_per_frame", "steps_per_frame",
            "newton_per_step", "solves_per_step", "kinematic_stages_per_step", "unconverged_steps",
            "min_contact_distance_m", "last_frame", "final_mean_pct", "final_max_pct", "worst_mean_pct",
            "ref_mean_pct", "ref_max_pct"]
    all_rows = old + rows
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, keys, extrasaction="ignore")
        w.writeheader()
        for r in all_rows:
            w.writerow({k: (f"{r[k]:.5g}" if isinstance(r.get(k), float) else r.get(k, "")) for k in keys})
    fmt = lambda r, k, spec=".3f": ("-" if r.get(k) in (None, "") else format(float(r[k]), spec))
    lines = ["| scene | run | dt (s) | frames | s/frame | Newton/step | solves/step | unconverged | "
             "mean / max nodal error at the last frame (% diag) | worst mean over frames (% diag) | "
             "to the same-dt reference, mean / max (% diag) | min contact distance (m) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in all_rows:
        failed = str(r.get("failed")) in ("True", "1")
        lines.append(f"| {r['scene']} | {r['run']} | {float(r['dt']):g}{' (CFL)' if float(r['dt']) == 0 else ''} | "
                     f"{r['frames']}{' (failed)' if failed else ''} | {fmt(r, 'seconds_per_frame')} | "
                     f"{fmt(r, 'newton_per_step', '.1f')} | {fmt(r, 'solves_per_step', '.1f')} | "
                     f"{r.get('unconverged_steps', '')} | {fmt(r, 'final_mean_pct', '.4f')} / "
                     f"{fmt(r, 'final_max_pct', '.4f')} | {fmt(r, 'worst_mean_pct', '.4f')} | "
                     f"{fmt(r, 'ref_mean_pct', '.4f')} / {fmt(r, 'ref_max_pct', '.4f')} | "
                     f"{fmt(r, 'min_contact_distance_m', '.3g')} |")
    (results / "summary.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
