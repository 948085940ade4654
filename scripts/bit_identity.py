#!/usr/bin/env python3
"""Do two builds of `pnet` simulate the same? For a refactor that must not change a result.

    scripts/bit_identity.py OLD_PNET NEW_PNET [--scenes scenes/tiny/*.json] [--frames 2] [--work DIR]

Runs every scene with both binaries (the scene's own integrator, one thread) and compares, frame by
frame, the PLY files' data (the run id a newer build writes into the header aside; where they differ,
the largest difference of a position), and stats.csv and steps.csv without their wall-clock columns,
on the columns both builds write (a column the new build adds is named, not counted as a difference).
Prints one line per scene and exits 1 if any differs.
"""

from __future__ import annotations

import argparse
import csv
import io
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from plasticitynet import launch  # noqa: E402  (the one launcher of pnet simulate)

launch.with_simulator()  # the frames are read by plasticitynet_sim

from plasticitynet import frames as frame_files  # noqa: E402
TIMING = re.compile(r"(^|_)(wall|p2g|solve|g2p|energy|cg|broad_phase|ccd)_s$")


def frame_data(path: Path) -> bytes:
    return re.sub(rb"comment run_id \w+\n", b"", path.read_bytes())


def table(path: Path) -> list[dict]:
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    return [{k: v for k, v in r.items() if not TIMING.search(k)} for r in rows]


def largest_move(old: Path, new: Path) -> float:
    """The largest difference of a position between two frames of the same kind (m)."""
    if old.name.endswith("_mesh.ply"):
        a, b = frame_files.read_mesh_ply(old).position, frame_files.read_mesh_ply(new).position
    else:
        a, b = frame_files.read_particle_positions(old), frame_files.read_particle_positions(new)
    return float(abs(a - b).max()) if a.shape == b.shape else float("inf")


def run(pnet: Path, scene: Path, frames: int, out: Path) -> None:
    command = launch.simulate_command(pnet, scene, out, frames=frames, threads=1, overwrite=out.exists())
    finished = launch.run(command)
    if finished.status != 0:
        sys.exit(f"{' '.join(command)} failed ({finished.status}):\n{finished.output}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--scenes", type=Path, nargs="+", default=sorted((ROOT / "scenes" / "tiny").glob("*.json")))
    parser.add_argument("--frames", type=int, default=2)
    parser.add_argument("--work", type=Path, default=Path("/tmp/pnet_bit_identity"))
    args = parser.parse_args()
    differing = 0
    for scene in args.scenes:
        old, new = args.work / "old" / scene.stem, args.work / "new" / scene.stem
        for pnet, out in ((args.old, old), (args.new, new)):
            run(pnet, scene, args.frames, out)
        frames = sorted(p.name for p in old.glob("frame_*.ply"))
        problems, notes = [], []  # a column only the new build writes is a note, not a difference
        if frames != sorted(p.name for p in new.glob("frame_*.ply")):
            problems.append("different frame files")
        differ = [name for name in frames if (new / name).exists() and frame_data(old / name) != frame_data(new / name)]
        if differ:
            move = max(largest_move(old / name, new / name) for name in differ)
            problems.append(f"{len(differ)} frame files differ, positions by at most {move:.3g} m")
        for name in ("stats.csv", "steps.csv"):
            a, b = table(old / name), table(new / name)
            shared = [k for k in (a[0] if a else {}) if k in (b[0] if b else {})]
            added = [k for k in (b[0] if b else {}) if k not in shared]
            if added:
                notes.append(f"{name} adds {', '.join(added)}")
            if [{k: r[k] for k in shared} for r in a] != [{k: r[k] for k in shared} for r in b]:
                problems.append(f"{name} differs")
        print(f"{scene.stem:28s} {len(frames)} frames  " + ("identical" if not problems else "; ".join(problems)) +
              "".join(f" ({note})" for note in notes))
        differing += bool(problems)
    print(f"{len(args.scenes) - differing} of {len(args.scenes)} scenes bit-identical")
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main())
