#!/usr/bin/env python3
"""How far each training target Ptilde(F, h) is from a gradient field: ||skew(J)||_F / ||J||_F with
J = d Ptilde/dF (central differences, float64) over 2000 held-out samples of the paper's sampling.

A gradient field has a symmetric Jacobian, so this fraction bounds what any energy's Hessian can match,
and a large one means the gradient error of eq. 9 has a floor that no representation or budget removes.

    .venv/bin/python scripts/target_skew.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "python"))

from plasticitynet.training import ElastoplasticStress, nondimensional_material, sample_batch, sampling_spec  # noqa: E402

SAMPLES = 2000


def skew_fraction(name: str, dim: int) -> float:
    m = nondimensional_material(name, dim)
    b = sample_batch(sampling_spec(m, "paper"), SAMPLES, seed=5, stream="test")
    stress = ElastoplasticStress(m)
    columns = []
    for k in range(dim * dim):
        E = torch.zeros(dim * dim, dtype=torch.float64)
        E[k] = 1e-6
        E = E.reshape(dim, dim)
        columns.append(((stress(b.F + E, b.h) - stress(b.F - E, b.h)) / 2e-6).reshape(SAMPLES, -1))
    J = torch.stack(columns, -1)
    skew = 0.5 * (J - J.transpose(1, 2))
    return float((skew**2).sum() / (J**2).sum()) ** 0.5


def main() -> int:
    print("| material | dim | skew(J) / J (Frobenius, paper sampling) |\n|---|---|---|")
    for name in ("sand", "snow", "metal", "metal_nh"):
        for dim in (2, 3):
            print(f"| {name} | {dim} | {100 * skew_fraction(name, dim):.2f}% |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
