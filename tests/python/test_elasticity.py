"""Derivative checks of the elasticity models (docs/architecture.md, testing): tau = d psi / d eps, P = d psi / dF and
dP/dF = d P / dF, each against central finite differences with torch.autograd.gradcheck in float64.

The analytic derivative is installed as the backward of a custom autograd Function whose forward is
the function being differentiated; gradcheck then compares it with finite differences of the forward.
Every check also records that it ran and that the analytic derivative is non-zero, so that two zero
vectors cannot pass and a check that silently never ran fails the test.
"""

import pytest
import torch

from plasticitynet.materials import ELASTICITY_MODELS, ElasticParams, make_elasticity, polar_svd

MODELS = sorted(ELASTICITY_MODELS)
# Every formula is linear in (mu, lambda, K), so E = 1 checks the structure at unit stress scale;
# nu = 0.3 keeps lambda and K distinct from mu.
PARAMS = ElasticParams(E=1.0, nu=0.3)


def with_backward(value, derivative, contract):
    """x -> value(x) as an autograd op whose vector-Jacobian product is contract(g, derivative(x))."""

    class _Op(torch.autograd.Function):
        @staticmethod
        def forward(ctx, x):
            ctx.save_for_backward(x)
            return value(x)

        @staticmethod
        def backward(ctx, g):
            (x,) = ctx.saved_tensors
            return contract(g, derivative(x))

    return _Op.apply


def random_F(dim, n, seed, rotation_sampler, log_range=0.5):
    """F = R1 diag(exp(eps)) R2 with eps ~ U[-log_range, log_range]^d (det F > 0)."""
    g = torch.Generator().manual_seed(seed)
    eps = (2 * torch.rand(n, dim, generator=g, dtype=torch.float64) - 1) * log_range
    return rotation_sampler(n, dim, g) @ (torch.exp(eps)[:, :, None] * rotation_sampler(n, dim, g))


def special_F(dim, rotation_sampler):
    """Equal and nearly equal singular values, where the pair blocks of dP/dF are 0/0 limits."""
    g = torch.Generator().manual_seed(99)
    R1, R2 = rotation_sampler(2, dim, g), rotation_sampler(2, dim, g)
    nearly = torch.tensor([1.2, 1.2 + 1e-9, 0.8][:dim], dtype=torch.float64)
    equal = torch.full((dim,), 1.3, dtype=torch.float64)
    return torch.stack([R1[0] @ torch.diag(nearly) @ R2[0], R1[1] @ torch.diag(equal) @ R2[1]])


def gradcheck_counted(op, x, analytic, counter):
    assert analytic.abs().max() > 1e-6, "analytic derivative is (numerically) zero: the check would be vacuous"
    assert torch.autograd.gradcheck(op, (x.clone().requires_grad_(True),), eps=1e-6, atol=1e-6, rtol=1e-5)
    counter.append(1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_tau_is_derivative_of_psi_wrt_log_strain(dim, model):
    m = make_elasticity(model, PARAMS)
    op = with_backward(
        lambda eps: m.psi(torch.exp(eps)),
        lambda eps: m.tau(torch.exp(eps)),
        lambda g, tau: g[:, None] * tau,
    )
    counter = []
    for seed in range(3):
        g = torch.Generator().manual_seed(seed)
        eps = (2 * torch.rand(4, dim, generator=g, dtype=torch.float64) - 1) * 0.5
        gradcheck_counted(op, eps, m.tau(torch.exp(eps)), counter)
    assert len(counter) == 3


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_P_is_derivative_of_psi_wrt_F(dim, model, rotation_sampler):
    m = make_elasticity(model, PARAMS)
    op = with_backward(m.psi_F, m.P, lambda g, P: g[:, None, None] * P)
    counter = []
    for seed in range(3):
        F = random_F(dim, 4, seed, rotation_sampler)
        gradcheck_counted(op, F, m.P(F), counter)
    F = special_F(dim, rotation_sampler)
    gradcheck_counted(op, F, m.P(F), counter)
    assert len(counter) == 4

    # Also against autograd through the SVD (distinct singular values only).
    F = random_F(dim, 16, 10, rotation_sampler).requires_grad_(True)
    (P_autograd,) = torch.autograd.grad(m.psi_F(F).sum(), F)
    assert P_autograd.abs().max() > 1e-3
    torch.testing.assert_close(m.P(F.detach()), P_autograd, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_dPdF_is_derivative_of_P(dim, model, rotation_sampler):
    m = make_elasticity(model, PARAMS)
    d2 = dim * dim

    def contract(g, dPdF):  # (g : dP/dF)_kl = sum_ij g_ij dP_ij / dF_kl
        return (g.reshape(-1, 1, d2) @ dPdF).reshape(-1, dim, dim)

    op = with_backward(m.P, m.dPdF, contract)
    counter = []
    for seed in range(3):
        F = random_F(dim, 4, seed, rotation_sampler)
        gradcheck_counted(op, F, m.dPdF(F), counter)
    F = special_F(dim, rotation_sampler)
    assert torch.isfinite(m.dPdF(F)).all()
    gradcheck_counted(op, F, m.dPdF(F), counter)
    assert len(counter) == 4

    # Hessian of a potential: symmetric.
    H = m.dPdF(random_F(dim, 8, 5, rotation_sampler))
    torch.testing.assert_close(H, H.transpose(-1, -2), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_dtau_deps_is_derivative_of_tau(dim, model):
    m = make_elasticity(model, PARAMS)
    g = torch.Generator().manual_seed(3)
    eps = ((2 * torch.rand(5, dim, generator=g, dtype=torch.float64) - 1) * 0.5).requires_grad_(True)
    tau = m.tau(torch.exp(eps))
    rows = [torch.autograd.grad(tau[:, i].sum(), eps, retain_graph=True)[0] for i in range(dim)]
    expected = torch.stack(rows, dim=1)
    assert expected.abs().max() > 1e-3
    torch.testing.assert_close(m.dtau_deps(torch.exp(eps.detach())), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_rest_state_is_stress_free(dim, model):
    m = make_elasticity(model, ElasticParams(E=1e6, nu=0.3))
    ones = torch.ones(1, dim, dtype=torch.float64)
    I = torch.eye(dim, dtype=torch.float64)[None]
    assert m.psi(ones).abs().max() <= 1e-9
    assert m.tau(ones).abs().max() <= 1e-9
    assert m.P(I).abs().max() <= 1e-9
    # At rest dP/dF is the linear-elasticity tensor: mu (delta_ik delta_jl + delta_il delta_jk) + lambda' delta_ij delta_kl
    # (lambda' = lambda for StVK-Hencky and the metal neo-Hookean; K - 2 mu/d for the snow form).
    H = m.dPdF(I)[0].reshape(dim, dim, dim, dim)
    e = torch.eye(dim, dtype=torch.float64)
    lam = m.K - 2 * m.mu / dim if model == "neo_hookean_snow" else m.lam
    expected = m.mu * (torch.einsum("ik,jl->ijkl", e, e) + torch.einsum("il,jk->ijkl", e, e)) + lam * torch.einsum(
        "ij,kl->ijkl", e, e
    )
    torch.testing.assert_close(H, expected, rtol=1e-12, atol=1e-12 * m.mu)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_P_is_frame_indifferent_and_isotropic(dim, model, rotation_sampler):
    m = make_elasticity(model, PARAMS)
    g = torch.Generator().manual_seed(11)
    F = random_F(dim, 16, 12, rotation_sampler)
    Q1, Q2 = rotation_sampler(16, dim, g), rotation_sampler(16, dim, g)
    torch.testing.assert_close(m.P(Q1 @ F @ Q2), Q1 @ m.P(F) @ Q2, rtol=1e-11, atol=1e-11)
    torch.testing.assert_close(m.psi_F(Q1 @ F @ Q2), m.psi_F(F), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_inverted_F_is_clamped(dim, model, rotation_sampler):
    """det F < 0: the material sees F_c = U diag(max(Sigma, 1e-4)) V^T; all outputs finite."""
    m = make_elasticity(model, PARAMS)
    F = random_F(dim, 8, 4, rotation_sampler)
    F[:, :, 0] *= -1
    U, Sigma, V = polar_svd(F)
    assert (Sigma[:, -1] < 0).all()
    F_c = (U * torch.clamp(Sigma, min=1e-4)[:, None, :]) @ V.transpose(-1, -2)
    torch.testing.assert_close(m.P(F), m.P(F_c), rtol=1e-9, atol=0.0)
    assert torch.isfinite(m.dPdF(F)).all() and torch.isfinite(m.psi_F(F)).all()
