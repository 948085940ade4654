#!/usr/bin/python3
"""Accuracy and speed of MPM-FEM coupling on sand_fem_coupling_2d or _3d (issues 18, 33; docs/methods.md,
docs/metrics.md).

Runs `pnet simulate scenes/sand_fem_coupling_2d.json` (or --scene sand_fem_coupling_3d) with
  explicit_1e-6        explicit coupling at 1e-6 s (the paper's step: the ground truth; in 3D
                       explicit_1e-5, the sphere's 2 cm elements being stable at 1e-5 s)
  explicit_cfl         explicit coupling at its CFL step (the stiff disk's elements: the noise floor)
  plasticitynet_1e-3   the sand's learned energy, one optimization with the disk (the paper)
  lagged_1e-3          the sand's elastic energy in the solve, Drucker-Prager after it (the baseline)
and compares every frame with the ground truth:
  sand      Jaccard index of the particles' mass fields at the grid's dx and at 4 dx (`pnet compare`)
  disk      mean and max nodal distance, m and % of the disk's size (its bounding-box diagonal at rest)
  contact   particles inside the disk (crossing number against its boundary edges; in 3D the
            winding number of its boundary triangles): must be 0
and reports seconds per frame from each run's stats.csv (timings for ratios: bench_table1).

Outputs (under --results, default notebooks/results/coupling_eval, coupling_eval_3d in 3D): summary.md, summary.csv,
per_frame.csv (every run and frame), iou_<run>.png (pnet compare's curves), <run>_final.png.
Runs stay in --work (default out/coupling, out/coupling_3d in 3D) and are reused when complete (--force re-runs them); a
run that is still going (or stopped early) is evaluated over the frames it has.

    /usr/bin/python3 scripts/evaluate_coupling.py [--scene sand_fem_coupling_3d] [--runs ...] [--frames N]
        [--threads 1] [--force]
"""
import argparse
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))
from plasticitynet.mesh_ply import read_mesh_ply  # noqa: E402

PNET = ROOT / "build" / "cpp" / "pnet"
SCENE = ROOT / "scenes" / "sand_fem_coupling_2d.json"  # --scene
GT = "explicit_1e-6"  # explicit_1e-5 in 3D
RUNS = {  # name: (integrator, dt)
    "explicit_1e-6": ("explicit", 1e-6),
    "explicit_cfl": ("explicit", 0.0),
    "plasticitynet_1e-3": ("plasticitynet", 1e-3),
    "lagged_1e-3": ("lagged", 1e-3),
}
RUN_NAMES = ["ground_truth", "explicit_cfl", "plasticitynet_1e-3", "lagged_1e-3"]


def use_scene(name: str) -> None:
    """Points SCENE, GT and RUNS at scenes/<name>.json: the 3D scene's ground truth is explicit at 1e-5 s."""
    global SCENE, GT
    SCENE = ROOT / "scenes" / f"{name}.json"
    if not SCENE.exists():
        sys.exit(f"{SCENE}: no such scene")
    if json.loads(SCENE.read_text())["dim"] == 3:
        del RUNS["explicit_1e-6"]
        GT = "explicit_1e-5"
        RUNS[GT] = ("explicit", 1e-5)


def frames_of(run: Path) -> list:
    return sorted(int(p.stem.split("_")[1]) for p in run.glob("frame_*_mesh.ply"))


def simulate(name: str, frames: int, threads: int, work: Path, force: bool) -> Path:
    out = work / name
    if out.exists() and not force and len(frames_of(out)) >= frames + 1:
        return out
    if out.exists() and not force and (out / "run.json").exists():
        print(f"{name}: {len(frames_of(out)) - 1} of {frames} frames present (still running or stopped): "
              f"evaluated as it is; --force re-runs it")
        return out
    integrator, dt = RUNS[name]
    command = [str(PNET), "simulate", str(SCENE), "--integrator", integrator, "--dt", repr(dt), "--frames",
               str(frames), "--threads", str(threads), "--out", str(out)]
    print(" ".join(command), flush=True)
    if out.exists():
        shutil.rmtree(out)
    if subprocess.run(command).returncode != 0:
        print(f"{name}: pnet simulate failed; evaluating the frames it wrote")
    return out


def read_particle_positions(path: Path) -> np.ndarray:
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    count = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    properties = [line.split()[-1] for line in header if line.startswith("property")]
    record = np.frombuffer(data, dtype=np.dtype([(p, "<f8") for p in properties]), count=count, offset=end)
    return np.stack([record[axis] for axis in ("x", "y", "z") if axis in record.dtype.names], axis=1)


def boundary_edges(triangles: np.ndarray) -> np.ndarray:
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    key = np.sort(edges, axis=1)
    _, index, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return edges[index[counts == 1]]


def inside_count(points: np.ndarray, nodes: np.ndarray, edges: np.ndarray) -> int:
    """Points inside (or on) the region the closed boundary `edges` bounds: crossing number."""
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    near = points[np.all((points >= lo) & (points <= hi), axis=1)]
    if len(near) == 0:
        return 0
    a, b = nodes[edges[:, 0]], nodes[edges[:, 1]]
    px, py = near[:, None, 0], near[:, None, 1]
    straddle = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
    crossings = np.sum(straddle & (px < xc), axis=1)
    return int(np.sum(crossings % 2 == 1))


def inside_count_3d(points: np.ndarray, nodes: np.ndarray, triangles: np.ndarray) -> int:
    """Points inside the closed surface `triangles`: generalized winding number (solid angles / 4 pi) above 1/2."""
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    near = points[np.all((points >= lo) & (points <= hi), axis=1)]
    if len(near) == 0:
        return 0
    a = nodes[triangles[:, 0]][None] - near[:, None]
    b = nodes[triangles[:, 1]][None] - near[:, None]
    c = nodes[triangles[:, 2]][None] - near[:, None]
    la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
    numerator = np.einsum("pti,pti->pt", a, np.cross(b, c))
    denominator = (la * lb * lc + np.einsum("pti,pti->pt", a, b) * lc + np.einsum("pti,pti->pt", a, c) * lb
                   + np.einsum("pti,pti->pt", b, c) * la)
    winding = np.abs(np.sum(2.0 * np.arctan2(numerator, denominator), axis=1)) / (4.0 * np.pi)
    return int(np.sum(winding > 0.5))


def compare_sand(run: Path, gt: Path, out: Path) -> dict:
    """Per-frame Jaccard at dx and 4 dx from `pnet compare` (frame: (J, J_4dx))."""
    out.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([str(PNET), "compare", str(gt), str(run), "--out", str(out)], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"pnet compare {gt} {run} failed:\n{r.stderr}")
    with open(out / "iou.csv") as f:
        return {int(row["frame"]): (float(row["soft_iou"]), float(row["soft_iou_coarse"])) for row in csv.DictReader(f)}


def seconds_per_frame(run: Path) -> float:
    with open(run / "stats.csv") as f:
        rows = list(csv.DictReader(f))
    return sum(float(r["wall_s"]) for r in rows) / max(len(rows), 1)


def main() -> int:
    global PNET
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="sand_fem_coupling_2d", help="sand_fem_coupling_2d or sand_fem_coupling_3d")
    parser.add_argument("--runs", nargs="+", choices=RUN_NAMES, help="ground_truth (explicit_1e-6, 3D: explicit_1e-5), "
                        "explicit_cfl, plasticitynet_1e-3, lagged_1e-3 (default: all)")
    parser.add_argument("--frames", type=int, default=0, help="frames (0: the scene's)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--work", type=Path, help="default out/coupling (3D: out/coupling_3d)")
    parser.add_argument("--results", type=Path,
                        help="default notebooks/results/coupling_eval (3D: notebooks/results/coupling_eval_3d)")
    parser.add_argument("--force", action="store_true")
    parser.add_argument("--pnet", type=Path, default=PNET, help="the pnet binary (default: the build's; a copy lets "
                        "the build change while the runs go on)")
    args = parser.parse_args()
    PNET = args.pnet
    if not PNET.exists():
        sys.exit(f"{PNET} not found: build first (./scripts/setup.sh)")
    use_scene(args.scene)
    dim = json.loads(SCENE.read_text())["dim"]
    suffix = "_3d" if dim == 3 else ""
    args.work = args.work or ROOT / "out" / f"coupling{suffix}"
    args.results = args.results or ROOT / "notebooks" / "results" / f"coupling_eval{suffix}"
    names = [GT if name == "ground_truth" else name for name in (args.runs or RUN_NAMES)]
    frames = args.frames or json.loads(SCENE.read_text())["frames"]
    runs = {name: simulate(name, frames, args.threads, args.work, args.force) for name in names}
    gt = runs.get(GT, args.work / GT)
    gt_frames = set(frames_of(gt))
    rest = read_mesh_ply(gt / "frame_00000_mesh.ply")
    size = float(np.linalg.norm(rest.position.max(axis=0) - rest.position.min(axis=0)))
    edges = boundary_edges(rest.triangles) if dim == 2 else rest.triangles  # a 3D mesh PLY holds its surface
    args.results.mkdir(parents=True, exist_ok=True)
    per_frame, summary = [], []
    for name, run in runs.items():
        common = [f for f in frames_of(run) if f in gt_frames and f > 0]
        if not common:
            print(f"{name}: no frame in common with the ground truth yet")
            continue
        sand = compare_sand(run, gt, args.work / "compare" / name) if name != GT else {}
        if name != GT and (args.work / "compare" / name / "iou.png").exists():
            shutil.copyfile(args.work / "compare" / name / "iou.png", args.results / f"iou_{name}.png")
        worst_penetrations = 0
        rows = []
        for f in common:
            mesh = read_mesh_ply(run / f"frame_{f:05d}_mesh.ply")
            particles = read_particle_positions(run / f"frame_{f:05d}.ply")
            penetrations = (inside_count(particles, mesh.position, edges) if dim == 2
                            else inside_count_3d(particles, mesh.position, edges))
            worst_penetrations = max(worst_penetrations, penetrations)
            d = np.linalg.norm(mesh.position - read_mesh_ply(gt / f"frame_{f:05d}_mesh.ply").position, axis=1)
            j, j4 = sand.get(f, (1.0, 1.0))
            rows.append({"run": name, "frame": f, "jaccard": j, "jaccard_4dx": j4, "disk_mean_m": d.mean(),
                         "disk_max_m": d.max(), "disk_mean_pct": 100 * d.mean() / size,
                         "disk_max_pct": 100 * d.max() / size, "penetrations": penetrations})
        per_frame += rows
        summary.append({
            "run": name, "integrator": RUNS[name][0], "dt": RUNS[name][1], "frames": len(common),
            "s_per_frame": seconds_per_frame(run),
            "jaccard_min": min(r["jaccard"] for r in rows), "jaccard_mean": np.mean([r["jaccard"] for r in rows]),
            "jaccard_4dx_min": min(r["jaccard_4dx"] for r in rows),
            "jaccard_4dx_mean": np.mean([r["jaccard_4dx"] for r in rows]),
            "disk_mean_pct_last": rows[-1]["disk_mean_pct"], "disk_mean_pct_worst": max(r["disk_mean_pct"] for r in rows),
            "disk_max_pct_worst": max(r["disk_max_pct"] for r in rows), "penetrations": worst_penetrations})
        finals = sorted(run.glob("frame_*.png"))
        if finals:
            shutil.copyfile(finals[-1], args.results / f"{name}_final.png")
    with open(args.results / "per_frame.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(per_frame[0]))
        w.writeheader()
        w.writerows(per_frame)
    with open(args.results / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(summary[0]))
        w.writeheader()
        w.writerows(summary)
    lines = [f"# {args.scene} against explicit coupling at {RUNS[GT][1]:g} s ({GT})", "",
             f"The body (disk, 3D: sphere) size (bounding-box diagonal at rest): {size:.4f} m. Frames compared: those of each run that the "
             "ground truth has. Seconds per frame: each run's own stats.csv (the runs may have shared the machine; "
             "speed ratios: bench_table1).", "",
             "| run | dt (s) | frames | s/frame | sand J min / mean | sand J(4dx) min / mean | disk mean error last / "
             "worst (% size) | disk max error worst (% size) | particles inside the disk (worst frame) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        dt = "CFL" if s["dt"] == 0 else f"{s['dt']:g}"
        lines.append(f"| {s['run']} | {dt} | {s['frames']} | {s['s_per_frame']:.3f} | {s['jaccard_min']:.4f} / "
                     f"{s['jaccard_mean']:.4f} | {s['jaccard_4dx_min']:.4f} / {s['jaccard_4dx_mean']:.4f} | "
                     f"{s['disk_mean_pct_last']:.3f} / {s['disk_mean_pct_worst']:.3f} | {s['disk_max_pct_worst']:.3f} | "
                     f"{s['penetrations']} |")
    (args.results / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
