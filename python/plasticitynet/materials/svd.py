"""Polar singular value decomposition and the singular-value clamp (docs/physics.md, material spec).

F = U diag(Sigma) V^T with U, V proper rotations (det = +1) and
Sigma_0 >= Sigma_1 >= ... >= |Sigma_{d-1}|. An inverted F (det F < 0) is marked by a
negative last singular value (Irving et al. 2004), so that isotropic models see a
continuous parametrisation through inversion.
"""

from __future__ import annotations

import torch

#: Every constitutive evaluation uses Sigma_c = max(Sigma, SIGMA_MIN) (elementwise; a
#: negative last value becomes SIGMA_MIN), so that eps = log(Sigma_c) stays finite.
SIGMA_MIN = 1e-4


def polar_svd(F: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Batched polar SVD of F, shape (B, d, d) (or (d, d)).

    Returns (U, Sigma, V) with F = U diag(Sigma) V^T, U and V rotations, Sigma of shape
    (B, d) sorted descending with, for det F < 0, the last entry negative.

    An ordinary SVD gives orthogonal U, V and Sigma >= 0; each of U, V that is a
    reflection has its last column negated, and each negation flips the sign of
    Sigma_{d-1} (two flips cancel: then det F > 0 and both factors were reflections).
    """
    U, Sigma, Vh = torch.linalg.svd(F)
    V = Vh.transpose(-1, -2)
    one = torch.ones((), dtype=F.dtype, device=F.device)
    sign_U = torch.where(torch.linalg.det(U) < 0, -one, one)
    sign_V = torch.where(torch.linalg.det(V) < 0, -one, one)
    U = torch.cat([U[..., :-1], U[..., -1:] * sign_U[..., None, None]], dim=-1)
    V = torch.cat([V[..., :-1], V[..., -1:] * sign_V[..., None, None]], dim=-1)
    Sigma = torch.cat([Sigma[..., :-1], Sigma[..., -1:] * (sign_U * sign_V)[..., None]], dim=-1)
    return U, Sigma, V


def clamp_sigma(Sigma: torch.Tensor) -> torch.Tensor:
    """Sigma_c = max(Sigma, SIGMA_MIN), elementwise (an inverted direction becomes SIGMA_MIN)."""
    return torch.clamp(Sigma, min=SIGMA_MIN)


def compose(U: torch.Tensor, values: torch.Tensor, V: torch.Tensor) -> torch.Tensor:
    """U diag(values) V^T: maps a diagonal-space quantity back to F space."""
    return (U * values[..., None, :]) @ V.transpose(-1, -2)
