#!/usr/bin/env python3
"""Writes the Python material test vectors (tests/data/material_vectors_python.json).

Format (material spec, "Test-vector JSON"): {"format": "plasticitynet-material-vectors",
"version": 1, "generator": "python", "cases": [{"name", "dim", "material", "F", "hardening",
"expect": {Sigma, branch, Z_Sigma, hardening_new, F_elastic, psi, tau, P, dPdF, Ptilde}}]}, float64,
full precision. The C++ test suite recomputes every case and compares (1e-10 relative).

Coverage, for d = 2 and 3 and every material below: each branch its return mapping can take
(elastic interior, Drucker-Prager apex/cone, Cam-Clay tips/ellipse in both variants, von Mises
yield with hardening_coefficient 0 and > 0, closed form and root find), plus near-identity F,
large stretch (Sigma ~ e^1), large compression (Sigma ~ e^-1) and reflected F (det F < 0, which
the material sees clamped). Every F is R1 diag(Sigma) R2 with random rotations.

Candidates whose branch tests lie within MARGIN (relative) of a threshold, or whose singular
values lie near the clamp SIGMA_MIN, are rejected, so both implementations take the same branch.
Deterministic: numpy's PCG64 seeded with (SEED, crc32 of the category name).

Usage: gen_material_vectors.py [--out PATH] [--seed N]
"""

from __future__ import annotations

import argparse
import json
import zlib
from pathlib import Path

import numpy as np
import torch

from plasticitynet.materials import (
    BRANCH_NAMES,
    PRESETS,
    SIGMA_MIN,
    CamClay,
    DruckerPrager,
    Material,
    StVKHencky,
    VonMises,
    clamp_sigma,
    polar_svd,
)

SEED = 20240611
CASES_PER_CATEGORY = 3
#: More cases for the branches that actually project (the ones with nontrivial numerics).
CASES_PER_PROJECTION_BRANCH = 5
PROJECTION_BRANCHES = ("cone", "ellipse", "yield")
#: Relative distance to any branch threshold below which a candidate is rejected (spec: >= 1e-6).
MARGIN = 1e-4
#: For det F < 0, the smallest |Sigma| is the one negated (and then clamped): the last two |Sigma|
#: must differ by this much (relative) so that the choice is unambiguous and well conditioned
#: (an error in U, V grows like 1/gap there, because clamping makes Z_{d-2} and Z_{d-1} very different).
INVERSION_GAP = 1e-2
CANDIDATES = 512  # per sampling round
MAX_ROUNDS = 50
SPECIAL_CATEGORIES = ("near_identity", "stretch", "compression", "reflected")
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "material_vectors_python.json"


def _with(desc: dict, name: str, **plasticity) -> dict:
    out = json.loads(json.dumps(desc))
    out["name"] = name
    out["plasticity"].update(plasticity)
    return out


def _elastic(name: str, model: str, E: float, nu: float) -> dict:
    return {
        "name": name, "density": 1000.0, "initial_hardening": 0.0,
        "elasticity": {"model": model, "E": E, "nu": nu},
        "plasticity": {"model": "none"},
    }


#: name -> material description (the presets, their variants, and pure elasticity).
MATERIALS = {
    "sand": PRESETS["sand"],
    "snow": PRESETS["snow"],
    "snow_paper": _with(PRESETS["snow"], "snow_paper", variant="paper"),
    "metal": PRESETS["metal"],
    "metal_perfect": _with(PRESETS["metal"], "metal_perfect", hardening_coefficient=0.0),
    "metal_nh": PRESETS["metal_nh"],
    "metal_nh_perfect": _with(PRESETS["metal_nh"], "metal_nh_perfect", hardening_coefficient=0.0),
    "elastic_stvk_hencky": _elastic("elastic_stvk_hencky", "stvk_hencky", 1.0e6, 0.25),
    "elastic_neo_hookean_snow": _elastic("elastic_neo_hookean_snow", "neo_hookean_snow", 1.4e5, 0.2),
    "elastic_neo_hookean_metal": _elastic("elastic_neo_hookean_metal", "neo_hookean_metal", 1.0e7, 0.35),
}


def random_rotations(rng: np.random.Generator, n: int, d: int) -> np.ndarray:
    """n Haar-random rotations (det +1), shape (n, d, d)."""
    Q, R = np.linalg.qr(rng.standard_normal((n, d, d)))
    Q = Q * np.sign(np.diagonal(R, axis1=1, axis2=2))[:, None, :]
    Q[:, :, 0] *= np.sign(np.linalg.det(Q))[:, None]
    return Q


def _deviatoric_directions(rng, n, d):
    x = rng.standard_normal((n, d))
    x -= x.mean(1, keepdims=True)
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _family(material: Material) -> str:
    p = material.plasticity
    if isinstance(p, DruckerPrager):
        return "sand"
    if isinstance(p, CamClay):
        return "snow"
    if isinstance(p, VonMises):
        return "metal"
    return "elastic"


#: Log-strain ranges of the branch-targeted sampler: eps = m 1 + r n, n a unit deviatoric direction;
#: m is drawn for the mean log-strain times d (i.e. log J).
_LOG_J_RANGE = {"sand": (-0.9, 0.3), "snow": (-0.5, 0.2), "metal": (-0.6, 0.6), "elastic": (-0.6, 0.6)}
_DEV_RANGE = {"sand": (0.0, 0.4), "snow": (0.0, 0.4), "metal": (0.0, 0.6), "elastic": (0.0, 0.5)}


def sample_hardening(family: str, category: str, rng, n: int) -> np.ndarray:
    if family == "snow":  # a = log plastic volume ratio, < 0 (p0 > 0: a non-degenerate ellipse)
        return rng.uniform(-0.8, -0.05, n)
    if family == "metal":  # h = tau_Y / (2 mu); kept > 0 (h = 0 makes the root a double root)
        return rng.uniform(0.005, 0.03, n) if category == "near_identity" else rng.uniform(0.005, 0.3, n)
    return np.zeros(n)


def sample_F(family: str, category: str, rng, n: int, d: int) -> np.ndarray:
    if category == "near_identity":
        return np.eye(d) + 0.01 * rng.standard_normal((n, d, d))
    if category == "stretch":
        eps = rng.uniform(0.8, 1.0, (n, d))
    elif category == "compression":
        eps = rng.uniform(-1.0, -0.8, (n, d))
    else:
        log_J = rng.uniform(*_LOG_J_RANGE[family], n)
        r = rng.uniform(*_DEV_RANGE[family], n)
        eps = log_J[:, None] / d + r[:, None] * _deviatoric_directions(rng, n, d)
    Sigma = np.exp(eps)
    if category == "reflected":  # det F < 0: negate one singular value
        Sigma[np.arange(n), rng.integers(0, d, n)] *= -1.0
    return random_rotations(rng, n, d) @ (Sigma[:, :, None] * random_rotations(rng, n, d))


def _relative_gap(value, threshold, scale):
    return (value - threshold).abs() > MARGIN * scale


def margin_ok(material: Material, F: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """Rows whose branch decisions are at least MARGIN (relative) away from every threshold."""
    _, Sigma, _ = polar_svd(F)
    ok = ((Sigma <= 0) | ((Sigma / SIGMA_MIN - 1.0).abs() > MARGIN)).all(-1)
    gap = (Sigma[:, -2].abs() - Sigma[:, -1].abs()) / Sigma[:, -2].abs()
    ok &= (Sigma[:, -1] > 0) | (gap > INVERSION_GAP)
    Sigma = clamp_sigma(Sigma)
    d = material.dim
    eps = torch.log(Sigma)
    p = material.plasticity
    if isinstance(p, DruckerPrager):
        tr = eps.sum(-1)
        eps_hat_norm = torch.linalg.vector_norm(eps - tr[:, None] / d, dim=-1)
        cone_term = p.alpha * (d * material.lam + 2 * material.mu) * tr / (2 * material.mu)
        ok &= _relative_gap(tr, 0.0, torch.linalg.vector_norm(eps, dim=-1))
        ok &= (tr > 0) | _relative_gap(eps_hat_norm + cone_term, 0.0, eps_hat_norm + cone_term.abs())
    elif isinstance(p, CamClay):
        _, _, pressure, p0, _, _ = p._state(Sigma, h)
        beta = p.params.beta
        ok &= _relative_gap(pressure, p0, pressure.abs() + p0)
        ok &= _relative_gap(pressure, -beta * p0, pressure.abs() + beta * p0)
        ok &= _relative_gap(p.yield_function(Sigma, h), 0.0, p.yield_scale(Sigma, h))
    elif isinstance(p, VonMises):
        dev = eps - eps.mean(-1, keepdim=True)
        L = torch.linalg.vector_norm(dev, dim=-1)
        if isinstance(p.elasticity, StVKHencky):
            ok &= _relative_gap(L, h, L + h)
        else:
            ok &= _relative_gap(p.yield_function(Sigma, h), 0.0, p.yield_scale(Sigma, h))
            # Keep the 16-step bracketing scan of the root find away from sign changes too.
            n = dev / torch.where(L > 0, L, torch.ones_like(L))[:, None]
            for k in range(1, 16):
                Z = torch.exp(eps - (k * L / 16)[:, None] * n)
                ok &= _relative_gap(p.yield_function(Z, h), 0.0, p.yield_scale(Z, h))
    return ok


def _flat(x: torch.Tensor) -> list:
    return [float(v) for v in x.reshape(-1).tolist()]


def make_case(name: str, material: Material, description: dict, F: torch.Tensor, h: float) -> dict:
    out = material.evaluate(F, torch.tensor(h, dtype=torch.float64))
    expect = {
        "Sigma": _flat(out["Sigma"]),
        "branch": BRANCH_NAMES[int(out["branch"])],
        "Z_Sigma": _flat(out["Z_Sigma"]),
        "hardening_new": float(out["hardening_new"]),
        "F_elastic": _flat(out["F_elastic"]),
        "psi": float(out["psi"]),
        "tau": _flat(out["tau"]),
        "P": _flat(out["P"]),
        "dPdF": _flat(out["dPdF"]),
        "Ptilde": _flat(out["Ptilde"]),
    }
    return {"name": name, "dim": material.dim, "material": description, "F": _flat(F), "hardening": float(h),
            "expect": expect}


def generate(seed: int = SEED) -> dict:
    """The whole vectors file as a dict (deterministic in `seed`)."""
    cases = []
    for mat_name, description in MATERIALS.items():
        for d in (2, 3):
            material = Material.from_dict(description, d)
            family = _family(material)
            description_out = material.to_dict()
            categories = list(material.branch_names) + list(SPECIAL_CATEGORIES)
            for category in categories:
                key = f"{mat_name}/{d}d/{category}"
                rng = np.random.default_rng([seed, zlib.crc32(key.encode())])
                wanted = CASES_PER_PROJECTION_BRANCH if category in PROJECTION_BRANCHES else CASES_PER_CATEGORY
                chosen = []
                for _ in range(MAX_ROUNDS):
                    F = torch.from_numpy(sample_F(family, category, rng, CANDIDATES, d))
                    h = torch.from_numpy(sample_hardening(family, category, rng, CANDIDATES))
                    ok = margin_ok(material, F, h)
                    if category in BRANCH_NAMES:
                        _, Sigma, _ = polar_svd(F)
                        _, _, branch = material.plasticity.return_map(clamp_sigma(Sigma), h)
                        ok &= branch == BRANCH_NAMES.index(category)
                    for i in torch.nonzero(ok)[:, 0].tolist():
                        chosen.append((F[i], float(h[i])))
                        if len(chosen) == wanted:
                            break
                    if len(chosen) == wanted:
                        break
                else:
                    raise RuntimeError(f"{key}: could not sample {wanted} cases with margin")
                for i, (F_i, h_i) in enumerate(chosen):
                    cases.append(make_case(f"{key}/{i:03d}", material, description_out, F_i, h_i))
    return {"format": "plasticitynet-material-vectors", "version": 1, "generator": "python", "cases": cases}


def dumps(vectors: dict) -> str:
    """JSON with one case per line (floats as repr: full precision, exact round trip)."""
    head = {k: v for k, v in vectors.items() if k != "cases"}
    lines = ",\n".join(json.dumps(c, allow_nan=False) for c in vectors["cases"])
    return json.dumps(head, allow_nan=False)[:-1] + ', "cases": [\n' + lines + "\n]}\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    vectors = generate(args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(dumps(vectors))
    counts: dict[str, int] = {}
    for c in vectors["cases"]:
        counts[c["expect"]["branch"]] = counts.get(c["expect"]["branch"], 0) + 1
    print(f"wrote {len(vectors['cases'])} cases to {args.out} ({args.out.stat().st_size / 1e6:.2f} MB); branches: {counts}")


if __name__ == "__main__":
    main()
