#!/usr/bin/env python3
"""Trains several models side by side within a wall-clock budget, each for as many steps as fit.

A cosine or step schedule needs its number of steps before the first one, and the time a step takes
depends on what else shares the machine (on a GPU, the other trainings' kernels). So the runs are first
launched together for a few probe steps, each one's time per step is read from its own log under that
load, and then they are launched together again with the number of steps that fits the time left:

    scripts/train_in_budget.py --budget 540 --out runs/ RUNS.txt [--probe-steps 200] [--safety 0.85]

RUNS.txt has one run per line, `NAME train.py-arguments` without --epochs and --out (# comments):

    metal_3d_w128  --material metal --dim 3 --device cuda --hidden 128 128 128 --batch 4096 --schedule cosine

Each run writes OUT/NAME/NAME.pt with its log, held-out error curve (20 points) and checkpoint (also
written at the last step, so a run finished on a GPU machine can be exported on another machine with
`train.py ... --resume --device cpu`). A run still going when the budget is spent is stopped; its
checkpoint remains. Progress (each run's step) is printed every --report seconds, and a summary at the end
(OUT/summary.csv).
"""

from __future__ import annotations

import argparse
import csv
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Run:
    name: str
    args: list[str]
    step_seconds: float = float("nan")
    startup_seconds: float = float("nan")
    epochs: int = 0
    process: subprocess.Popen | None = None
    started: float = 0.0
    log: Path | None = None
    status: str = "pending"
    errors: dict = field(default_factory=dict)


def read_runs(path: Path) -> list[Run]:
    runs = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, *args = shlex.split(line)
        for forbidden in ("--epochs", "--out", "--resume"):
            if forbidden in args:
                raise SystemExit(f"{path}:{number}: run {name!r} sets {forbidden}, which this script chooses")
        if any(r.name == name for r in runs):
            raise SystemExit(f"{path}:{number}: run name {name!r} appears twice")
        runs.append(Run(name, args))
    if not runs:
        raise SystemExit(f"{path}: no runs")
    return runs


def launch(run: Run, out: Path, epochs: int, extra: list[str]) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    run.log = out.with_suffix(".out")
    cmd = [sys.executable, str(ROOT / "train.py"), *run.args, "--epochs", str(epochs), "--out", str(out),
           "--no-progress", *extra]
    env = dict(os.environ, PYTHONPATH=str(ROOT / "python") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    run.started = time.perf_counter()
    run.process = subprocess.Popen(cmd, stdout=open(run.log, "w"), stderr=subprocess.STDOUT, env=env, cwd=ROOT)


def loss_log(model: Path) -> list[tuple[int, float]]:
    """(step, training wall seconds) rows of train.py's OUT.csv so far."""
    path = model.with_suffix(".csv")
    if not path.is_file():
        return []
    with open(path) as f:
        return [(int(r[0]), float(r[3])) for r in list(csv.reader(f))[1:] if len(r) == 4]


def wait_all(runs: list[Run], models: dict, deadline: float, report: float) -> None:
    next_report = time.perf_counter() + report
    while any(r.process.poll() is None for r in runs):
        now = time.perf_counter()
        if now > deadline:
            for r in runs:
                if r.process.poll() is None:
                    r.process.terminate()
                    r.status = "stopped by the budget"
            for r in runs:
                r.process.wait()
            break
        if now >= next_report:
            steps = ", ".join(f"{r.name} {(loss_log(models[r.name]) or [(0, 0)])[-1][0]}/{r.epochs or '?'}" for r in runs)
            print(f"[{time.strftime('%H:%M:%S')}] {steps}", flush=True)
            next_report = now + report
        time.sleep(1.0)
    for r in runs:
        if r.status == "pending":
            r.status = "finished" if r.process.returncode == 0 else f"failed (exit {r.process.returncode}, see {r.log})"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", type=Path, help="the runs, one per line: NAME train.py-arguments")
    p.add_argument("--budget", type=float, required=True, help="wall-clock seconds for everything, probe included")
    p.add_argument("--out", type=Path, required=True, help="folder of the runs")
    p.add_argument("--probe-steps", type=int, default=200)
    p.add_argument("--safety", type=float, default=0.85, help="fraction of the time left planned for steps")
    p.add_argument("--tail", type=float, default=30.0, help="seconds kept for the final export and evaluation")
    p.add_argument("--report", type=float, default=30.0, help="seconds between progress lines")
    args = p.parse_args()
    t0 = time.perf_counter()
    deadline = t0 + args.budget
    runs = read_runs(args.runs)

    print(f"probe: {len(runs)} runs side by side for {args.probe_steps} steps", flush=True)
    probes = {r.name: args.out / "probe" / f"{r.name}.pt" for r in runs}
    for r in runs:
        launch(r, probes[r.name], args.probe_steps, ["--eval-samples", "0", "--checkpoint-every", "1000000"])
    wait_all(runs, probes, deadline, args.report)
    first = args.probe_steps // 4
    for r in runs:
        rows = loss_log(probes[r.name])
        if r.process.returncode != 0 or len(rows) < args.probe_steps:
            raise SystemExit(f"probe of {r.name} failed (exit {r.process.returncode}): see {r.log}")
        r.step_seconds = (rows[-1][1] - rows[first - 1][1]) / (args.probe_steps - first)
        r.startup_seconds = max(time.perf_counter() - r.started - rows[-1][1], 0.0)
        r.status = "pending"

    left = deadline - time.perf_counter()
    models = {r.name: args.out / r.name / f"{r.name}.pt" for r in runs}
    for r in runs:
        steps = args.safety * (left - r.startup_seconds - args.tail) / r.step_seconds
        r.epochs = int(steps // 100 * 100)
        if r.epochs < 100:
            raise SystemExit(f"{r.name}: {left:.0f} s left fit only {steps:.0f} steps of {r.step_seconds:.4f} s")
        print(f"{r.name}: {r.step_seconds * 1e3:.1f} ms per step side by side, start-up {r.startup_seconds:.0f} s: "
              f"{r.epochs} steps", flush=True)
    for r in runs:
        launch(r, models[r.name], r.epochs,
               ["--eval-every", str(max(r.epochs // 20, 1)), "--checkpoint-every", "1000"])
    wait_all(runs, models, deadline, args.report)

    with open(args.out / "summary.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["name", "epochs", "probe_step_ms", "steps_done", "train_wall_s", "status", "args"])
        for r in runs:
            rows = loss_log(models[r.name])
            done, wall = rows[-1] if rows else (0, 0.0)
            w.writerow([r.name, r.epochs, f"{r.step_seconds * 1e3:.2f}", done, f"{wall:.1f}", r.status, " ".join(r.args)])
            print(f"{r.name}: {done}/{r.epochs} steps in {wall:.0f} s, {r.status}", flush=True)
    print(f"total {time.perf_counter() - t0:.0f} s of a {args.budget:.0f} s budget", flush=True)
    if any(r.status.startswith("failed") for r in runs):
        sys.exit(1)


if __name__ == "__main__":
    main()
