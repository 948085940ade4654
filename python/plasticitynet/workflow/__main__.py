"""The evaluation's jobs, one command each (what the workflow's rules run; docs/workflow.md).

    python -m plasticitynet.workflow simulate KEY   [--config FILE] [--threads N]
    python -m plasticitynet.workflow metric KEY     [--config FILE]
    python -m plasticitynet.workflow study NAME     [--config FILE]
    python -m plasticitynet.workflow sweep NAME     [--config FILE]
    python -m plasticitynet.workflow bench NAME     [--config FILE] [--threads N]
    python -m plasticitynet.workflow list           [--config FILE]   every run of the plan, with its key
    python -m plasticitynet.workflow progress       [--config FILE] [--jobs N] [--every S]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from . import catalogue
from .plan import Plan


def load_plan(config: Path | None) -> Plan:
    values = {}
    if config is not None:
        try:
            values = json.loads(config.read_text())
        except (OSError, json.JSONDecodeError) as err:
            sys.exit(f"{config}: not a readable JSON configuration ({err})")
    return Plan(values)


def bench(plan: Plan, name: str, out: Path, threads: int) -> None:
    """One bench_table1 invocation of catalogue.BENCHMARKS; its table (stdout) to `out`, atomically."""
    options = catalogue.BENCHMARKS[name]
    binary = plan.path(plan.config["bench"])
    cmd = [str(binary), *options, "--threads", str(threads), "--scenes", str(plan.path(plan.config["scenes"]))]
    if int(plan.config["frames"]):  # every row that many frames (the tiny pipeline)
        n = str(plan.config["frames"])
        cmd += ["--frames", n, "--fem-frames", n, "--coupling-frames", n, "--stiff-frames", n]
    print(" ".join(cmd), flush=True)
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed (exit {done.returncode}):\n{done.stderr}")
    text = f"`{' '.join([binary.name, *cmd[1:]])}`\n\n{done.stdout}"
    for path in (out, plan.benchmark_record(name)):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        tmp.replace(path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m plasticitynet.workflow", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", choices=["simulate", "metric", "study", "sweep", "bench", "list", "progress"])
    p.add_argument("name", nargs="?")
    p.add_argument("--config", type=Path, help="the workflow's configuration as JSON (default: the defaults)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--jobs", type=int, default=1, help="progress: jobs running at once (for the estimate)")
    p.add_argument("--every", type=float, default=30.0, help="progress: seconds between reports")
    p.add_argument("--targets", nargs="*", default=["all"], help="progress: the targets being made")
    args = p.parse_args(argv)
    plan = load_plan(args.config)
    if args.command in ("simulate", "metric", "study", "sweep", "bench") and not args.name:
        p.error(f"{args.command} needs a name or key")
    if args.command == "simulate":
        from .runner import simulate
        if args.name not in plan.runs:
            sys.exit(f"no run with key {args.name} in the plan (its scene, models or the binary changed since the "
                     "workflow started?)")
        simulate(plan, args.name, args.threads)
    elif args.command == "metric":
        from .metrics import compute
        compute(plan, args.name)
    elif args.command == "study":
        from .tables import write_study
        write_study(plan, args.name)
    elif args.command == "sweep":
        from .tables import write_sweep
        write_sweep(plan, args.name)
    elif args.command == "bench":
        bench(plan, args.name, plan.benchmark_output(args.name), args.threads)
    elif args.command == "list":
        for key, job in plan.runs.items():
            print(key, job.describe())
    else:
        from .progress import watch
        watch(plan, args.targets, args.jobs, args.every)
    return 0


if __name__ == "__main__":
    sys.exit(main())
