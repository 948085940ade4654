#!/usr/bin/env python3
"""Identify a material parameter from an observed run, by the adjoint of the implicit step (docs/adjoint.md).

    scripts/identify.py youngs_modulus [--true-E 2e5] [--start-E 1e5] [--out out/identify]

youngs_modulus: an elastic box (FEM, neo-Hookean, bouncing_box() below) dropped onto the ground
bounces. The observed run is `pnet simulate` of that scene at --true-E with the implicit integrator
the fit uses (`lagged`: backward Euler on the elastic energy, 1e-3 s, Newton to 1e-10 m/s), read back
from its frames; the fit never sees --true-E. (Explicit FEM is not the observation here: backward
Euler's impacts are nearly inelastic, so at any E it does not follow explicit's elastic rebound: 6.3 cm
apart after 0.1 s even at 1e-4 s, docs/adjoint.md.) The fit runs implicit rollouts from --start-E and
moves log E by L-BFGS on the mean squared distance of the nodes to the observed ones at every frame,
each evaluation a forward and a backward pass (plasticitynet.adjoint). Prints the optimizer's path and
the result beside the true value, and plots the loss along the path (out/identify/youngs_modulus.png).

The other identifications issue 57 asks for (a sand column's friction angle, a metal's yield stress)
need the adjoint of the MPM step and of the return mapping, which are not written yet.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

from plasticitynet import launch  # noqa: E402

launch.with_simulator()

import numpy as np  # noqa: E402
import torch  # noqa: E402

from plasticitynet import adjoint, frames  # noqa: E402

FRAME_DT, FRAMES, DT = 0.01, 10, 1e-3


def bouncing_box(E: float) -> dict:
    """A 6 x 3 cm elastic box (1000 kg/m^3, nu 0.3) 1 cm above the ground, falling at 1 m/s; 0.1 s."""
    return {
        "name": "bouncing_box_2d",
        "description": "scripts/identify.py: an elastic box bouncing on the ground, for identifying E.",
        "dim": 2, "domain": {"min": [0, -0.01], "max": [0.2, 0.2]},
        "gravity": [0, -9.8], "frame_dt": FRAME_DT, "frames": FRAMES,
        "integrator": {"name": "lagged", "dt": DT, "newton_tolerance": 1e-10, "max_newton_iterations": 1000},
        "meshes": [{"shape": "box", "min": [0.07, 0.01], "max": [0.13, 0.04], "element_size": 0.01,
                    "velocity": [0, -1.0],
                    "material": {"name": "rubber", "density": 1000,
                                 "elasticity": {"model": "neo_hookean_metal", "E": E, "nu": 0.3},
                                 "plasticity": {"model": "none"}}}],
        "ground": {"height": 0}, "contact": {"friction": 0},
    }


def observed_frames(E: float, out: Path) -> np.ndarray:
    """The observed run's node positions at frames 1..FRAMES, (FRAMES, nodes, 2)."""
    out.mkdir(parents=True, exist_ok=True)
    scene = out / "observed_scene.json"
    scene.write_text(json.dumps(bouncing_box(E), indent=1))
    run = out / "observed"
    cmd = launch.simulate_command(launch.default_pnet(), scene, run, threads=2, overwrite=run.exists())
    done = launch.run(cmd, echo=True)
    if done.status != 0:
        sys.exit(f"the observed run failed ({done.status}):\n{done.output}")
    return np.stack([frames.read_mesh_ply(run / f"frame_{k:05d}.ply").position for k in range(1, FRAMES + 1)])


def identify_youngs_modulus(true_E: float, start_E: float, out: Path, max_evaluations: int) -> int:
    observed = torch.from_numpy(observed_frames(true_E, out))
    scene = bouncing_box(start_E)  # the fit's scene: E is what it moves
    steps_per_frame = round(FRAME_DT / DT)
    states = [k * steps_per_frame for k in range(1, FRAMES + 1)]
    log_E = torch.tensor(math.log(start_E), dtype=torch.float64, requires_grad=True)
    optimizer = torch.optim.LBFGS([log_E], lr=1.0, max_iter=max_evaluations, max_eval=max_evaluations,
                                  tolerance_grad=1e-12, tolerance_change=1e-12, line_search_fn="strong_wolfe")
    path = []

    def closure():
        optimizer.zero_grad()
        start = time.perf_counter()
        x = adjoint.fem_positions(scene, torch.exp(log_E), None, FRAMES * steps_per_frame, DT, states)
        loss = ((x - observed) ** 2).sum(dim=-1).mean()
        loss.backward()
        path.append((float(torch.exp(log_E)), float(loss), float(log_E.grad), time.perf_counter() - start))
        E, L, g, seconds = path[-1]
        print(f"evaluation {len(path):2d}: E {E:.6g} Pa, loss {L:.6g} m^2, dL/dlogE {g:.4g} ({seconds:.2f} s)",
              flush=True)
        return loss

    optimizer.step(closure)
    best = min(path, key=lambda p: p[1])
    error = abs(best[0] - true_E) / true_E
    print(f"identified E = {best[0]:.6g} Pa against the true {true_E:.6g} Pa ({100 * error:.3g}%), "
          f"{len(path)} evaluations (a forward and a backward pass each)")
    (out / "youngs_modulus.json").write_text(json.dumps(
        {"true_E": true_E, "start_E": start_E, "identified_E": best[0], "relative_error": error,
         "path": [{"E": E, "loss": L, "dloss_dlogE": g, "seconds": s} for E, L, g, s in path]}, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.semilogy([p[1] for p in path], "o-")
        ax.set_xlabel("evaluation (forward + backward)")
        ax.set_ylabel("loss (m$^2$)")
        ax.set_title(f"E: {start_E:.3g} -> {best[0]:.4g} Pa (true {true_E:.3g})")
        fig.tight_layout()
        fig.savefig(out / "youngs_modulus.png", dpi=120)
        print(f"wrote {out / 'youngs_modulus.json'} and {out / 'youngs_modulus.png'}")
    except ImportError:
        print(f"wrote {out / 'youngs_modulus.json'} (no matplotlib: no plot)")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", choices=["youngs_modulus"])
    parser.add_argument("--true-E", type=float, default=2e5, help="the observed run's E, Pa (the fit never sees it)")
    parser.add_argument("--start-E", type=float, default=1e5, help="the fit's first E, Pa")
    parser.add_argument("--max-evaluations", type=int, default=20)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "identify")
    args = parser.parse_args()
    return identify_youngs_modulus(args.true_E, args.start_E, args.out, args.max_evaluations)


if __name__ == "__main__":
    sys.exit(main())
