#!/usr/bin/env python3
"""The model table of issue 16: the shipped energies before and after (errors from their MANIFESTs), and the
held-out error against training time (from the *_eval.csv curves written during training).

    .venv/bin/python scripts/model_table.py [--old notebooks/results/model_eval/raw_models] [--new models]
        [--out notebooks/results/model_eval] [--old-files DIR]

--old: a folder with the earlier MANIFEST and *_eval.csv (the raw-input models of issue 3-14, kept in
notebooks/results/model_eval/raw_models); --new: the shipped models. The Hessian error (relative RMS of
Hess Psi against sym(d Ptilde/dF), "near" sampling, 2000 samples) is in the new MANIFEST; for the old models
it is read from OLD/hessian_errors.json, which --old-files DIR (the old .pt files) computes and writes.
Writes OUT/models.md (also printed) and OUT/error_vs_time.png.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

SCALES = ("0.5x", "1x", "2x")


def manifest(folder: Path) -> dict:
    data = json.loads((folder / "MANIFEST").read_text())
    return {m["file"]: m for m in data["models"] if m.get("kind") == "energy"}


def recipe_of(entry: dict, folder: Path) -> dict:
    """representation, sampling and Hessian weight from the model's command line (MANIFEST 'command')."""
    args = entry.get("command", "").split()

    def value(flag, default):
        return args[args.index(flag) + 1] if flag in args else default

    return {
        "representation": entry.get("representation", value("--representation", "raw")),
        "sampling": value("--sampling", "paper"),
        "hessian_weight": float(entry.get("hessian_weight", value("--hessian-weight", "0"))),
    }


def old_hessian_errors(old: Path, files: Path | None) -> dict:
    path = old / "hessian_errors.json"
    if files is not None:
        from plasticitynet import load_model
        from plasticitynet.training.held_out import EVAL_SEED, HESSIAN_SAMPLES, hessian_error

        errors = {}
        for name in manifest(old):
            model = load_model(files / name) if (files / name).is_file() else None
            if model is not None:
                errors[name] = hessian_error(model, HESSIAN_SAMPLES, EVAL_SEED)
                print(f"{name}: Hessian error {100 * errors[name]:.2f}%", file=sys.stderr)
        path.write_text(json.dumps(errors, indent=1) + "\n")
    return json.loads(path.read_text()) if path.is_file() else {}


def row(name: str, label: str, entry: dict, folder: Path, hessian: float | None) -> str:
    r = recipe_of(entry, folder)
    e = entry["errors"]
    rel = e["rel_rms"]
    cells = [name, label, r["representation"], r["sampling"], f"{r['hessian_weight']:g}", str(entry.get("epochs", "")),
             f"{entry.get('wall_seconds', 0):.0f}"]
    cells += [f"{100 * rel['paper'][s]:.2f}" for s in SCALES]
    cells += [f"{100 * rel['near'][s]:.2f}" for s in SCALES]
    cells.append("-" if hessian is None else f"{100 * hessian:.1f}")
    cells.append(f"{e['at_F0_max_rel']:.1e}")
    return "| " + " | ".join(cells) + " |"


def table(old: Path, new: Path, old_hessian: dict) -> str:
    before, after = manifest(old), manifest(new)
    header = ["model", "", "input", "training sampling", "Hessian weight", "steps", "training s",
              "paper 0.5x %", "paper 1x %", "paper 2x %", "near 0.5x %", "near 1x %", "near 2x %",
              "Hessian (near) %", "at F0"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name in after:
        stem = name[:-3]
        if name in before:
            lines.append(row(stem, "before", before[name], old, old_hessian.get(name)))
        lines.append(row(stem, "now", after[name], new, after[name]["errors"].get("hessian_rel_rms_near")))
    return "\n".join(lines)


def read_curve(path: Path):
    if not path.is_file():
        return None
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return rows or None


def plot(old: Path, new: Path, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [n[:-3] for n in manifest(new)]
    cols = 4
    rows_ = (len(names) + cols - 1) // cols
    fig, axes = plt.subplots(rows_, cols, figsize=(4 * cols, 3.2 * rows_), squeeze=False)
    for ax, name in zip(axes.flat, names):
        for folder, style, label in ((old, "--", "before"), (new, "-", "now")):
            curve = read_curve(folder / f"{name}_eval.csv")
            if not curve:
                continue
            t = [float(r["wall_seconds"]) / 60 for r in curve]
            for key, color in (("paper", "#1f77b4"), ("near", "#d62728")):
                if key in curve[0]:
                    ax.plot(t, [100 * float(r[key]) for r in curve], style, color=color, marker=".",
                            label=f"{label} {key}")
        ax.set_title(name)
        ax.set_yscale("log")
        ax.set_xlabel("training wall time (min)")
        ax.set_ylabel("held-out rel. RMS error (%)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", type=Path, default=ROOT / "notebooks/results/model_eval/raw_models")
    p.add_argument("--new", type=Path, default=ROOT / "models")
    p.add_argument("--out", type=Path, default=ROOT / "notebooks/results/model_eval")
    p.add_argument("--old-files", type=Path, default=None, help="the old .pt files: compute their Hessian errors")
    args = p.parse_args()
    old_hessian = old_hessian_errors(args.old, args.old_files)
    text = table(args.old, args.new, old_hessian)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "models.md").write_text(
        "Relative RMS gradient error on 100000 held-out samples (python -m plasticitynet.model_errors), before "
        "(raw input, the paper's sampling) and now; regenerate with `scripts/model_table.py`.\n\n" + text + "\n"
    )
    plot(args.old, args.new, args.out / "error_vs_time.png")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
