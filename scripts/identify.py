#!/usr/bin/env python3
"""Identify a material parameter from an observed run, by the adjoint of the implicit step (docs/adjoint.md).

    scripts/identify.py youngs_modulus [--true-E 2e5] [--start-E 1e5] [--out out/identify]
    scripts/identify.py ball_youngs_modulus [--true-E 1e5] [--start-E 5e4] [--observed explicit|implicit]
    scripts/identify.py yield_stress [--true-h0 0.004] [--start-h0 0.006] [--out out/identify]
        [--yield-scene cantilever|impact] [--observed explicit|implicit]
    scripts/identify.py friction_angle [--true-phi 27] [--start-phi 35] [--observed explicit|implicit]
        [--loss positions|profile]
    [--integrator lagged|return_map]: the fit's steps (default lagged for E, return_map for the yield stress
    and the friction angle)
    [--dt S]: the fit's step (default 1e-3 s; the cantilever 5e-4 s)

youngs_modulus: an elastic box (FEM, neo-Hookean, bouncing_box() below) dropped onto the ground
bounces. The observed run is `pnet simulate` of that scene at --true-E with the implicit integrator
the fit uses (`lagged`: backward Euler on the elastic energy, 1e-3 s, Newton to 1e-10 m/s), read back
from its frames; the fit never sees --true-E. (Explicit FEM is not the observation here: backward
Euler's impacts are nearly inelastic, so at any E it does not follow explicit's elastic rebound: 6.3 cm
apart after 0.1 s even at 1e-4 s, docs/adjoint.md.) The fit runs implicit rollouts from --start-E and
moves log E by L-BFGS on the mean squared distance of the nodes to the observed ones at every frame,
each evaluation a forward and a backward pass (plasticitynet.adjoint). Prints the optimizer's path and
the result beside the true value, and plots the loss along the path (out/identify/youngs_modulus.png).

yield_stress: a metal cantilever (von Mises with StVK-Hencky: the metal preset's E 1e7 Pa, nu 0.3,
hardening coefficient 0.1; 10 x 1 cm, its left end clamped) sags under gravity for 0.1 s and yields at its
root (--yield-scene impact: a metal block hits the ground at 4 m/s and flattens plastically instead). The
observed run is `pnet simulate` at the initial hardening --true-h0 (tau_Y = 2 mu h0): for the cantilever
explicit FEM at 1e-5 s, the ground truth integrator, so that the fit's own step error is in the result (a
bar that bends has no impact for backward Euler to damp); for the impact the fit's implicit step. The fit
moves log h0 from --start-h0 the same way.

ball_youngs_modulus: scenes/elastic_ball_2d.json, an elastic disk (MPM, StVK-Hencky) dropped at 2 m/s onto
the slip floor, its first 0.2 s (the fall and the bounce). The observed run is explicit MPM at 1e-5 s at
--true-E; the fit moves log E by L-BFGS on the mean squared distance of the particles at the 20 frames,
each evaluation an implicit MPM rollout at --dt (2.5e-4 s) and its adjoint (plasticitynet.adjoint
.mpm_positions). The implicit bounce's own damping is in the result (docs/adjoint.md).

friction_angle: the sand column (scenes/sand_column_2d.json at twice its dx, 1846 particles, its AFLIP transfers
and Coulomb floor, the floor's friction known; its first 0.3 s, the collapse) observed by explicit MPM at 1e-5 s
at --true-phi, fitted from --start-phi through the MPM adjoint of `return_map`'s step at --dt (1e-3 s), the
particles' mean squared distance at the 15 frames (--loss profile: the deposits' height profiles). The implicit
step's own distance from explicit's is in the result (docs/adjoint.md). --floor slip: APIC transfers and a
slip floor instead (the fit before the adjoint had the Coulomb floor). `lagged` does not identify the angle
(its column is far from explicit's, and its fit runs to 0 degrees; on the Coulomb floor it is refused).
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

import plasticitynet_sim  # noqa: E402

from plasticitynet import adjoint, frames  # noqa: E402

FRAME_DT, FRAMES, DT = 0.01, 10, 1e-3
BALL_FRAMES = 20
SAND_FRAMES = 15


def bouncing_box(E: float, integrator: str = "lagged", dt: float = DT) -> dict:
    """A 6 x 3 cm elastic box (1000 kg/m^3, nu 0.3) 1 cm above the ground, falling at 1 m/s; 0.1 s."""
    return {
        "name": "bouncing_box_2d",
        "description": "scripts/identify.py: an elastic box bouncing on the ground, for identifying E.",
        "dim": 2, "domain": {"min": [0, -0.01], "max": [0.2, 0.2]},
        "gravity": [0, -9.8], "frame_dt": FRAME_DT, "frames": FRAMES,
        "integrator": {"name": integrator, "dt": dt, "newton_tolerance": 1e-10, "max_newton_iterations": 1000},
        "meshes": [{"shape": "box", "min": [0.07, 0.01], "max": [0.13, 0.04], "element_size": 0.01,
                    "velocity": [0, -1.0],
                    "material": {"name": "rubber", "density": 1000,
                                 "elasticity": {"model": "neo_hookean_metal", "E": E, "nu": 0.3},
                                 "plasticity": {"model": "none"}}}],
        "ground": {"height": 0}, "contact": {"friction": 0},
    }


def metal_block(h0: float, integrator: str = "lagged", dt: float = DT) -> dict:
    """A 6 x 3 cm metal block (the metal preset's elasticity and hardening, initial hardening h0) 2 mm
    above the ground, falling at 4 m/s; 20 ms in frames of 2 ms."""
    return {
        "name": "metal_block_2d",
        "description": "scripts/identify.py: a metal block flattening on the ground, for identifying its yield stress.",
        "dim": 2, "domain": {"min": [0, -0.01], "max": [0.2, 0.2]},
        "gravity": [0, -9.8], "frame_dt": 0.002, "frames": FRAMES,
        "integrator": {"name": integrator, "dt": dt, "newton_tolerance": 1e-10, "max_newton_iterations": 1000},
        "meshes": [{"shape": "box", "min": [0.07, 0.002], "max": [0.13, 0.032], "element_size": 0.01,
                    "velocity": [0, -4.0],
                    "material": {"name": "metal", "density": 7800, "initial_hardening": h0,
                                 "elasticity": {"model": "stvk_hencky", "E": 1e7, "nu": 0.3},
                                 "plasticity": {"model": "von_mises", "hardening_coefficient": 0.1}}}],
        "ground": {"height": 0}, "contact": {"friction": 0},
    }


def cantilever(h0: float, integrator: str = "lagged", dt: float = DT) -> dict:
    """A metal bar 10 x 1 cm (the metal preset's elasticity and hardening, initial hardening h0) clamped at
    its left end, released at rest: it sags under gravity and yields at its root; 0.1 s."""
    return {
        "name": "metal_cantilever_2d",
        "description": "scripts/identify.py: a clamped metal bar sagging under gravity, for identifying its yield "
                       "stress.",
        "dim": 2, "domain": {"min": [-0.01, -0.1], "max": [0.15, 0.1]},
        "gravity": [0, -9.8], "frame_dt": FRAME_DT, "frames": FRAMES,
        "integrator": {"name": integrator, "dt": dt, "newton_tolerance": 1e-10, "max_newton_iterations": 1000},
        "meshes": [{"shape": "box", "min": [0.0, 0.05], "max": [0.1, 0.06], "element_size": 0.005,
                    "material": {"name": "metal", "density": 7800, "initial_hardening": h0,
                                 "elasticity": {"model": "stvk_hencky", "E": 1e7, "nu": 0.3},
                                 "plasticity": {"model": "von_mises", "hardening_coefficient": 0.1}},
                    "clamp": {"min": [-0.001, 0.049], "max": [1e-9, 0.061]}}],
    }


def elastic_ball(E: float, integrator: str = "lagged", dt: float = 2.5e-4) -> dict:
    """scenes/elastic_ball_2d.json (an elastic disk, StVK-Hencky, dropped at 2 m/s onto the slip floor) at
    Young's modulus E for its first BALL_FRAMES frames (the fall and the bounce), the implicit steps at dt
    without the advection limit (the adjoint's steps are fixed)."""
    scene = json.loads((ROOT / "scenes" / "elastic_ball_2d.json").read_text())
    scene["objects"][0]["material"]["elasticity"]["E"] = E
    scene["frames"] = BALL_FRAMES
    scene["integrator"] = {"name": integrator, "dt": dt, "advection_cfl": 0, "newton_tolerance": 1e-10,
                           "max_newton_iterations": 1000}
    return scene


def sand_column(friction_angle: float, integrator: str = "return_map", dt: float = 1e-3, floor: str = "coulomb") -> dict:
    """scenes/sand_column_2d.json's column (sand, E 3.537e5 Pa) at twice its dx, at the friction angle phi,
    for its first SAND_FRAMES frames (0.3 s of the collapse), the implicit steps at dt without the
    advection limit, Newton to 1e-10 m/s. floor "coulomb": the shipped column's AFLIP transfers and Coulomb
    floor (mu 0.5774, known to the fit); "slip": APIC transfers and a slip floor (the fit before the MPM
    adjoint had the Coulomb floor)."""
    scene = json.loads((ROOT / "scenes" / "sand_column_2d.json").read_text())
    scene["dx"] *= 2  # 1/128 m: about 1900 particles (a quarter of the shipped column's), for the fit's time
    scene["objects"][0]["min"][1] = 3 * scene["dx"]  # on the floor's wall nodes, as the shipped column
    if floor == "slip":
        scene.pop("transfer", None)
        scene["boundary"] = {"walls": "slip", "sticky_floor_cells": 0}
    scene["objects"][0]["material"]["plasticity"]["friction_angle_deg"] = friction_angle
    scene["frames"] = SAND_FRAMES
    scene["integrator"] = {"name": integrator, "dt": dt, "advection_cfl": 0, "newton_tolerance": 1e-10,
                           "max_newton_iterations": 1000}
    return scene


def observed_frames(scene_dict: dict, out: Path, name: str, with_mass: bool = False):
    """The observed run's node (particle) positions at frames 1..frames, (frames, points, dim); with_mass
    (particles): and their masses, (frames, points)."""
    out.mkdir(parents=True, exist_ok=True)
    scene = out / f"{name}_observed_scene.json"
    scene.write_text(json.dumps(scene_dict, indent=1))
    run = out / f"{name}_observed"
    cmd = launch.simulate_command(launch.default_pnet(), scene, run, threads=2, overwrite=run.exists())
    done = launch.run(cmd, echo=True)
    if done.status != 0:
        sys.exit(f"the observed run failed ({done.status}):\n{done.output}")
    count = scene_dict["frames"]
    if with_mass:
        read = [plasticitynet_sim.read_particle_frame(str(run / f"frame_{k:05d}.ply")) for k in range(1, count + 1)]
        return np.stack([d["position"] for d in read]), np.stack([d["mass"] for d in read])
    if "objects" in scene_dict:
        return np.stack([frames.read_particle_positions(run / f"frame_{k:05d}.ply") for k in range(1, count + 1)])
    return np.stack([frames.read_mesh_ply(run / f"frame_{k:05d}.ply").position for k in range(1, count + 1)])


def explicit_observation(scene: dict) -> dict:
    """The same scene under explicit FEM or MPM at 1e-5 s (the ground truth integrator)."""
    return {**scene, "integrator": {"name": "explicit", "dt": 1e-5}}


def fit_and_observed(make, start_value: float, true_value: float, observed: str, fit_label: str, dt: float,
                     kind: str = "", note: str = "") -> tuple[dict, dict]:
    """The fit's scene make(start_value) and the observed run's make(true_value), that one under explicit at 1e-5 s
    where observed is "explicit"; prints which runs they are (kind: " MPM" for particle scenes)."""
    scene, truth = make(start_value), make(true_value)
    if observed == "explicit":
        truth = explicit_observation(truth)
    print(f"observed: {truth['integrator']['name']}{kind} at {truth['integrator']['dt']:g} s; the fit: {fit_label} at "
          f"{dt:g} s{note}")
    return scene, truth


def fit(name: str, symbol: str, unit: str, scene: dict, frame_dt: float, true_value: float, start_value: float,
        positions, out: Path, max_evaluations: int, dt: float = DT, profile=None) -> int:
    """L-BFGS on log p of the mean squared nodal distance to the observed frames; positions(scene, p, states)
    is the differentiable rollout. With profile = (the fit's particle masses, density): the mean squared
    difference of the deposits' height profiles instead (adjoint.height_profile; no particle correspondence)."""
    if profile is None:
        observed = torch.from_numpy(observed_frames(scene, out, name))

        def discrepancy(x):  # m^2
            return ((x - observed) ** 2).sum(dim=-1).mean()
    else:
        fit_mass, density = profile
        x_seen, m_seen = observed_frames(scene, out, name, with_mass=True)
        observed = torch.stack([adjoint.height_profile(torch.from_numpy(x), m, scene, density)
                                for x, m in zip(x_seen, m_seen)])

        def discrepancy(x):  # m^2
            return ((adjoint.height_profile(x, fit_mass, scene, density) - observed) ** 2).mean()
    steps_per_frame = round(frame_dt / dt)
    frame_count = scene["frames"]
    states = [k * steps_per_frame for k in range(1, frame_count + 1)]
    log_p = torch.tensor(math.log(start_value), dtype=torch.float64, requires_grad=True)
    optimizer = torch.optim.LBFGS([log_p], lr=1.0, max_iter=max_evaluations, max_eval=max_evaluations,
                                  tolerance_grad=1e-14, tolerance_change=1e-14, line_search_fn="strong_wolfe")
    path = []

    class Budget(Exception):
        """max_evaluations reached: L-BFGS's strong-Wolfe search may ask for more within its last iteration."""

    def closure():
        if len(path) >= max_evaluations:
            raise Budget
        optimizer.zero_grad()
        start = time.perf_counter()
        x = positions(torch.exp(log_p), frame_count * steps_per_frame, states)
        loss = 1e6 * discrepancy(x)  # mm^2
        loss.backward()
        path.append((float(torch.exp(log_p)), float(loss), float(log_p.grad), time.perf_counter() - start))
        p, L, g, seconds = path[-1]
        print(f"evaluation {len(path):2d}: {symbol} {p:.6g} {unit}, loss {L:.6g} mm^2, dL/dlog{symbol} {g:.4g} "
              f"({seconds:.2f} s)", flush=True)
        return loss

    try:
        optimizer.step(closure)
    except Budget:
        print(f"stopped at {max_evaluations} evaluations (--max-evaluations)")
    best = min(path, key=lambda q: q[1])
    error = abs(best[0] - true_value) / true_value
    print(f"identified {symbol} = {best[0]:.6g} {unit} against the true {true_value:.6g} {unit} ({100 * error:.3g}%), "
          f"{len(path)} evaluations (a forward and a backward pass each)")
    (out / f"{name}.json").write_text(json.dumps(
        {"parameter": symbol, "true": true_value, "start": start_value, "identified": best[0], "relative_error": error,
         "path": [{"value": p, "loss_mm2": L, "dloss_dlog": g, "seconds": s} for p, L, g, s in path]}, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.semilogy([q[1] for q in path], "o-")
        ax.set_xlabel("evaluation (forward + backward)")
        ax.set_ylabel("loss (mm$^2$)")
        ax.set_title(f"{symbol}: {start_value:.3g} -> {best[0]:.4g} {unit} (true {true_value:.3g})")
        fig.tight_layout()
        fig.savefig(out / f"{name}.png", dpi=120)
        print(f"wrote {out / (name + '.json')} and {out / (name + '.png')}")
    except ImportError:
        print(f"wrote {out / (name + '.json')} (no matplotlib: no plot)")
    return 0


def identify_youngs_modulus(true_E: float, start_E: float, out: Path, max_evaluations: int, integrator: str,
                            dt: float = DT) -> int:
    scene = bouncing_box(start_E, integrator, dt)  # the fit's scene: E is what it moves

    def positions(E, steps, states):
        return adjoint.fem_positions(scene, E, None, steps, dt, states, integrator=integrator)

    return fit("youngs_modulus", "E", "Pa", bouncing_box(true_E, integrator, dt), FRAME_DT, true_E, start_E, positions,
               out, max_evaluations, dt)


def identify_ball_youngs_modulus(true_E: float, start_E: float, out: Path, max_evaluations: int, observed: str,
                                 dt: float) -> int:
    scene, truth = fit_and_observed(lambda E: elastic_ball(E, "lagged", dt), start_E, true_E, observed, "lagged", dt,
                                    " MPM", " (elastic: every implicit MPM integrator's step)")

    def positions(E, steps, states):
        return adjoint.mpm_positions(scene, E, None, steps, dt, states)

    return fit("ball_youngs_modulus", "E", "Pa", truth, FRAME_DT, true_E, start_E, positions, out, max_evaluations,
               dt)


def identify_friction_angle(true_phi: float, start_phi: float, out: Path, max_evaluations: int, observed: str,
                            dt: float, integrator: str = "return_map", loss: str = "positions",
                            floor: str = "coulomb") -> int:
    scene, truth = fit_and_observed(lambda phi: sand_column(phi, integrator, dt, floor), start_phi, true_phi, observed,
                                    integrator, dt, " MPM")
    E = torch.tensor(float(scene["objects"][0]["material"]["elasticity"]["E"]), dtype=torch.float64)

    def positions(phi, steps, states):
        return adjoint.mpm_positions(scene, E, None, steps, dt, states, newton_tolerance=1e-10, friction_angle=phi,
                                     integrator=integrator)

    profile = None
    if loss == "profile":
        material = scene["objects"][0]["material"]
        masses = plasticitynet_sim.MpmRollout(scene, integrator=integrator).start()["mass"]
        profile = (masses, float(material["density"]))
        print("the loss: the deposits' height profiles on the scene's grid at each frame (no particle correspondence)")
    name = "friction_angle" + ("" if loss == "positions" else "_profile") + ("" if floor == "coulomb" else "_slip_floor")
    return fit(name, "phi", "deg", truth, scene["frame_dt"], true_phi, start_phi, positions, out, max_evaluations, dt,
               profile)


def identify_yield_stress(true_h0: float, start_h0: float, out: Path, max_evaluations: int, integrator: str,
                          bar: str = "cantilever", observed: str = "explicit", dt: float = 5e-4) -> int:
    make, frame_dt = (cantilever, FRAME_DT) if bar == "cantilever" else (metal_block, 0.002)
    scene, truth = fit_and_observed(lambda h0: make(h0, integrator, dt), start_h0, true_h0, observed, integrator, dt)
    mu = 1e7 / (2 * 1.3)
    print(f"yield stress tau_Y = 2 mu h0 with mu = {mu:.6g} Pa: the true {2 * mu * true_h0:.6g} Pa")

    def positions(h0, steps, states):
        return adjoint.fem_positions(scene, torch.tensor(1e7, dtype=torch.float64), None, steps, dt, states,
                                     initial_hardening=h0, integrator=integrator)

    status = fit("yield_stress", "h0", "", truth, frame_dt, true_h0, start_h0, positions, out, max_evaluations, dt)
    found = json.loads((out / "yield_stress.json").read_text())["identified"]
    print(f"tau_Y = {2 * mu * found:.6g} Pa against the true {2 * mu * true_h0:.6g} Pa")
    return status


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", choices=["youngs_modulus", "yield_stress", "ball_youngs_modulus", "friction_angle"])
    parser.add_argument("--true-phi", type=float, default=27.0,
                        help="friction_angle: the observed run's angle, degrees (the fit never sees it)")
    parser.add_argument("--start-phi", type=float, default=35.0, help="friction_angle: the fit's first angle")
    parser.add_argument("--true-E", type=float, default=None,
                        help="the observed run's E, Pa (the fit never sees it; default 2e5, the ball 1e5)")
    parser.add_argument("--start-E", type=float, default=None, help="the fit's first E, Pa (default 1e5, the ball 5e4)")
    parser.add_argument("--true-h0", type=float, default=0.004,
                        help="the observed run's initial hardening h0 = tau_Y / (2 mu) (the fit never sees it)")
    parser.add_argument("--start-h0", type=float, default=0.006, help="the fit's first h0")
    parser.add_argument("--max-evaluations", type=int, default=20)
    parser.add_argument("--integrator", choices=["lagged", "return_map"], default=None,
                        help="the fit's steps (and the observed run's, where it is implicit); default lagged for "
                             "youngs_modulus, return_map for yield_stress and friction_angle")
    parser.add_argument("--yield-scene", choices=["cantilever", "impact"], default="cantilever",
                        help="yield_stress: the clamped bar sagging under gravity, or the block hitting the ground")
    parser.add_argument("--observed", choices=["explicit", "implicit"], default=None,
                        help="yield_stress, ball_youngs_modulus, friction_angle: the observed run by explicit FEM or "
                             "MPM at 1e-5 s (the default, but for the impact) or by the fit's own implicit step")
    parser.add_argument("--dt", type=float, default=None,
                        help="the fit's step, s (default 1e-3; the cantilever 5e-4)")
    parser.add_argument("--loss", choices=["positions", "profile"], default="positions",
                        help="friction_angle: the particles' mean squared distance to the observed ones, or the "
                             "deposits' height profiles on the grid (no particle correspondence)")
    parser.add_argument("--floor", choices=["coulomb", "slip"], default="coulomb",
                        help="friction_angle: the shipped column's Coulomb floor and AFLIP transfers (default), or a "
                             "slip floor with APIC transfers (results named *_slip_floor)")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "identify")
    args = parser.parse_args()
    if args.loss != "positions" and args.case != "friction_angle":
        parser.error(f"--loss {args.loss}: only friction_angle fits a height profile")
    if args.case == "friction_angle":
        return identify_friction_angle(args.true_phi, args.start_phi, args.out, args.max_evaluations,
                                       args.observed or "explicit", args.dt or 1e-3, args.integrator or "return_map",
                                       args.loss, args.floor)
    if args.case == "ball_youngs_modulus":
        return identify_ball_youngs_modulus(args.true_E or 1e5, args.start_E or 5e4, args.out, args.max_evaluations,
                                            args.observed or "explicit", args.dt or 2.5e-4)
    if args.case == "yield_stress":
        cantilever_scene = args.yield_scene == "cantilever"
        observed = args.observed or ("explicit" if cantilever_scene else "implicit")
        dt = args.dt or (5e-4 if cantilever_scene else DT)
        return identify_yield_stress(args.true_h0, args.start_h0, args.out, args.max_evaluations,
                                     args.integrator or "return_map", args.yield_scene, observed, dt)
    if args.observed == "explicit":
        parser.error("--observed explicit: an implicit bounce does not follow explicit's elastic rebound at any E "
                     "(docs/adjoint.md); youngs_modulus observes the fit's own implicit step")
    return identify_youngs_modulus(args.true_E or 2e5, args.start_E or 1e5, args.out, args.max_evaluations,
                                   args.integrator or "lagged", args.dt or DT)


if __name__ == "__main__":
    sys.exit(main())
