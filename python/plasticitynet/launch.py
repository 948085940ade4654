"""Running `pnet simulate` from Python: the one place that writes its command line, runs it and runs many
at once (the evaluation workflow's keyed runs, plasticitynet.workflow.runner; the granular-collapse
study, scripts/granular_collapse.py; the physics check, scripts/physics_check.py).

`pnet simulate` exits 0 when every frame was written, 1 after a simulation error (the frames before it
are valid: a blow-up is a result) and 2 on bad input (nothing written).
"""
from __future__ import annotations

import concurrent.futures
import importlib.util
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence, TypeVar

ROOT = Path(__file__).resolve().parents[2]
T = TypeVar("T")


def with_simulator() -> None:
    """Re-runs the calling script with the project's .venv Python when this one cannot import
    plasticitynet_sim (built into .venv by scripts/setup.sh), as train.py does for torch."""
    if importlib.util.find_spec("plasticitynet_sim") is not None:
        return
    venv = ROOT / ".venv" / "bin" / "python"
    if not venv.exists() or Path(sys.prefix).resolve() == (ROOT / ".venv").resolve():
        sys.exit(f"{sys.argv[0]}: plasticitynet_sim is not importable; run scripts/setup.sh first")
    os.execv(str(venv), [str(venv), *sys.argv])


def default_pnet() -> Path:
    """The `pnet` that scripts/setup.sh builds."""
    return ROOT / "build" / "cpp" / "pnet"


def simulate_command(pnet: str | Path, scene: str | Path, out: str | Path, *, integrator: str | None = None,
                     dt: float | str | None = None, frames: int | None = None, threads: int | None = 1,
                     overwrite: bool = False, options: Sequence[str] = ()) -> list[str]:
    """The command line of one run; None leaves an option at the scene's (dt: repr, so that the step is
    exact; a string is passed as it is)."""
    cmd = [str(pnet), "simulate", str(scene)]
    if integrator is not None:
        cmd += ["--integrator", integrator]
    if dt is not None:
        cmd += ["--dt", dt if isinstance(dt, str) else repr(float(dt))]
    if frames is not None:
        cmd += ["--frames", str(frames)]
    if threads is not None:
        cmd += ["--threads", str(threads)]
    cmd += ["--out", str(out)]
    if overwrite:
        cmd.append("--overwrite")
    return cmd + [str(o) for o in options]


@dataclass
class Finished:
    status: int      # pnet's exit status: 0 done, 1 a simulation error, 2 bad input
    wall_s: float    # seconds the command took
    output: str      # what it printed (stdout and stderr), unless it went to a log file


def run(cmd: Sequence[str], log: Path | None = None, echo: bool = False) -> Finished:
    """Runs a command; its output goes to `log` (a file) when given, else is captured."""
    if echo:
        print("+", " ".join(cmd), flush=True)
    start = time.perf_counter()
    if log is not None:
        with open(log, "w") as f:
            status = subprocess.run(list(cmd), stdout=f, stderr=subprocess.STDOUT).returncode
        output = ""
    else:
        result = subprocess.run(list(cmd), capture_output=True, text=True)
        status, output = result.returncode, result.stdout + result.stderr
    return Finished(status, time.perf_counter() - start, output)


def run_all(jobs: Iterable[tuple[object, Callable[[], T]]], n_jobs: int,
            report: Callable[[int, int, object, T], None] | None = None) -> dict[object, T]:
    """Runs each job's function, n_jobs at a time (threads: each waits on its own process); returns
    {key: result} and calls report(done, total, key, result) as each finishes. The first error is
    raised once the running jobs have ended."""
    jobs = list(jobs)
    results: dict[object, T] = {}
    with concurrent.futures.ThreadPoolExecutor(max(1, n_jobs)) as pool:
        futures = {pool.submit(fn): key for key, fn in jobs}
        for done, future in enumerate(concurrent.futures.as_completed(futures), 1):
            key = futures[future]
            results[key] = future.result()
            if report is not None:
                report(done, len(jobs), key, results[key])
    return results
