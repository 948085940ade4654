"""A sand column simulated twice from Python, with the explicit integrator (at its CFL step) and with
plasticitynet (dt 1e-3), compared frame by frame by the soft IoU of their grid masses.

    .venv/bin/python scripts/example_sand.py [--frames 10] [--out out/example_sand] [--tiny]

Writes particles.png (both runs' particles at the last frame, side by side) and iou.png (soft IoU
per frame) into --out and prints a line per frame. --tiny uses the small test scene (seconds).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

try:
    import plasticitynet_sim as pns
except ImportError as error:
    sys.exit(f"{error}: run scripts/setup.sh, then use .venv/bin/python")

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=10, help="frames of 0.02 s (default 10)")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "example_sand")
    parser.add_argument("--tiny", action="store_true", help="the small test scene instead of sand_column_2d")
    args = parser.parse_args()
    if args.frames < 1:
        parser.error("--frames must be >= 1")
    scene = pns.load_scene(ROOT / "scenes" / ("tiny" if args.tiny else "") / "sand_column_2d.json")

    runs = {
        "explicit (CFL step)": pns.Simulation(scene, integrator="explicit", dt=0.0),
        "plasticitynet (dt 1e-3)": pns.Simulation(scene, integrator="plasticitynet", dt=1e-3),
    }
    reference, implicit = runs.values()
    times, ious = [], []
    print(f"{scene.name}: {reference.num_particles} particles, {args.frames} frames")
    for frame in range(1, args.frames + 1):
        seconds = []
        for sim in runs.values():
            seconds.append(sim.advance(1)[0]["wall_s"])
        iou = pns.iou(reference.grid_mass(), implicit.grid_mass())["soft"]
        times.append(implicit.time)
        ious.append(iou)
        print(f"frame {frame:3d}  t = {implicit.time:.2f} s  soft IoU {iou:.3f}  "
              f"explicit {seconds[0]:.2f} s  plasticitynet {seconds[1]:.2f} s", flush=True)
    print(f"soft IoU over {args.frames} frames: min {min(ious):.3f}, mean {sum(ious) / len(ious):.3f}")

    args.out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5), dpi=100, sharey=True)
    for ax, (name, sim) in zip(axes, runs.items()):
        x = sim.positions
        ax.scatter(x[:, 0], x[:, 1], s=0.5, c=sim.velocities[:, 1], cmap="viridis")
        ax.set_title(f"{name}, t = {sim.time:.2f} s")
        ax.set_xlim(scene.domain_min[0], scene.domain_max[0])
        ax.set_ylim(scene.domain_min[1], 0.5 * (scene.domain_min[1] + scene.domain_max[1]))
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(args.out / "particles.png")
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    ax.plot(times, ious, marker="o")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("soft IoU, plasticitynet vs explicit")
    ax.set_ylim(0, 1.02)
    ax.set_title(scene.name)
    fig.tight_layout()
    fig.savefig(args.out / "iou.png")
    plt.close(fig)
    print(f"wrote {args.out / 'particles.png'} and {args.out / 'iou.png'}")


if __name__ == "__main__":
    main()
