#!/usr/bin/env python3
"""Writes the Python side of the energy cross-check (tests/data/energy_vectors_python.json).

For every energy model in models/MANIFEST and models/ablation/MANIFEST: Psi, grad_F Psi and the raw Hessian of the PlasticityNet
energy (paper eqs. 8 + 11) through `plasticitynet.load_model` (torch autograd, float64), at a
scene Young's modulus E and regularizer weight w, on a few (F, F0, h); for every return-map model:
Z and the new hardening of the learned return mapping. The C++ tests
(tests/cpp/energy/test_neural_elastoplastic.cpp) recompute every case with the fused kernel and
compare to 1e-10 relative.

Deterministic: numpy's PCG64 seeded with SEED. Usage: gen_energy_vectors.py [--out PATH]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from plasticitynet import load_model
from plasticitynet.materials import Material

ROOT = Path(__file__).resolve().parent.parent
SEED = 20261121
CASES = 6
E_SCENE = 2.5e5  # Pa
W = 1.0


def rotation(rng, d):
    Q, R = np.linalg.qr(rng.normal(size=(d, d)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] *= -1
    return Q


def deformation(rng, d, magnitude):
    return rotation(rng, d) @ np.diag(np.exp(rng.uniform(-magnitude, magnitude, d))) @ rotation(rng, d)


def hardening(rng, material: str, d: int, n: int) -> np.ndarray:
    if material.startswith("metal"):
        return rng.uniform(0.02, 0.5, n)  # h = tau_Y / (2 mu) >= 0
    if material == "snow":
        return rng.uniform(-0.5 if d == 2 else -1.0, 0.0, n)
    return np.zeros(n)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "tests/data/energy_vectors_python.json"))
    args = parser.parse_args()
    entries = json.loads((ROOT / "models/MANIFEST").read_text())["models"]
    # The energy-representation ablation's models (scripts/train_ablation_models.sh), named relative to models/.
    for entry in json.loads((ROOT / "models/ablation/MANIFEST").read_text())["models"]:
        entries.append({**entry, "file": "ablation/" + entry["file"]})
    rng = np.random.Generator(np.random.PCG64(SEED))
    cases = []
    for entry in entries:
        path = ROOT / "models" / entry["file"]
        d = entry["dim"]
        model = load_model(path, E=E_SCENE) if entry["kind"] == "energy" else load_model(path)
        h = hardening(rng, entry["material"], d, CASES)
        if entry["kind"] == "energy":
            F0 = np.stack([deformation(rng, d, 0.4) for _ in range(CASES)])
            F = F0 + 0.05 * rng.normal(size=F0.shape)
            args_t = [torch.tensor(a, dtype=torch.float64) for a in (F, F0, h)]
            psi = model.psi(*args_t, w=W)
            grad = model.gradient(*args_t, w=W)
            hess = model.hessian(*args_t, w=W)
            P0 = model.Ptilde(args_t[1], args_t[2])
            cases.append(
                {
                    "file": entry["file"], "kind": "energy", "dim": d, "E": E_SCENE, "w": W,
                    "F": F.tolist(), "F0": F0.tolist(), "hardening": h.tolist(),
                    "expect": {"psi": psi.tolist(), "gradient": grad.tolist(), "hessian": hess.tolist(),
                               "Ptilde_F0": P0.tolist()},
                }
            )
        else:
            # Singular values spread so that about half yield.
            Sigma = np.exp(rng.uniform(-0.3, 0.3, size=(CASES, d)))
            Z = model.project(torch.tensor(Sigma), torch.tensor(h))
            dg = model.dgamma(torch.tensor(Sigma), torch.tensor(h))
            mat: Material = model.material
            y = mat.yield_function(torch.tensor(Sigma), torch.tensor(h))
            h_new = torch.where(y > 0, torch.tensor(h) + mat.plasticity.params.hardening_coefficient * dg,
                                torch.tensor(h))
            cases.append(
                {
                    "file": entry["file"], "kind": "return_map", "dim": d,
                    "Sigma": Sigma.tolist(), "hardening": h.tolist(),
                    "expect": {"Z": Z.tolist(), "hardening_new": h_new.tolist(), "yielding": (y > 0).tolist()},
                }
            )
    out = {"format": "plasticitynet-energy-vectors", "version": 1, "generator": "python", "cases": cases}
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {len(cases)} models x {CASES} cases to {args.out}")


if __name__ == "__main__":
    main()
