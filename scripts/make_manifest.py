#!/usr/bin/env python3
"""Writes models/MANIFEST: one entry per shipped model file, pinning its sha256 and recording how it
was trained (command line, schedule, wall time, machine) and the errors measured on held-out samples
at export (plasticitynet.model_errors). The C++ loader and the tests check model files against it.

    .venv/bin/python scripts/make_manifest.py [--models DIR] [--all]

MANIFEST is JSON: {"format": "plasticitynet-manifest", "version": 1, "models": [{...}, ...]}.
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import sys
from pathlib import Path

import plasticitynet
from plasticitynet.training.export import sha256_of

#: The models this release ships (issue 3), in training order.
SHIPPED = ("sand_2d", "snow_2d", "metal_2d", "metal_nh_rm_2d", "metal_nh_2d", "sand_3d", "snow_3d", "metal_3d",
           "sand_param_2d", "snow_param_2d", "metal_param_2d", "sand_param_3d", "snow_param_3d")


def shipped_command(command: str | None, path: Path) -> str | None:
    """The command that writes `path`: the recorded one without --resume and without an --out naming another folder (a model
    trained elsewhere, e.g. by scripts/recipe_study.py, and copied into models/ is written there by the
    same command with train.py's default output, models/<material>_<dim>d.pt)."""
    if command is None:
        return None
    words = [w for w in shlex.split(command) if w != "--resume"]  # a resumed run is the same run
    if "--out" in words:
        k = words.index("--out")
        if Path(words[k + 1]).name != path.name or "models" not in Path(words[k + 1]).parts:
            del words[k : k + 2]
    return shlex.join(words)


def entry(path: Path) -> dict:
    model = plasticitynet.load_model(path)
    meta = model.metadata
    recipe = meta.get("recipe", {})
    stem = path.stem
    return {
        "file": path.name,
        "sha256": sha256_of(path),
        "kind": meta["kind"],
        "material": meta["material"]["name"],
        "dim": meta["dim"],
        "widths": meta["widths"],
        "command": shipped_command(recipe.get("command"), path),
        # a fine-tuned model (train.py --init-from): the file and sha256 its weights started from
        **({"init_from": recipe["init_from"]} if recipe.get("init_from") else {}),
        **(
            {
                "representation": meta.get("representation", "raw"),
                "hessian_weight": recipe.get("hessian_weight", 0.0),
                "energy_form": meta.get("energy_form", "eq8"),
            }
            if meta["kind"] == "energy"
            else {}
        ),
        "epochs": recipe.get("epochs"),
        "batch": recipe.get("batch"),
        "lr": recipe.get("lr"),
        "lr_decay": recipe.get("decay"),
        "decay_steps": recipe.get("decay_steps"),
        "sampling": recipe.get("sampling"),
        "seed": recipe.get("seed"),
        "wall_seconds": recipe.get("wall_seconds"),
        "threads": recipe.get("threads"),
        "device": recipe.get("device"),
        **({"exported_on": recipe["exported_on"]} if "exported_on" in recipe else {}),
        **({"schedule": recipe["schedule"], "warmup": recipe.get("warmup", 0)} if "schedule" in recipe else {}),
        **({"parameters": meta["parameters"]} if "parameters" in meta else {}),
        "errors": meta.get("errors"),
        "return_map": meta.get("return_map"),
        "loss_curve": f"{stem}_loss.png" if (path.parent / f"{stem}_loss.png").exists() else None,
        "loss_log": f"{stem}.csv" if (path.parent / f"{stem}.csv").exists() else None,
        "torch_version": meta.get("torch_version"),
        "created": meta.get("created"),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", type=Path, default=Path(__file__).resolve().parent.parent / "models")
    parser.add_argument(
        "--all", action="store_true", help="every .pt file in the folder (models/ablation) instead of the shipped list"
    )
    args = parser.parse_args(argv)
    names = sorted(p.stem for p in args.models.glob("*.pt")) if args.all else SHIPPED
    entries, missing = [], []
    for name in names:
        path = args.models / f"{name}.pt"
        if path.exists():
            entries.append(entry(path))
        else:
            missing.append(name)
    manifest = {
        "format": "plasticitynet-manifest",
        "version": 1,
        "machine": f"{platform.machine()} CPU, 2 threads, OpenBLAS (no GPU)",
        "models": entries,
    }
    out = args.models / "MANIFEST"
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(manifest, indent=1) + "\n")
    tmp.replace(out)
    print(f"wrote {out}: {len(entries)} models" + (f"; not trained yet: {', '.join(missing)}" if missing else ""))
    print("\n| model | steps x batch | wall | rel. RMS grad error, paper sampling 0.5x / 1x / 2x deps "
          "| near sampling 0.5x / 1x / 2x | at F = F0 |")
    print("|---|---|---|---|---|---|")
    for e in entries:
        errors = e["errors"] or {}
        size = f"{e['epochs']} x {e['batch']}"
        wall = f"{(e['wall_seconds'] or 0) / 60:.1f} min"
        if e["kind"] == "return_map":
            print(f"| {e['file']} | {size} | {wall} | mean abs(dgamma error) {errors['mean_abs_dgamma_error']:.2e}, "
                  f"mean abs(y)/(2 mu h)^2 {errors['mean_abs_y_rel']:.2e} | within 1e-3 of the surface: "
                  f"{errors['frac_within_1e-3']:.1%} | - |")
            continue
        rms = errors["rel_rms"]
        row = [" / ".join(f"{rms[s][k]:.2%}" for k in ("0.5x", "1x", "2x")) for s in ("paper", "near")]
        print(f"| {e['file']} | {size} | {wall} | {row[0]} | {row[1]} | {errors['at_F0_max_rel']:.1e} |")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
