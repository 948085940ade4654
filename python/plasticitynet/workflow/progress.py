"""A progress line for a running workflow, with an estimate of the time left (docs/workflow.md).

Every `watch` period it reads the plan's run folders: a run with done.json is finished; one with a
frames/stats.csv but no done.json is running (frames written, its own seconds per frame over its last
three frames); the others are waiting. The time left is the waiting runs' frames times a seconds-per-frame estimate plus the
running runs' remaining frames at their own rate, divided by the jobs at once. The estimate of a run
that has not started is the rate of the last finished run of the same scene and run name (kept in
<work>/timings.json, so that it improves as runs finish), else the mean rate of the finished runs.
"""
from __future__ import annotations

import json
import sys
import time

from .metrics import read_csv
from .plan import Plan


def _rate(plan: Plan, key: str, last: int | None = None) -> tuple[int, float | None]:
    """(frames written, seconds per frame) of a run from its stats.csv: the mean over all its frames, or
    over the `last` few (a running run's frames may slow down as it goes)."""
    rows = read_csv(plan.run_dir(key) / "frames" / "stats.csv")
    if not rows:
        return 0, None
    recent = rows[-last:] if last else rows
    return len(rows), sum(float(r["wall_s"]) for r in recent) / len(recent)


def _sweep_runs(plan: Plan, sweeps) -> set[str]:
    """The runs of some sweeps and the ground truths they are compared with."""
    points = [p for sweep in sweeps for p in sweep.points]
    return ({p["run_key"] for p in points}
            | {plan.metrics[p["metric_key"]].gt_key for p in points if p["metric_key"]})


def needed_runs(plan: Plan, targets: list[str]) -> list[str]:
    from .catalogue import STUDIES, TARGETS
    keys = set()
    for target in targets:
        if target.startswith("sweep_"):
            keys |= _sweep_runs(plan, [s for s in plan.sweeps.values() if f"sweep_{s.kind}" == target])
            continue
        studies = [target] if target in STUDIES else list(TARGETS[target].studies)
        for study in studies:
            for runs in plan.studies[study].runs.values():
                keys |= set(runs.values())
            for metrics in plan.studies[study].metrics.values():
                keys |= {plan.metrics[m].gt_key for m in metrics.values()}
        if target == "all":
            keys |= _sweep_runs(plan, plan.sweeps.values())
    return sorted(keys)


def report(plan: Plan, keys: list[str], jobs: int) -> str:
    timings_path = plan.work / "timings.json"
    timings = json.loads(timings_path.read_text()) if timings_path.exists() else {}
    done, running, waiting = [], [], []
    for key in keys:
        folder = plan.run_dir(key)
        job = plan.runs[key]
        name = f"{job.scene}/{job.run}"
        finished = (folder / "done.json").exists()
        written, rate = _rate(plan, key, last=None if finished else 3)
        if finished:
            done.append(key)
            if rate is not None:
                timings[name] = rate
        elif written:
            running.append((key, written, rate))
        else:
            waiting.append(key)
    timings_path.parent.mkdir(parents=True, exist_ok=True)
    timings_path.write_text(json.dumps(timings, indent=1))
    fallback = sum(timings.values()) / len(timings) if timings else None
    left, unknown = 0.0, 0
    for key, written, rate in running:
        left += max(plan.runs[key].frames - written, 0) * rate
    for key in waiting:
        job = plan.runs[key]
        rate = timings.get(f"{job.scene}/{job.run}", fallback)
        if rate is None:
            unknown += 1
        else:
            left += job.frames * rate
    left /= max(jobs, 1)
    now = ", ".join(f"{plan.runs[k].scene}/{plan.runs[k].run} {w}/{plan.runs[k].frames}" for k, w, _ in running)
    eta = (f"~{left:.0f} s left" if left < 120 else f"~{left / 60:.1f} min left") + (
        f" (+{unknown} runs not yet timed)" if unknown else "")
    return (f"[progress] runs: {len(done)} done, {len(running)} running, {len(waiting)} waiting; {eta}"
            + (f"; now: {now}" if now else ""))


def watch(plan: Plan, targets: list[str], jobs: int, every: float) -> None:
    keys = needed_runs(plan, targets)
    while True:
        print(report(plan, keys, jobs), file=sys.stderr, flush=True)
        time.sleep(every)
