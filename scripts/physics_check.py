#!/usr/bin/python3
"""Physics check of the explicit ground-truth MPM (issue 5).

Runs sand_column_2d and snowball_2d to rest with `pnet simulate --integrator
explicit`, once at dt = 1e-5 s (the paper's ground-truth step) and once at the
CFL step, then reports for the last frame the run-out (half-width of the
deposit about the initial centre line x = 0.5 m) and the deposit height (top
of the particles above the floor), whether the run came to rest (kinetic
energy against its peak), and the soft/binary IoU between the two runs
(`pnet compare`).

Outputs (under --results, default notebooks/results/physics_check): summary.csv,
summary.md, per run its stats.csv and run.json and the PNGs of a few frames,
per scene the IoU CSV and plot. The full runs (PLY of every frame) stay in
--work (default out/physics_check).

    .venv/bin/python scripts/physics_check.py [--seconds 1.5] [--threads 2]   (plasticitynet_sim reads the frames)
"""
import argparse
import csv
import json
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

from plasticitynet import launch  # noqa: E402

launch.with_simulator()  # the frames are read by plasticitynet_sim
from plasticitynet.frames import read_particle_positions  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=1.5, help="simulated time (s); default 1.5")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--pnet", default=str(ROOT / "build/cpp/pnet"))
    ap.add_argument("--work", default=str(ROOT / "out/physics_check"))
    ap.add_argument("--results", default=str(ROOT / "notebooks/results/physics_check"))
    ap.add_argument("--scenes", nargs="+", default=["sand_column_2d", "snowball_2d"])
    args = ap.parse_args()
    pnet = Path(args.pnet)
    if not pnet.exists():
        sys.exit(f"{pnet}: not built; run scripts/setup.sh first")
    work, results = Path(args.work), Path(args.results)
    results.mkdir(parents=True, exist_ok=True)

    rows = []
    for scene in args.scenes:
        scene_file = ROOT / "scenes" / f"{scene}.json"
        description = json.loads(scene_file.read_text())
        frame_dt = description["frame_dt"]
        frames = int(round(args.seconds / frame_dt))
        floor = description["domain"]["min"][1] + description["boundary"]["sticky_floor_cells"] * description["dx"]
        centre = 0.5
        dirs = {}
        for label, dt in (("dt1e-5", "1e-5"), ("cfl", "0")):
            out = work / f"{scene}_{label}"
            dirs[label] = out
            if not (out / "run.json").exists() or json.loads((out / "run.json").read_text())["frames"] != frames \
                    or not (out / f"frame_{frames:05d}.ply").exists():
                cmd = launch.simulate_command(pnet, scene_file, out, integrator="explicit", dt=dt, frames=frames,
                                              threads=args.threads, overwrite=True,
                                              options=["--color", "hardening" if "snow" in scene else "speed"])
                if launch.run(cmd, echo=True, log=work / f"{scene}_{label}.log").status != 0:
                    sys.exit(f"{' '.join(cmd)} failed; see {work / f'{scene}_{label}.log'}")
            with open(out / "stats.csv") as f:
                stats = list(csv.DictReader(f))
            kinetic = np.array([float(r["kinetic_J"]) for r in stats])
            wall = np.array([float(r["wall_s"]) for r in stats])
            steps = np.array([int(r["steps"]) for r in stats])
            x = read_particle_positions(out / f"frame_{frames:05d}.ply")
            runout = float(np.max(np.abs(x[:, 0] - centre)))
            height = float(np.max(x[:, 1]) - floor)
            rows.append({
                "scene": scene, "run": label, "frames": frames, "time_s": frames * frame_dt,
                "steps": int(steps.sum()), "mean_dt_s": frames * frame_dt / steps.sum(),
                "wall_s": float(wall.sum()), "particles": len(x),
                "runout_m": runout, "height_m": height,
                "final_kinetic_J": float(kinetic[-1]), "peak_kinetic_J": float(kinetic.max()),
            })
            keep = results / f"{scene}_{label}"
            keep.mkdir(exist_ok=True)
            for name in ("stats.csv", "run.json"):
                shutil.copy(out / name, keep / name)
            for frame in sorted({0, frames // 6, frames // 3, frames // 2, frames}):
                shutil.copy(out / f"frame_{frame:05d}.png", keep / f"frame_{frame:05d}.png")
        compare_out = results / f"{scene}_iou"
        if launch.run([str(c) for c in (pnet, "compare", dirs["dt1e-5"], dirs["cfl"], "--out", compare_out)],
                      echo=True).status != 0:
            sys.exit(f"pnet compare {dirs['dt1e-5']} {dirs['cfl']} failed")
        with open(compare_out / "iou.csv") as f:
            iou = list(csv.DictReader(f))
        soft = np.array([float(r["soft_iou"]) for r in iou])
        binary = np.array([float(r["binary_iou"]) for r in iou])
        for r in rows[-2:]:
            r.update({"iou_soft_min": float(soft.min()), "iou_soft_final": float(soft[-1]),
                      "iou_binary_min": float(binary.min()), "iou_binary_final": float(binary[-1])})

    with open(results / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    lines = ["| scene | run | steps | mean dt (s) | wall (s) | run-out (m) | height (m) | final KE / peak KE | "
             "soft IoU min / final | binary IoU min / final |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['run']} | {r['steps']} | {r['mean_dt_s']:.2e} | {r['wall_s']:.1f} | "
                     f"{r['runout_m']:.4f} | {r['height_m']:.4f} | {r['final_kinetic_J'] / r['peak_kinetic_J']:.1e} | "
                     f"{r['iou_soft_min']:.3f} / {r['iou_soft_final']:.3f} | "
                     f"{r['iou_binary_min']:.3f} / {r['iou_binary_final']:.3f} |")
    text = "\n".join(lines) + "\n"
    (results / "summary.md").write_text(
        f"Explicit MPM physics check, {args.seconds} s simulated, written by scripts/physics_check.py. "
        "Run-out: max |x - 0.5| over the particles of the last frame; height: top particle above the floor "
        "(3 dx). IoU: dt 1e-5 against the CFL run, per frame (pnet compare).\n\n" + text)
    print(text)


if __name__ == "__main__":
    main()
