#!/usr/bin/env python3
"""Numerical damping of the time integrators (issue 34): the elastic ball of scenes/elastic_ball_2d.json
dropped onto a slip floor, run with explicit MPM at its CFL step and with the implicit integrator
(`lagged`: the ball is purely elastic, so this is the exact implicit elastic step) in backward Euler and
BDF2 at several steps. Per frame: the centre of mass's vertical velocity and the mechanical energy
sum m (|v|^2 / 2 + g y) (per metre of depth; the elastic energy is left out, small away from the floor).

    .venv/bin/python scripts/elastic_ball.py [--dts 1e-4 1e-3 1e-2] [--capped-dts 1e-2 --advection-cfl 0.2]
        [--out notebooks/results/time_integrator]

Writes OUT/elastic_ball.csv (run, frame, time, com_vy, energy), OUT/elastic_ball.md (the coefficient of
restitution: the largest upward centre-of-mass velocity after the impact over the largest downward one
before it, and the energy kept at the last frame) and OUT/elastic_ball.png.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "elastic_ball_2d.json"


def run(integrator: str, dt: float, time_integrator: str | None, frames: int, threads: int,
        advection_cfl: float = 0.0) -> dict:
    import plasticitynet_sim as pns

    pns.set_threads(threads)
    solver = {"time_integrator": time_integrator, "newton_tolerance": 1e-6} if time_integrator else None
    if solver:
        solver["advection_cfl"] = advection_cfl  # 0 (off) unless asked: the steps as given
    sim = pns.Simulation(str(SCENE), integrator=integrator, dt=dt, **({"solver": solver} if solver else {}))
    g = 9.8
    rows = []
    start = time.perf_counter()
    for frame in range(frames + 1):
        if frame:
            try:
                sim.advance(1)
            except pns.SimulationError as err:  # kept in the table: a large step may blow up
                return {"rows": rows, "seconds": time.perf_counter() - start, "steps": sim.total_steps,
                        "error": str(err)}
        m = np.asarray(sim.mass)
        v = np.asarray(sim.velocities)
        x = np.asarray(sim.positions)
        rows.append((frame, sim.time, float((m * v[:, 1]).sum() / m.sum()),
                     float((m * (0.5 * (v**2).sum(1) + g * x[:, 1])).sum())))
    return {"rows": rows, "seconds": time.perf_counter() - start, "steps": sim.total_steps}


def restitution(rows) -> tuple[float, float]:
    """(coefficient of restitution, energy at the last frame / energy at the first)."""
    vy = np.array([r[2] for r in rows])
    impact = int(np.argmin(vy))
    down = -vy[impact]
    up = vy[impact:].max()
    return up / down, rows[-1][3] / rows[0][3]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dts", type=float, nargs="+", default=[1e-4, 1e-3, 1e-2])
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--capped-dts", type=float, nargs="*", default=[1e-2],
                   help="steps run again with the advection limit (docs/solver.md)")
    p.add_argument("--advection-cfl", type=float, default=0.2, help="the limit of those runs (0.2)")
    p.add_argument("--out", type=Path, default=ROOT / "notebooks" / "results" / "time_integrator")
    args = p.parse_args()
    runs = {"explicit (CFL)": ("explicit", 0.0, None, 0.0)}
    for dt in args.dts:
        for ti in ("backward_euler", "bdf2"):
            runs[f"{ti} {dt:g}"] = ("lagged", dt, ti, 0.0)
    for dt in args.capped_dts:
        for ti in ("backward_euler", "bdf2"):
            runs[f"{ti} {dt:g}, advection_cfl {args.advection_cfl:g}"] = ("lagged", dt, ti, args.advection_cfl)
    args.out.mkdir(parents=True, exist_ok=True)
    results = {}
    for name, (integrator, dt, ti, cap) in runs.items():
        results[name] = run(integrator, dt, ti, args.frames, args.threads, cap)
        r = results[name]
        if "error" in r:
            print(f"{name:>22}: {r['error']}", flush=True)
            continue
        e, kept = restitution(r["rows"])
        print(f"{name:>22}: restitution {e:.3f}, energy kept {kept:.3f}, {r['steps']} steps, {r['seconds']:.1f} s",
              flush=True)
    with open(args.out / "elastic_ball.csv", "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["run", "frame", "time_s", "com_vy_m_per_s", "energy_j_per_m"])
        for name, r in results.items():
            for row in r["rows"]:
                w.writerow([name, row[0], f"{row[1]:.6g}", f"{row[2]:.6g}", f"{row[3]:.6g}"])
    explicit_e = restitution(results["explicit (CFL)"]["rows"])[0]
    lines = ["| run | steps | restitution | vs explicit | energy kept at the last frame | wall s |", "|---|---|---|---|---|---|"]
    for name, r in results.items():
        if "error" in r:
            lines.append(f"| {name} | {r['steps']} | blew up: {r['error'].split(':')[0]} | | | {r['seconds']:.1f} |")
            continue
        e, kept = restitution(r["rows"])
        lines.append(f"| {name} | {r['steps']} | {e:.3f} | {e / explicit_e - 1:+.1%} | {kept:.3f} | {r['seconds']:.1f} |")
    (args.out / "elastic_ball.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    for name, r in results.items():
        t = [row[1] for row in r["rows"]]
        style = "-" if "bdf2" in name else ("--" if "backward" in name else ":")
        a.plot(t, [row[2] for row in r["rows"]], style, label=name)
        b.plot(t, [row[3] / r["rows"][0][3] for row in r["rows"]], style, label=name)
    a.set_xlabel("time (s)")
    a.set_ylabel("centre-of-mass vertical velocity (m/s)")
    b.set_xlabel("time (s)")
    b.set_ylabel("kinetic + gravitational energy / initial")
    a.legend(fontsize=7)
    fig.suptitle("elastic ball on a slip floor: explicit at CFL, backward Euler and BDF2")
    fig.tight_layout()
    fig.savefig(args.out / "elastic_ball.png", dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
