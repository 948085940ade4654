"""Properties of every return mapping Z(Sigma, h), for d = 2 and 3.

Surface tolerance: each yield function is a difference of terms (||dev tau||^2 and (2 mu h)^2 for
von Mises; the q^2 and pressure terms for Cam-Clay; ||dev tau|| and alpha tr(tau) for
Drucker-Prager), so the relevant measure of "on the surface" is |y| / yield_scale, yield_scale being
the sum of the magnitudes of those terms (Pa for Drucker-Prager, Pa^2 for the squared forms; a
plain mu or mu^2 would be too loose for small stresses and too tight for the Cam-Clay tips, where
the terms are K-sized). Rounding alone leaves ~1e-15 of it; we accept 1e-10, far below any
first-order error (the paper Cam-Clay variant is off by ~1e-2).
"""

import pytest
import torch

from plasticitynet.materials import BRANCH_NAMES, clamp_sigma, unimodular_shift
from plasticitynet.materials.branches import APEX, COMPRESSION_TIP, CONE, ELASTIC, ELLIPSE, TENSION_TIP, YIELD

ALL = ["sand", "snow", "snow_paper", "metal", "metal_perfect", "metal_nh", "metal_nh_perfect"]
IDEMPOTENT = [m for m in ALL if m != "snow_paper"]
SURFACE_TOL = 1e-10
N = 3000


def relative_yield(material, Sigma, h):
    """|y| / yield_scale (|y| itself where the scale is 0: the stress-free Drucker-Prager apex)."""
    y, scale = material.yield_function(Sigma, h).abs(), material.yield_scale(Sigma, h)
    return torch.where(scale > 0, y / torch.where(scale > 0, scale, torch.ones_like(scale)), y)


def branch_counts(material, branch):
    return {BRANCH_NAMES[c]: int((branch == c).sum()) for c in material.plasticity.BRANCHES}


DIMS = pytest.mark.parametrize("dim", [2, 3])


@pytest.fixture
def return_mapped(material_factory, state_sampler):
    """return_mapped(name, dim, seed): the material, N of its sampled states (Sigma, h) and their
    return map (Z, h_new, branch)."""

    def sample(name, dim, seed):
        m = material_factory(name, dim)
        Sigma, h = state_sampler(m, N, seed=seed)
        return (m, Sigma, h, *m.return_map(Sigma, h))

    return sample


@DIMS
@pytest.mark.parametrize("name", ALL)
def test_every_branch_is_sampled(dim, name, return_mapped):
    m, _, _, _, _, branch = return_mapped(name, dim, seed=1)
    counts = branch_counts(m, branch)
    assert set(branch.unique().tolist()) <= set(m.plasticity.BRANCHES)
    assert all(n >= 20 for n in counts.values()), counts


@DIMS
@pytest.mark.parametrize("name", ALL)
def test_interior_points_unchanged(dim, name, return_mapped):
    m, Sigma, h, Z, h_new, branch = return_mapped(name, dim, seed=2)
    elastic = branch == ELASTIC
    assert elastic.sum() >= 20
    assert torch.equal(Z[elastic], Sigma[elastic])
    assert torch.equal(h_new[elastic], h[elastic])
    # Elastic exactly where the yield function is <= 0 (tips and apex have y > 0 too).
    y = m.yield_function(Sigma, h)
    assert (y[elastic] <= 0).all()
    assert (y[~elastic] > 0).all()


@DIMS
@pytest.mark.parametrize("name", IDEMPOTENT)
def test_projection_lies_on_yield_surface(dim, name, return_mapped):
    m, _, h, Z, _, branch = return_mapped(name, dim, seed=3)
    plastic = branch != ELASTIC
    assert plastic.sum() >= 20
    drift = relative_yield(m, Z, h)[plastic]
    assert drift.max() <= SURFACE_TOL, f"max |y|/scale = {drift.max():.3e}"


@DIMS
@pytest.mark.parametrize("name", IDEMPOTENT)
def test_return_map_is_idempotent(dim, name, return_mapped):
    """Z(Z(Sigma, h), h) == Z(Sigma, h) (same hardening input: the same yield surface)."""
    m, _, h, Z, _, branch = return_mapped(name, dim, seed=4)
    Z2, _, _ = m.return_map(Z, h)
    err = ((Z2 - Z).abs().amax(-1) / Z.abs().amax(-1))
    for code in m.plasticity.BRANCHES:
        rows = branch == code
        assert rows.sum() >= 20
        assert err[rows].max() <= 1e-12, f"{BRANCH_NAMES[code]}: {err[rows].max():.3e}"


@DIMS
@pytest.mark.parametrize("name", ["sand", "snow", "metal", "metal_perfect", "metal_nh", "metal_nh_perfect"])
def test_volume_preserving_branches_keep_det(dim, name, return_mapped):
    """von Mises yield, the Drucker-Prager cone and the exact Cam-Clay ellipse keep J = prod(Sigma_c)."""
    _, Sigma, _, Z, _, branch = return_mapped(name, dim, seed=5)
    rows = (branch == YIELD) | (branch == CONE) | (branch == ELLIPSE)
    assert rows.sum() >= 20
    log_J_ratio = torch.log(Z).sum(-1) - torch.log(Sigma).sum(-1)
    assert log_J_ratio[rows].abs().max() <= 1e-13


@DIMS
def test_drucker_prager_branches(dim, return_mapped):
    _, Sigma, h, Z, h_new, branch = return_mapped("sand", dim, seed=6)
    eps = torch.log(Sigma)
    assert torch.equal(branch == APEX, eps.sum(-1) > 0)
    assert torch.equal(Z[branch == APEX], torch.ones_like(Z[branch == APEX]))
    assert torch.equal(h_new, h)  # no hardening
    # Cone: the deviatoric strain shrinks along itself, the volumetric part is kept.
    cone = branch == CONE
    dev = eps - eps.mean(-1, keepdim=True)
    dev_Z = torch.log(Z) - torch.log(Z).mean(-1, keepdim=True)
    cos = (dev * dev_Z).sum(-1) / (dev.norm(dim=-1) * dev_Z.norm(dim=-1))
    assert (cos[cone] > 1 - 1e-12).all()
    assert (dev_Z.norm(dim=-1)[cone] < dev.norm(dim=-1)[cone]).all()


@DIMS
@pytest.mark.parametrize("name", ["snow", "snow_paper"])
def test_cam_clay_hardening(dim, name, return_mapped):
    m, Sigma, a, Z, a_new, branch = return_mapped(name, dim, seed=7)
    J, J_Z = Sigma.prod(-1), Z.prod(-1)
    tips = (branch == COMPRESSION_TIP) | (branch == TENSION_TIP)
    assert tips.sum() >= 20
    # Tips: J_x = J_new = det Z, a += log(J / J_new); compression hardens (a decreases).
    torch.testing.assert_close(a_new[tips], (a + torch.log(J / J_Z))[tips], rtol=1e-13, atol=1e-13)
    assert (a_new[branch == COMPRESSION_TIP] < a[branch == COMPRESSION_TIP]).all()
    assert (a_new[branch == TENSION_TIP] > a[branch == TENSION_TIP]).all()
    # Ellipse: a state already on the ellipse is its own ray crossing, J_x = J: no hardening.
    if name == "snow":
        ellipse = branch == ELLIPSE
        _, a_again, branch_again = m.return_map(Z[ellipse], a[ellipse])
        assert ((a_again - a[ellipse]).abs() <= 1e-9).all()
        # and the ellipse branch hardens/softens by the ray formula, finite
        assert torch.isfinite(a_new).all()


@DIMS
@pytest.mark.parametrize("name", ["metal", "metal_perfect", "metal_nh", "metal_nh_perfect"])
def test_von_mises_hardening_and_smallest_root(dim, name, return_mapped):
    m, Sigma, h, Z, h_new, branch = return_mapped(name, dim, seed=8)
    xi = m.plasticity.params.hardening_coefficient
    rows = branch == YIELD
    assert rows.sum() >= 20
    eps, eps_Z = torch.log(Sigma[rows]), torch.log(Z[rows])
    dgamma = torch.linalg.vector_norm(eps - eps_Z, dim=-1)
    L = torch.linalg.vector_norm(eps - eps.mean(-1, keepdim=True), dim=-1)
    assert (dgamma > 0).all() and (dgamma <= L * (1 + 1e-12)).all()
    torch.testing.assert_close(h_new[rows], h[rows] + xi * dgamma, rtol=1e-12, atol=1e-14)
    if name.startswith("metal_nh"):
        # The root is the smallest one: y > 0 all along eps - s dgamma n for s in [0, 1).
        n = (eps - eps.mean(-1, keepdim=True)) / L[:, None]
        for s in torch.linspace(0, 0.999, 40, dtype=torch.float64):
            y = m.yield_function(torch.exp(eps - (s * dgamma)[:, None] * n), h[rows])
            assert (y > 0).all()
    else:
        torch.testing.assert_close(dgamma, L - h[rows], rtol=1e-12, atol=1e-14)


@DIMS
def test_von_mises_root_find_matches_closed_form_for_small_strain(dim, material_factory, state_sampler):
    """At small strain the two metal elasticities agree to first order, and so do their projections."""
    m_cf, m_nh = material_factory("metal", dim), material_factory("metal_nh", dim)
    g = torch.Generator().manual_seed(9)
    eps = 1e-4 * torch.randn(200, dim, generator=g, dtype=torch.float64)
    h = torch.full((200,), 2e-5, dtype=torch.float64)
    Z_cf, _, b_cf = m_cf.return_map(torch.exp(eps), h)
    Z_nh, _, b_nh = m_nh.return_map(torch.exp(eps), h)
    assert (b_cf == YIELD).sum() > 50
    agree = b_cf == b_nh
    assert agree.float().mean() > 0.9
    assert (torch.log(Z_cf) - torch.log(Z_nh))[agree].abs().max() < 1e-6


@DIMS
def test_cam_clay_paper_variant_drift(dim, material_factory, state_sampler):
    """The paper's eq. 20 keeps tr(b), not J: it lands on the surface only to first order and is
    not idempotent. Measure and print how far off it is, binned by the trial deviatoric Hencky
    strain r = ||dev eps||: |y|/scale after one projection and after 100 re-projections (same a),
    the relative error of q = sqrt((6-d)/2) ||s|| against the surface at the new p, the creep
    ||log Z_100 - log Z_1|| and the distance to the exact variant ||log Z_paper - log Z_exact||."""
    m_paper, m_exact = material_factory("snow_paper", dim), material_factory("snow", dim)
    Sigma, a = state_sampler(m_paper, 3 * N, seed=10)
    Z, _, branch = m_paper.return_map(Sigma, a)
    ellipse = branch == ELLIPSE
    assert ellipse.sum() >= 100
    Sigma, a, Z = Sigma[ellipse], a[ellipse], Z[ellipse]
    drift1 = relative_yield(m_paper, Z, a)
    Zk = Z
    for _ in range(100):
        Zk, _, _ = m_paper.return_map(Zk, a)
    drift100 = relative_yield(m_paper, Zk, a)
    creep = (torch.log(Zk) - torch.log(Z)).norm(dim=-1)
    Z_exact, _, _ = m_exact.return_map(Sigma, a)
    vs_exact = (torch.log(Z) - torch.log(Z_exact)).norm(dim=-1)
    # q error against the surface at the projected pressure (inf where p left [-beta p0, p0]).
    cc = m_paper.plasticity
    _, _, p, p0, s, M = cc._state(Z, a)
    beta = cc.params.beta
    q = torch.sqrt((6 - dim) / 2 * (s * s).sum(-1))
    q_surface = torch.sqrt(torch.clamp(-M * M * (p + beta * p0) * (p - p0), min=0) / (1 + 2 * beta))
    q_error = (q - q_surface).abs() / q_surface
    eps = torch.log(Sigma)
    r = (eps - eps.mean(-1, keepdim=True)).norm(dim=-1)

    outside = float((m_paper.yield_function(Z, a) > 0).double().mean())
    print(
        f"\n[cam_clay paper variant, {dim}D, {len(r)} ellipse states, {100 * outside:.1f}% still outside "
        f"after one projection (re-projected again), the rest inside; medians (max)]"
    )
    print("  trial ||dev eps||   n  |y|/scale 1x          |y|/scale 100x        q rel. error   creep 100x   vs exact")
    medians = []
    for lo, hi in ((0.0, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, 0.4)):
        k = (r >= lo) & (r < hi)
        if k.sum() == 0:
            continue
        medians.append(float(drift1[k].median()))
        print(
            f"  [{lo:.2f}, {hi:.2f})  {int(k.sum()):5d}  {drift1[k].median():.2e} ({drift1[k].max():.2e})"
            f"  {drift100[k].median():.2e} ({drift100[k].max():.2e})  {q_error[k].median():.2e}"
            f"     {creep[k].median():.2e} ({creep[k].max():.2e})  {vs_exact[k].median():.2e} ({vs_exact[k].max():.2e})"
        )
    for x in (drift1, drift100, creep, vs_exact):
        assert torch.isfinite(x).all()
    # Off the surface by a measurable, first-order amount (the exact variant is ~1e-15) that grows
    # with the strain increment, but bounded: a few percent at small strain, |y|/scale < 1 always.
    assert drift1.max() > 1e-6
    assert medians[0] < 0.05 and medians[0] < medians[-1]
    assert drift1.max() < 1.0 and drift100.max() < 1.0
    assert creep.max() < 0.5 and vs_exact.max() < 0.5


@DIMS
def test_von_mises_yield_function_is_differentiable(dim, material_factory, state_sampler):
    """A learned return mapping trains through y(Z_theta): autograd gradient vs finite differences."""
    for name in ("metal", "metal_nh"):
        m = material_factory(name, dim)
        Sigma, h = state_sampler(m, 6, seed=11)
        Sigma = Sigma.clone().requires_grad_(True)
        (grad,) = torch.autograd.grad(m.yield_function(Sigma, h).sum(), Sigma)
        assert grad.abs().max() > 0
        scale = 1.0 / (2 * m.mu) ** 2  # gradcheck tolerances are absolute: work in units of (2 mu)^2
        assert torch.autograd.gradcheck(lambda S: scale * m.yield_function(S, h), (Sigma,), eps=1e-7, atol=1e-6)


@DIMS
def test_unimodular_shift(dim):
    g = torch.Generator().manual_seed(12)
    t = torch.randn(500, dim, generator=g, dtype=torch.float64) * torch.logspace(-6, 1, 500, dtype=torch.float64)[:, None]
    t -= t.mean(-1, keepdim=True)
    c = unimodular_shift(t)
    assert ((c[:, None] + t) > 0).all()
    # prod(c + t) = 1 up to rounding of a product of d terms of size <= c + |t|
    err = ((c[:, None] + t).prod(-1) - 1).abs()
    assert (err <= 1e-14 * (c[:, None] + t.abs()).prod(-1)).all()


@DIMS
@pytest.mark.parametrize("name", ALL)
def test_clamped_and_batched_consistency(dim, name, material_factory, state_sampler):
    """Z acts on Sigma_c: a raw Sigma below SIGMA_MIN gives the clamped result; single == batch."""
    m = material_factory(name, dim)
    Sigma, h = state_sampler(m, 8, seed=13)
    Sigma_raw = Sigma.clone()
    Sigma_raw[:, -1] = -0.3  # inverted
    Z_raw, h_raw, b_raw = m.return_map(Sigma_raw, h)
    Z_c, h_c, b_c = m.return_map(clamp_sigma(Sigma_raw), h)
    assert torch.equal(Z_raw, Z_c) and torch.equal(h_raw, h_c) and torch.equal(b_raw, b_c)
    for i in range(8):
        Z_i, h_i, b_i = m.return_map(Sigma[i], h[i])
        Z_b, h_b, b_b = m.return_map(Sigma, h)
        torch.testing.assert_close(Z_i, Z_b[i], rtol=1e-14, atol=0.0)
        assert b_i.ndim == 0 and int(b_i) == int(b_b[i])
