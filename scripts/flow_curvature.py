#!/usr/bin/env python3
"""How stiff a learned sand energy is along plastic flow, against the return mapping it was trained on.

Newton's step on a flowing particle is as long as the energy's curvature along the flow allows. The
consistent tangent of Drucker-Prager flow is nearly zero along a shear on the yield cone (only the
pressure's coupling is left); the elastic stiffness is what unloading sees. This script puts a state on
the cone (log strain a (1, ..., 1) + beta n under compression, n a unit deviatoric shear, beta where the
Drucker-Prager yield function is zero), moves it `delta` further along n (the trial state of a step that
keeps flowing, the reference of the rebased Newton), and prints along n:

    network   n . Hess_F Psi(F0; F0) . n           (the learned energy's Hessian at its reference, w = 0)
    loading   n . (Ptilde(F0 + t n) - Ptilde(F0)) / t   (the return-mapped stress, one-sided, t = 1e-7)
    unloading the same with -t

Both from the simulator's C++ runtime (plasticitynet_sim.load_model: hessian(), stress()). On the cone
(delta = 0) loading and unloading differ (plastic against elastic); past it both are the plastic
stiffness. docs/integrators.md ("The stiff column") has the shipped sand model's figures.

    .venv/bin/python scripts/flow_curvature.py [--model models/sand_2d.pt] [--E 3.537e7] [--pressure-strain 1e-3]
        [--deltas 0 1e-4 ...] [--trust-model]
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="models/sand_2d.pt", help="a Drucker-Prager energy model (default: %(default)s)")
    parser.add_argument("--E", type=float, default=3.537e7,
                        help="Young's modulus of the scene, Pa (default: stiff/sand_column_2d's %(default)g)")
    parser.add_argument("--pressure-strain", type=float, default=1e-3,
                        help="-a, the volumetric log strain per axis of the state on the cone (default: %(default)g)")
    parser.add_argument("--trust-model", action="store_true",
                        help="load a model no MANIFEST beside it pins (TorchScript is code: only one you trust)")
    parser.add_argument("--deltas", type=float, nargs="+", default=[0.0, 1e-5, 1e-4, 1e-3, 1e-2],
                        help="log strains past the cone along the shear (default: %(default)s)")
    args = parser.parse_args(argv)

    import plasticitynet_sim as pns

    model = pns.load_model(args.model, E=args.E, trusted=args.trust_model)
    material = model.metadata["material"]
    plasticity = material["plasticity"]
    if plasticity.get("model") != "drucker_prager":
        parser.error(f"{args.model}: material.plasticity.model is {plasticity.get('model')!r}; this check needs "
                     "a drucker_prager energy")
    if not args.pressure_strain > 0.0:
        parser.error(f"--pressure-strain {args.pressure_strain}: must be > 0 (a state under compression)")
    d = model.dim
    nu = material["elasticity"]["nu"]
    lam_over_mu = 2.0 * nu / (1.0 - 2.0 * nu)
    sin_phi = math.sin(math.radians(plasticity["friction_angle_deg"]))
    alpha = math.sqrt(2.0 / 3.0) * 2.0 * sin_phi / (3.0 - sin_phi)  # Drucker-Prager's cone (Klar et al. 2016)
    a = -args.pressure_strain
    beta = -alpha * (d * lam_over_mu + 2.0) * d * a / 2.0  # |eps_hat| where the yield function is zero
    n = np.zeros(d)
    n[0], n[1] = 1.0 / math.sqrt(2.0), -1.0 / math.sqrt(2.0)
    N = np.diag(n)  # the shear direction in F (principal frame, F diagonal)
    v = N.reshape(-1)
    t = 1e-7  # the one-sided difference's step

    def stiffness(F0: np.ndarray, P0: np.ndarray, sign: float) -> float:
        P1 = model.stress((F0 + sign * t * N)[None])[0]
        return float(sign * np.sum((P1 - P0) * N) / t)

    print(f"{args.model}, E = {args.E:g} Pa, {d}D, state on the cone: log strain {a:g} per axis + {beta:.4g} along "
          "the shear")
    print(f"{'delta':>8} {'network':>12} {'loading':>12} {'unloading':>12} {'network/loading':>16}  (Pa)")
    for delta in args.deltas:
        F0 = np.diag(np.exp(a + (beta + delta) * n))
        H = model.hessian(F0[None], F0[None], w=0.0)[0]
        network = float(v @ H @ v)
        P0 = model.stress(F0[None])[0]
        loading, unloading = stiffness(F0, P0, +1.0), stiffness(F0, P0, -1.0)
        print(f"{delta:8.0e} {network:12.4e} {loading:12.4e} {unloading:12.4e} {network / loading:16.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
