#!/usr/bin/env python3
"""Copies a model trained elsewhere (e.g. a run of scripts/recipe_study.py) into models/ as a shipped model:
the TorchScript file with its metadata, the loss log (<stem>.csv; a long run's thinned to LOSS_LOG_ROWS
rows), the error curve (<stem>_eval.csv) and
the loss plot (<stem>_loss.png), renamed to NAME. A model trained against a learned return mapping
(metal_nh) records that file relative to itself; the reference is rewritten relative to the new place
(after checking the file there is the one it was trained with, by sha256), so that the copy loads.

    .venv/bin/python scripts/ship_model.py RUN/model.pt NAME [--models DIR]

Then regenerate models/MANIFEST (scripts/make_manifest.py) and the energy vectors of the C++ cross-check
(scripts/gen_energy_vectors.py). Nothing is written when a check fails; the model file is replaced
atomically.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

from plasticitynet.model import read_model_file  # noqa: E402
from plasticitynet.training.export import export_model, sha256_of  # noqa: E402

#: The files beside a model, by suffix after its stem.
SIDECARS = (".csv", "_eval.csv", "_loss.png")

#: A shipped loss log (one row per step) keeps at most about this many rows: every k-th step and the last.
#: A 100000-step run's full log is 5.5 MiB, and the repository travels (clones, the device machine).
LOSS_LOG_ROWS = 10000


def thin_loss_log(source: Path, dest: Path, max_rows: int = LOSS_LOG_ROWS) -> int:
    """Copies the loss log `source` (a header, then one row per step) to `dest` keeping the header, every
    k-th step (k the smallest integer leaving <= max_rows + 1 rows) and the last row; returns k."""
    lines = source.read_text().splitlines(keepends=True)
    header, rows = lines[:1], lines[1:]
    k = max(1, -(-len(rows) // max_rows))
    kept = rows[k - 1 :: k]
    if rows and (not kept or kept[-1] is not rows[-1]):
        kept.append(rows[-1])
    tmp = dest.with_name(dest.name + ".tmp")
    tmp.write_text("".join(header + kept))
    os.replace(tmp, dest)
    return k


def relocated_metadata(meta: dict, source: Path, dest: Path) -> dict:
    """meta with the learned return map's file (relative to the model) re-expressed relative to `dest`."""
    rm = meta.get("return_map") or {}
    if rm.get("type") != "learned":
        return meta
    target = (source.parent / rm["file"]).resolve()
    if not target.is_file():
        raise ValueError(f"{source}: its learned return mapping {rm['file']!r} is not at {target}")
    if rm.get("sha256") and sha256_of(target) != rm["sha256"]:
        raise ValueError(f"{source}: {target} is not the return mapping it was trained with (sha256 differs)")
    relative = os.path.relpath(target, dest.parent.resolve())
    return {**meta, "return_map": {**rm, "file": relative}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("source", type=Path, help="the trained model file (.pt)")
    p.add_argument("name", help="the shipped name without .pt, e.g. sand_2d")
    p.add_argument("--models", type=Path, default=ROOT / "models")
    args = p.parse_args(argv)
    try:
        _, meta = read_model_file(args.source)
        dest = args.models / f"{args.name}.pt"
        meta = relocated_metadata(meta, args.source, dest)
    except ValueError as err:
        print(f"ship_model: {err}", file=sys.stderr)
        return 2
    export_model(dest, torch.jit.load(str(args.source), map_location="cpu"), meta)  # atomic, as train.py writes
    copied = [dest.name]
    for suffix in SIDECARS:
        side = args.source.with_name(args.source.stem + suffix)
        if side.is_file():
            target = args.models / f"{args.name}{suffix}"
            if suffix == ".csv":
                k = thin_loss_log(side, target)
                copied.append(f"{args.name}{suffix}" + (f" (1 row in {k})" if k > 1 else ""))
            else:
                shutil.copyfile(side, target)
                copied.append(f"{args.name}{suffix}")
    print(f"shipped {args.source} as {', '.join(copied)} in {args.models}")
    print("next: scripts/make_manifest.py, scripts/gen_energy_vectors.py")
    return 0


if __name__ == "__main__":
    sys.exit(main())
