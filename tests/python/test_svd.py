"""Polar SVD convention: F = U diag(Sigma) V^T, U and V rotations, Sigma sorted with the sign of
det F carried by the last (smallest in magnitude) singular value."""

import pytest
import torch

from plasticitynet.materials import SIGMA_MIN, clamp_sigma, compose, polar_svd

TOL = {torch.float64: 1e-12, torch.float32: 1e-5}


def check_polar(F, U, Sigma, V):
    d = F.shape[-1]
    tol = TOL[F.dtype]
    I = torch.eye(d, dtype=F.dtype)
    assert torch.allclose(compose(U, Sigma, V), F, atol=tol * F.abs().max().item(), rtol=0)
    assert torch.allclose(U.transpose(-1, -2) @ U, I.expand_as(U), atol=tol, rtol=0)
    assert torch.allclose(V.transpose(-1, -2) @ V, I.expand_as(V), atol=tol, rtol=0)
    assert torch.allclose(torch.linalg.det(U), torch.ones(F.shape[0], dtype=F.dtype), atol=tol)
    assert torch.allclose(torch.linalg.det(V), torch.ones(F.shape[0], dtype=F.dtype), atol=tol)
    # Sigma_0 >= ... >= |Sigma_{d-1}|, only the last may be negative, with the sign of det F.
    assert (Sigma[:, :-1] >= 0).all()
    assert (Sigma[:, :-1] - Sigma[:, 1:].abs() >= -tol).all()
    det = torch.linalg.det(F)
    assert torch.equal(torch.sign(Sigma[:, -1]), torch.sign(det))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_polar_svd_random(dim, dtype):
    g = torch.Generator().manual_seed(dim)
    F = torch.randn(500, dim, dim, generator=g, dtype=torch.float64).to(dtype)
    det = torch.linalg.det(F)
    assert (det < 0).sum() > 100 and (det > 0).sum() > 100  # both orientations are exercised
    U, Sigma, V = polar_svd(F)
    assert Sigma.dtype == dtype and U.shape == F.shape and Sigma.shape == (500, dim)
    check_polar(F, U, Sigma, V)


@pytest.mark.parametrize("dim", [2, 3])
def test_polar_svd_repeated_and_degenerate(dim, rotation_sampler):
    g = torch.Generator().manual_seed(7)
    R = rotation_sampler(4, dim, g)
    reflect = torch.eye(dim, dtype=torch.float64)
    reflect[-1, -1] = -1
    F = torch.stack([torch.eye(dim, dtype=torch.float64), 1.5 * R[0], R[1] @ reflect, 2.0 * R[2] @ reflect @ R[3]])
    U, Sigma, V = polar_svd(F)
    check_polar(F, U, Sigma, V)
    expected = torch.tensor([[1.0] * dim, [1.5] * dim, [1.0] * (dim - 1) + [-1.0], [2.0] * (dim - 1) + [-2.0]],
                            dtype=torch.float64)
    assert torch.allclose(Sigma, expected, atol=1e-12, rtol=0)


def test_polar_svd_single_matrix():
    F = torch.tensor([[2.0, 0.5], [0.0, -1.0]], dtype=torch.float64)
    U, Sigma, V = polar_svd(F)
    assert Sigma.shape == (2,)
    assert Sigma[1] < 0 < Sigma[0]
    assert torch.allclose(U @ torch.diag(Sigma) @ V.T, F, atol=1e-14)


def test_clamp_sigma():
    Sigma = torch.tensor([[2.0, 1e-5, -0.5], [1.0, SIGMA_MIN, 3.0]], dtype=torch.float64)
    assert SIGMA_MIN == 1e-4
    assert torch.equal(clamp_sigma(Sigma), torch.tensor([[2.0, 1e-4, 1e-4], [1.0, 1e-4, 3.0]], dtype=torch.float64))
