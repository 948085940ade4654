"""The distance from a training target to the nearest gradient field: the least gradient error any
energy can reach on the paper's sampling (scripts/gradient_floor.py explains the reduction).

For one slice (Sigma0, h) of the paper's distribution, F's log-singular values s fill the box
log Sigma0 + [-r, r]^d uniformly and its rotations are Haar, so the best energy of the slice is an
isotropic phi(s), the solution of the weighted least-squares (Poisson) problem

    min_phi  sum_i E_box (d phi / d s_i - tau_i(s))^2 w_i(s),   w_i = Sigma_i^-2,
    error^2 = that minimum,  norm^2 = sum_i E_box tau_i^2 w_i       (= E ||Ptilde||_F^2 over the slice)

with tau the target's principal Kirchhoff stress (Ptilde = U diag(tau / Sigma) V^T). phi lives on the
nodes of a uniform grid of n^d points per slice, d phi / d s_i on the edges along axis i (where tau_i and
w_i are taken); all slices are solved together by Jacobi-preconditioned conjugate gradients on the
normal equations sum_i D_i^T w_i D_i phi = sum_i D_i^T w_i tau_i.
"""

from __future__ import annotations

import torch

from ..materials import clamp_sigma
from . import nondimensional_material
from .sampling import sample_batch, sampling_spec
from .targets import ElastoplasticStress


def _diff(phi: torch.Tensor, axis: int, dx: float) -> torch.Tensor:
    """D_i phi: forward differences along grid axis `axis` (tensor dim 1 + axis), on the edges."""
    return torch.diff(phi, dim=1 + axis) / dx


def _diff_adjoint(y: torch.Tensor, axis: int, dx: float) -> torch.Tensor:
    """D_i^T y: (D^T y)_j = (y_{j-1} - y_j) / dx with y_{-1} = y_{n-1} = 0."""
    dim = 1 + axis
    zero = torch.zeros_like(y.narrow(dim, 0, 1))
    return (torch.cat([zero, y], dim) - torch.cat([y, zero], dim)) / dx


def _edge_points(log_sigma0: torch.Tensor, offsets: torch.Tensor, axis: int) -> torch.Tensor:
    """Log-singular values at the midpoints of the edges along `axis`, (S, *edge_shape, d)."""
    d = log_sigma0.shape[1]
    mid = 0.5 * (offsets[:-1] + offsets[1:])
    grids = torch.meshgrid(*[(mid if j == axis else offsets) for j in range(d)], indexing="ij")
    local = torch.stack(grids, dim=-1)  # (*edge_shape, d)
    return log_sigma0.reshape(-1, *([1] * d), d) + local


def slice_problem(material: str, dim: int, n: int, slices: int, seed: int = 20240):
    """(tau, w, dx): per axis i the target tau_i and weight w_i on the edges along i, (S, *edge_shape)."""
    m = nondimensional_material(material, dim)
    spec = sampling_spec(m, "paper")
    r = spec.deps * spec.deps_scale
    b = sample_batch(spec, slices, seed, stream="eval")
    offsets = torch.linspace(-r, r, n, dtype=torch.float64)
    dx = float(offsets[1] - offsets[0])
    stress = ElastoplasticStress(m)
    taus, weights = [], []
    for axis in range(dim):
        s = _edge_points(torch.log(b.Sigma0), offsets, axis)
        shape = s.shape[:-1]
        Sigma = clamp_sigma(torch.exp(s.reshape(-1, dim)))
        h = b.h.reshape(-1, *([1] * dim)).expand(shape).reshape(-1)
        tau = m.tau(stress.project(Sigma, h))
        taus.append(tau[:, axis].reshape(shape))
        weights.append(Sigma[:, axis].reshape(shape) ** -2)
    return taus, weights, dx


def solve_slices(taus, weights, dx: float, tol: float = 1e-10, max_iterations: int | None = None) -> torch.Tensor:
    """phi (S, n, ..., n) minimising sum_i |w_i^(1/2) (D_i phi - tau_i)|^2 per slice."""
    dim = len(taus)
    S, n = taus[0].shape[0], taus[0].shape[1] + 1
    shape = (S, *([n] * dim))

    def apply(phi):
        return sum(_diff_adjoint(weights[i] * _diff(phi, i, dx), i, dx) for i in range(dim))

    rhs = sum(_diff_adjoint(weights[i] * taus[i], i, dx) for i in range(dim))
    diag = sum(_node_weight(weights[i], i) for i in range(dim)) / dx**2
    phi = torch.zeros(shape, dtype=torch.float64)
    res = rhs.clone()
    z = res / diag
    p = z.clone()
    rz = (res * z).flatten(1).sum(1)
    rhs_norm = rhs.flatten(1).norm(dim=1).clamp_min(1e-300)
    view = (-1, *([1] * dim))
    for _ in range(max_iterations or 50 * n * dim):
        active = res.flatten(1).norm(dim=1) > tol * rhs_norm  # converged slices stay as they are
        if not bool(active.any()):
            break
        Ap = apply(p)
        pAp = (p * Ap).flatten(1).sum(1)
        alpha = torch.where(active, rz / torch.where(active, pAp, torch.ones_like(pAp)), torch.zeros_like(rz))
        phi = phi + alpha.reshape(view) * p
        res = res - alpha.reshape(view) * Ap
        z = res / diag
        rz_new = (res * z).flatten(1).sum(1)
        beta = torch.where(active, rz_new / torch.where(active, rz, torch.ones_like(rz)), torch.zeros_like(rz))
        p = z + beta.reshape(view) * p
        rz = torch.where(active, rz_new, rz)
    return phi


def _node_weight(w: torch.Tensor, axis: int) -> torch.Tensor:
    """sum of the weights of the edges along `axis` that meet each node (the Jacobi diagonal's part)."""
    dim = 1 + axis
    zero = torch.zeros_like(w.narrow(dim, 0, 1))
    return torch.cat([zero, w], dim) + torch.cat([w, zero], dim)


def gradient_floor(material: str, dim: int, n: int, slices: int, seed: int = 20240) -> float:
    """sqrt(sum over slices of the least squared gradient error / sum of E ||Ptilde||^2): the relative RMS
    gradient error (paper 1x) of the nearest gradient field, on a grid of n^dim nodes per slice."""
    taus, weights, dx = slice_problem(material, dim, n, slices, seed)
    phi = solve_slices(taus, weights, dx)
    num = sum(float((weights[i] * (_diff(phi, i, dx) - taus[i]) ** 2).sum()) for i in range(dim))
    den = sum(float((weights[i] * taus[i] ** 2).sum()) for i in range(dim))
    return (num / den) ** 0.5


__all__ = ["gradient_floor", "slice_problem", "solve_slices"]
