"""Running one keyed simulation (docs/workflow.md).

A run's folder, <work>/runs/<key>/, holds what `pnet simulate` wrote (frames, stats.csv, steps.csv,
run.json), the scene it ran (scene.json, file paths absolute), job.json (what the key was made of, for
the record) and, last, done.json: the marker the workflow waits for. A run that stops with a simulation
error (pnet's exit status 1: a blow-up, an unconverged solve) is a result: its frames are evaluated and
done.json says it failed. Bad input (exit status 2) fails the job.
"""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict
from pathlib import Path

from .. import launch
from .plan import Plan, RunJob


def command(plan: Plan, job: RunJob, out: Path, threads: int) -> list[str]:
    return launch.simulate_command(plan.pnet, out / "scene.json", out / "frames", integrator=job.integrator,
                                   dt=job.dt, frames=job.frames, threads=threads, options=job.options)


def simulate(plan: Plan, key: str, threads: int = 1, log=print) -> Path:
    """Runs plan.runs[key] into its folder and writes done.json; returns the folder."""
    job = plan.runs[key]
    out = plan.run_dir(key)
    if out.exists():  # an interrupted attempt: the key says nothing in it can be kept
        shutil.rmtree(out)
    out.mkdir(parents=True)
    (out / "scene.json").write_text(json.dumps(job.scene_content, indent=1))
    (out / "job.json").write_text(json.dumps({**asdict(job), "pnet_version": plan.version}, indent=1))
    cmd = command(plan, job, out, threads)
    log(f"[run {key}] {job.describe()}: {' '.join(cmd)}")
    finished = launch.run(cmd, log=out / "pnet.log")
    status, wall = finished.status, finished.wall_s
    if status not in (0, 1):
        raise RuntimeError(f"{job.describe()}: pnet simulate exited {status} (bad input); see {out / 'pnet.log'}:\n"
                           + (out / "pnet.log").read_text()[-2000:])
    done = {"key": key, "scene": job.scene, "run": job.run, "exit_status": status, "failed": status != 0,
            "wall_s": wall, "frames_written": len(frame_numbers(out / "frames"))}
    tmp = out / "done.json.tmp"
    tmp.write_text(json.dumps(done, indent=1))
    os.replace(tmp, out / "done.json")
    if status:
        log(f"[run {key}] {job.describe()}: stopped with a simulation error after "
            f"{done['frames_written'] - 1} frames (evaluated as it is)")
    return out


def frame_numbers(folder: Path) -> list[int]:
    """The frame numbers of a run's particle (MPM) or mesh (FEM) PLY frames."""
    numbers = set()
    for p in folder.glob("frame_*.ply"):
        numbers.add(int(p.stem.split("_")[1]))
    return sorted(numbers)
