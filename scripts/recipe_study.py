#!/usr/bin/env python3
"""Held-out error against compute for training recipes (issue 32, item 1): batch size, step count and
learning-rate schedule at a similar wall-time budget, per model.

Each run is one `train.py` invocation (1 thread, so that two runs share a 2-core machine without
slowing each other; --jobs) with an in-training error curve (--eval-every: relative RMS gradient error
on 2^14 held-out samples, paper and near sampling) and the final evaluation on 10^5 samples. Runs whose
model file exists are reused (delete the run's folder to redo it).

Outputs under --out (default notebooks/results/model_eval/recipe):
  runs/<name>/model.pt, model.csv, model_eval.csv   the trainings
  error_vs_compute_<model>.png                       held-out error (paper 1x) against wall time and
                                                     against samples seen, one curve per run
  summary.md                                         per run: recipe, steps, wall, final errors

    .venv/bin/python scripts/recipe_study.py [--runs NAME ...] [--jobs 2] [--list]
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

#: Options every run shares: the shipped models' input, sampling and Hessian weight.
COMMON = ["--sampling", "mixed", "--representation", "principal", "--hessian-weight", "0.1", "--seed", "0",
          "--threads", "1", "--no-progress", "--eval-samples", "100000", "--checkpoint-every", "1000"]


@dataclass(frozen=True)
class Run:
    name: str
    material: str
    dim: int
    batch: int
    epochs: int
    schedule: str = "step"
    decay_steps: int = 100
    warmup: int = 0
    lr: float = 0.01
    note: str = ""
    extra: tuple = field(default_factory=tuple)

    @property
    def model(self) -> str:
        return f"{self.material}_{self.dim}d"

    def args(self, out: Path) -> list[str]:
        eval_every = max(1, self.epochs // 25)
        args = ["--material", self.material, "--dim", str(self.dim), "--batch", str(self.batch),
                "--epochs", str(self.epochs), "--schedule", self.schedule, "--lr", str(self.lr),
                "--eval-every", str(eval_every), "--out", str(out), *COMMON, *self.extra]
        if self.schedule == "step":
            args += ["--decay-steps", str(self.decay_steps), "--lr-decay", "0.95"]
        if self.warmup:
            args += ["--warmup", str(self.warmup)]
        return args


#: The study. The shipped 3D models were trained with batch 8192 x 5000 steps, x0.95 every 100 (~1300 s
#: on one core; snow_2d: 15000 steps, every 300, ~1270 s); their curves (models/<model>_eval.csv) are
#: drawn beside these runs, which spend about the same wall time or more on smaller batches and more steps.
RUNS = [
    Run("metal3d_b2048_step", "metal", 3, 2048, 16000, "step", 320, note="the shipped decay (x0.95^50) over 4x more steps"),
    Run("metal3d_b2048_cosine", "metal", 3, 2048, 16000, "cosine", warmup=500),
    Run("metal3d_b512_cosine", "metal", 3, 512, 40000, "cosine", warmup=1000),
    Run("metal3d_b2048_onecycle", "metal", 3, 2048, 16000, "onecycle"),
    # The metal_3d winner (batch 512, 40000 cosine steps) on every other shipped energy: the retraining
    # of issue 32 item 3 (a run ships when it beats the shipped model on held-out error).
    Run("sand3d_b512_cosine", "sand", 3, 512, 40000, "cosine", warmup=1000),
    Run("snow3d_b512_cosine", "snow", 3, 512, 40000, "cosine", warmup=1000),
    Run("snow2d_b512_cosine", "snow", 2, 512, 40000, "cosine", warmup=1000),
    Run("sand2d_b512_cosine", "sand", 2, 512, 40000, "cosine", warmup=1000),
    Run("metal2d_b512_cosine", "metal", 2, 512, 40000, "cosine", warmup=1000),
    Run("metalnh2d_b512_cosine", "metal_nh", 2, 512, 40000, "cosine", warmup=1000),
    # Training precision: the network and loss in float32 (every run above) against float64, metal_2d
    # (exact gradient-field targets: pure approximation and optimisation error), same batches.
    Run("metal2d_b512_cosine10k", "metal", 2, 512, 10000, "cosine", warmup=250, note="float32"),
    Run("metal2d_b512_cosine10k_fp64", "metal", 2, 512, 10000, "cosine", warmup=250, note="float64",
        extra=("--precision", "float64")),
    # Width and depth at the float32/float64 pair's budget (batch 512 x 10000 cosine steps), metal_2d:
    Run("metal2d_w64_b512_cosine10k", "metal", 2, 512, 10000, "cosine", warmup=250, note="hidden 64 64 64",
        extra=("--hidden", "64", "64", "64")),
    Run("metal2d_d4_b512_cosine10k", "metal", 2, 512, 10000, "cosine", warmup=250, note="hidden 32 32 32 32",
        extra=("--hidden", "32", "32", "32", "32")),
    # Width and depth (Table 2's [7, 32, 32, 32, 1] against twice as wide and one layer deeper), snow_2d:
    # the target farthest from a gradient field, where capacity might buy the most.
    Run("snow2d_w64_b512_cosine", "snow", 2, 512, 40000, "cosine", warmup=1000, note="hidden 64 64 64",
        extra=("--hidden", "64", "64", "64")),
    Run("snow2d_d4_b512_cosine", "snow", 2, 512, 40000, "cosine", warmup=1000, note="hidden 32 32 32 32",
        extra=("--hidden", "32", "32", "32", "32")),
    # Capacity at the recipe that gave snow_2d its best error (the shipped batch 8192 x 15000 steps, x0.95
    # every 300): is the network, rather than the schedule (cpu5: cosine, same budget, 9.94%), the limit?
    Run("snow2d_w64_b8192_step", "snow", 2, 8192, 15000, "step", 300, note="hidden 64 64 64, the shipped recipe",
        extra=("--hidden", "64", "64", "64")),
]

#: The models the study started from (issue 16's, before the retraining of issue 32): their curves and
#: recipes are kept under <out>/baseline/ (--baseline COMMIT extracts them from git).
BASELINE_COMMIT = "df17245"
BASELINE_MODELS = ("sand_2d", "snow_2d", "metal_2d", "metal_nh_2d", "sand_3d", "snow_3d", "metal_3d")


def extract_baseline(out_dir: Path, commit: str) -> None:
    """<out>/baseline/<model>_eval.csv and <model>.json (recipe, widths, errors) of models/ at `commit`."""
    import tempfile

    from plasticitynet.model import read_model_file

    folder = out_dir / "baseline"
    folder.mkdir(parents=True, exist_ok=True)
    for name in BASELINE_MODELS:
        def show(path):
            return subprocess.run(["git", "show", f"{commit}:models/{path}"], cwd=ROOT, capture_output=True,
                                  check=True).stdout
        (folder / f"{name}_eval.csv").write_bytes(show(f"{name}_eval.csv"))
        with tempfile.TemporaryDirectory() as tmp:
            model = Path(tmp) / f"{name}.pt"
            model.write_bytes(show(f"{name}.pt"))
            meta = read_model_file(model)[1]
        info = {"commit": commit, "recipe": meta["recipe"], "widths": meta["widths"], "errors": meta.get("errors", {})}
        (folder / f"{name}.json").write_text(json.dumps(info, indent=1) + "\n")
    print(f"baseline: models/ at {commit} -> {folder}")


def _shipped_errors(model_name: str) -> dict | None:
    """The held-out errors models/MANIFEST records for models/<model_name>.pt (they identify the run it came
    from: scripts/ship_model.py keeps a model's metadata, errors included)."""
    for e in json.loads((ROOT / "models" / "MANIFEST").read_text())["models"]:
        if e["file"] == f"{model_name}.pt":
            return e.get("errors")
    return None


def run_one(run: Run, out_dir: Path) -> Path:
    model = out_dir / "runs" / run.name / "model.pt"
    if model.is_file():
        print(f"[reuse] {run.name}", flush=True)
        return model
    model.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, str(ROOT / "train.py"), *run.args(model)]
    if (model.with_suffix(".ckpt")).is_file():
        cmd.append("--resume")  # a study interrupted mid-run continues where it stopped
    print(f"[start] {run.name}: {' '.join(cmd[2:])}", flush=True)
    t0 = time.perf_counter()
    with open(model.parent / "train.log", "w") as log:
        done = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"{run.name}: train.py exited {done.returncode} (see {model.parent / 'train.log'})")
    print(f"[done]  {run.name} in {time.perf_counter() - t0:.0f} s", flush=True)
    return model


def read_curve(model: Path) -> list[dict]:
    path = model.with_name(model.stem + "_eval.csv")
    with open(path) as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def _recipe_and_errors(model: Path) -> tuple[dict, dict]:
    """The model's recipe (with its network's widths) and its final held-out errors."""
    from plasticitynet.model import read_model_file

    metadata = read_model_file(str(model))[1]
    return {**metadata["recipe"], "widths": metadata.get("widths")}, metadata.get("errors", {})


def summarize(runs: list[Run], out_dir: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = []
    for model_name in sorted({r.model for r in runs}):
        group = [r for r in runs if r.model == model_name and (out_dir / "runs" / r.name / "model.pt").is_file()]
        if not group:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
        shipped_errors = _shipped_errors(model_name)
        base = out_dir / "baseline" / f"{model_name}.json"
        if base.is_file():
            info = json.loads(base.read_text())
            curve = read_curve(base)  # baseline/<model>_eval.csv
            batch = info["recipe"]["batch"]
            axes[0].plot([c["wall_seconds"] / 60 for c in curve], [100 * c["paper"] for c in curve], "k--", marker="o",
                         label=f"before (batch {batch}, step decay)")
            axes[1].plot([c["step"] * batch for c in curve], [100 * c["paper"] for c in curve], "k--", marker="o")
            material, dim = model_name.rsplit("_", 1)
            rows.append((Run(f"before: models/{model_name}.pt", material, int(dim[0]), batch, info["recipe"]["epochs"],
                             note=f"git {info['commit']}" + ("; still shipped" if info["errors"] == shipped_errors else "")),
                         {**info["recipe"], "widths": info["widths"]}, info["errors"]))
        for run in group:
            curve = read_curve(out_dir / "runs" / run.name / "model.pt")
            wall = [c["wall_seconds"] / 60 for c in curve]
            samples = [c["step"] * run.batch for c in curve]
            err = [100 * c["paper"] for c in curve]
            axes[0].plot(wall, err, marker=".", label=run.name)
            axes[1].plot(samples, err, marker=".", label=run.name)
        for ax, xlabel in zip(axes, ("training wall time, 1 core (min)", "samples seen")):
            ax.set_yscale("log")
            ax.set_xlabel(xlabel)
            ax.set_ylabel("held-out relative RMS gradient error, paper 1x (%)")
            ax.grid(True, which="both", alpha=0.3)
        axes[1].set_xscale("log")
        axes[0].legend(fontsize=8)
        axes[0].set_title(model_name)
        fig.tight_layout()
        fig.savefig(out_dir / f"error_vs_compute_{model_name}.png", dpi=110)
        plt.close(fig)
        for run in group:
            recipe, errors = _recipe_and_errors(out_dir / "runs" / run.name / "model.pt")
            if errors and errors == shipped_errors:
                run = replace(run, note=(run.note + "; " if run.note else "") + f"shipped as models/{model_name}.pt")
            rows.append((run, recipe, errors))
    lines = ["# Training recipes: held-out error against compute (scripts/recipe_study.py)", "",
             "Every run: mixed sampling, principal input, Hessian weight 0.1, seed 0, 1 thread; errors are the",
             "final evaluation on 10^5 held-out samples (relative RMS gradient error, %).", "",
             "| run | model | widths | precision | batch | steps | schedule | wall s | paper 1x | near 1x | Hessian near | note |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for run, recipe, errors in rows:
        paper = errors.get("rel_rms", {}).get("paper", {}).get("1x")
        near = errors.get("rel_rms", {}).get("near", {}).get("1x")
        fmt = (lambda x: f"{100 * x:.2f}" if isinstance(x, (int, float)) else "-")
        sched = recipe.get("schedule", "step") + (f" /{recipe.get('decay_steps')}" if recipe.get("schedule", "step") == "step" else "") + (
            f", warm-up {run.warmup}" if run.warmup else "")
        hidden = (recipe.get("widths") or [None])[1:-1]
        lines.append(f"| {run.name} | {run.model} | {'x'.join(map(str, hidden))} | {recipe.get('dtype', 'float32')} | "
                     f"{run.batch} | {recipe.get('epochs')} | {sched} | {recipe.get('wall_seconds')} | {fmt(paper)} | "
                     f"{fmt(near)} | {fmt(errors.get('hessian_rel_rms_near'))} | {run.note} |")
    (out_dir / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=ROOT / "notebooks" / "results" / "model_eval" / "recipe")
    p.add_argument("--runs", nargs="+", default=None, help="run names (default: all; --list shows them)")
    p.add_argument("--jobs", type=int, default=2, help="runs at once, one thread each (2)")
    p.add_argument("--list", action="store_true")
    p.add_argument("--summary-only", action="store_true", help="plot and tabulate the finished runs")
    p.add_argument("--baseline", metavar="COMMIT", help=f"extract the starting models' curves and errors from git "
                   f"(the study's: {BASELINE_COMMIT}) into <out>/baseline/")
    args = p.parse_args()
    if args.list:
        for run in RUNS:
            print(f"{run.name:<26} {run.model:<9} batch {run.batch:<5} {run.epochs:>6} steps  {run.schedule}  {run.note}")
        return 0
    chosen = RUNS if args.runs is None else [r for r in RUNS if r.name in args.runs]
    unknown = set(args.runs or []) - {r.name for r in RUNS}
    if unknown:
        p.error(f"unknown run(s): {', '.join(sorted(unknown))} (see --list)")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.baseline:
        extract_baseline(args.out, args.baseline)
    if not args.summary_only:
        # Every run is submitted and waited for: a failed one is reported at the end and leaves the others
        # running (Executor.map cancels the queued runs at the first failure it returns).
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            futures = [pool.submit(run_one, run, args.out) for run in chosen]
        failed = [f.exception() for f in futures if f.exception() is not None]
        for err in failed:
            print(f"[failed] {err}", file=sys.stderr, flush=True)
    else:
        failed = []
    summarize(RUNS, args.out)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
