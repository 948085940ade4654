"""The corrected energy (eq. 8, 11), the loss (eq. 9) and the learned return mapping (eqs. 12-13)."""

import pytest
import torch

from plasticitynet.training import (
    ElastoplasticStress,
    energy_input,
    energy_loss,
    energy_widths,
    make_mlp,
    nondimensional_material,
    psi,
    psi_gradient,
    return_map_widths,
    sample_batch,
    sample_return_map_states,
    sampling_spec,
)
from plasticitynet.training import return_map_net


def _setup(name, dim, n=64, seed=0):
    m = nondimensional_material(name, dim)
    spec = sampling_spec(m, "paper")
    net = make_mlp(energy_widths(dim, spec.has_hardening), seed).double()
    b = sample_batch(spec, n, seed=seed)
    stress = ElastoplasticStress(m)
    P = stress.from_factors(b.U, b.Sigma, b.V, b.h)
    P0 = stress.from_factors(b.U0, b.Sigma0, b.V0, b.h)
    return m, net, b, (b.h if spec.has_hardening else None), P, P0


@pytest.mark.parametrize("dim", [2, 3])
def test_widths_and_input_layout(dim):
    assert energy_widths(2, False) == [8, 32, 32, 32, 1] and energy_widths(2, True) == [9, 32, 32, 32, 1]
    assert energy_widths(3, False) == [18, 64, 64, 64, 1] and energy_widths(3, True) == [19, 64, 64, 64, 1]
    assert return_map_widths(2) == [3, 32, 32, 32, 1] and return_map_widths(3) == [4, 64, 64, 64, 1]
    F = torch.arange(dim * dim, dtype=torch.float64).reshape(1, dim, dim)
    x = energy_input(F, 10 + F, torch.tensor([0.5], dtype=torch.float64))
    assert x.tolist()[0] == list(range(dim * dim)) + [10.0 + k for k in range(dim * dim)] + [0.5]
    net = make_mlp(energy_widths(dim, True), 3)
    assert [type(l).__name__ for l in net.layers] == ["Linear", "SiLU", "Linear", "SiLU", "Linear", "SiLU", "Linear"]
    assert all(torch.equal(p, q) for p, q in zip(net.parameters(), make_mlp(energy_widths(dim, True), 3).parameters()))


@pytest.mark.parametrize("name,dim", [("sand", 2), ("snow", 3), ("metal", 2)])
def test_gradient_at_F0_is_the_target(name, dim):
    """grad_F Psi(F0, F0, h) = Ptilde(F0, h) whatever the network (the correction of eq. 8), also with w != 0."""
    m, net, b, h, P, P0 = _setup(name, dim)
    for w in (0.0, 1.0):
        g = psi_gradient(net, b.F0, b.F0, h, P0, w=w, mu=m.mu)
        assert float((g - P0).abs().max()) <= 1e-13 * float(P0.abs().max())


@pytest.mark.parametrize("name,dim", [("sand", 3), ("snow", 2)])
def test_psi_gradient_is_the_derivative_of_psi(name, dim):
    m, net, b, h, P, P0 = _setup(name, dim, n=16)
    F = b.F.clone().requires_grad_(True)
    (g_auto,) = torch.autograd.grad(psi(net, F, b.F0, h, P0, w=0.7, mu=m.mu).sum(), F)
    g = psi_gradient(net, b.F, b.F0, h, P0, w=0.7, mu=m.mu)
    assert torch.allclose(g, g_auto, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("name,dim", [("sand", 2), ("metal", 3)])
def test_loss_is_eq9(name, dim):
    """The fused 2B-input loss equals mean ||grad Psi - Ptilde||^2 computed term by term, and its parameter
    gradient comes through the input gradient (double backward)."""
    m, net, b, h, P, P0 = _setup(name, dim)
    loss = energy_loss(net, b.F, b.F0, h, P, P0)
    ref = ((psi_gradient(net, b.F, b.F0, h, P0) - P) ** 2).sum((-2, -1)).mean()
    assert torch.allclose(loss, ref, rtol=1e-12)
    loss.backward()
    grads = [p.grad for p in net.parameters()]
    # The last layer's bias does not enter grad_F N: it gets no gradient (Adam leaves it as initialised).
    assert grads[-1] is None
    assert all(g is not None and torch.isfinite(g).all() and float(g.abs().max()) > 0 for g in grads[:-1])


def test_return_map_net_pieces():
    m = nondimensional_material("metal_nh", 2)
    net = make_mlp(return_map_widths(2), 0).double()
    Sigma, h = sample_return_map_states(2, 2000, seed=0)
    mask = return_map_net.yielding(m, Sigma, h)
    assert 0.3 < float(mask.double().mean()) < 0.99
    eps, L, n = return_map_net.flow_path(Sigma)
    dg = return_map_net.dgamma(net, Sigma, h)
    assert torch.all(dg <= L)
    Z = return_map_net.project(net, m, Sigma, h)
    # Volume preserving where projected, unchanged elsewhere.
    assert torch.allclose(torch.log(Z).sum(-1), eps.sum(-1), atol=1e-12)
    assert torch.equal(Z[~mask], Sigma[~mask])
    # With the exact dgamma (the library's root find) the yield term of eq. 13 vanishes.
    Z_exact = m.return_map(Sigma, h)[0]
    y = m.yield_function(Z_exact[mask], h[mask]) / return_map_net.yield_unit(m)
    assert float(y.abs().max()) < 1e-9
    loss = return_map_net.return_map_loss(net, m, Sigma, h)
    assert loss.ndim == 0 and float(loss) > 0
    loss.backward()
    assert all(p.grad is not None for p in net.parameters())


def test_return_map_residuals_share_their_zero_set_and_reject_unknown_names():
    from plasticitynet.training.nets import make_mlp, return_map_widths
    from plasticitynet.training.sampling import sample_return_map_states
    from plasticitynet.training.targets import nondimensional_material

    material = nondimensional_material("metal_nh", 2)
    net = make_mlp(return_map_widths(2), seed=0).double()
    Sigma, h = sample_return_map_states(2, 256, seed=3)
    radius = return_map_net.return_map_loss(net, material, Sigma, h, residual="radius")
    paper = return_map_net.return_map_loss(net, material, Sigma, h, residual="paper")
    assert radius > 0 and paper > 0 and radius != paper
    with pytest.raises(ValueError, match="residual"):
        return_map_net.return_map_loss(net, material, Sigma, h, residual="relative")


# --- the energy forms the paper rejected (sec. 5.2, Fig. 11) ----------------------------------------------
@pytest.mark.parametrize("form", ["local_identity", "global_identity", "global"])
@pytest.mark.parametrize("name,dim", [("sand", 2), ("snow", 3)])
def test_rejected_forms_are_what_the_paper_wrote(form, name, dim):
    """Each rejected form's gradient against its definition written out with autograd on the bare network:
    local_identity grad N(F, F0) - grad N(I, F0), global_identity grad N(F, I) - grad N(I, I), global
    grad N(F, I); the *_identity forms give zero stress at F = I, the global ones do not depend on F0."""
    m, net, b, h, P, P0 = _setup(name, dim, n=16)
    eye = torch.eye(dim, dtype=torch.float64).expand_as(b.F)

    def grad_n(F, slot):
        F = F.clone().requires_grad_(True)
        (g,) = torch.autograd.grad(net(energy_input(F, slot, h)).sum(), F)
        return g

    slot = b.F0 if form == "local_identity" else eye
    expected = grad_n(b.F, slot) - (grad_n(eye, slot) if form != "global" else 0.0)
    g = psi_gradient(net, b.F, b.F0, h, P0, form=form)
    assert torch.allclose(g, expected, rtol=1e-12, atol=1e-14)
    # w != 0 adds the regularizer of eq. 11 around F0 as in eq. 8.
    g_w = psi_gradient(net, b.F, b.F0, h, P0, w=0.5, mu=m.mu, form=form)
    assert torch.allclose(g_w - g, 0.5 * m.mu * (b.F - b.F0), rtol=1e-12, atol=1e-14)
    # psi's autograd derivative is psi_gradient.
    F = b.F.clone().requires_grad_(True)
    (g_auto,) = torch.autograd.grad(psi(net, F, b.F0, h, P0, w=0.5, mu=m.mu, form=form).sum(), F)
    assert torch.allclose(g_auto, g_w, rtol=1e-12, atol=1e-13)
    at_identity = psi_gradient(net, eye.clone(), b.F0, h, P0, form=form)
    if form != "global":
        assert float(at_identity.abs().max()) < 1e-12
    else:
        assert float(at_identity.abs().max()) > 1e-6  # nothing makes N's gradient vanish at I
    if form != "local_identity":
        other_F0 = b.F0.flip(0)
        assert torch.allclose(psi_gradient(net, b.F, other_F0, h, P0.flip(0), form=form), g, rtol=1e-13, atol=1e-15)
    # Unlike eq. 8, none of them reproduces Ptilde(F0) at F = F0 by construction.
    assert float((psi_gradient(net, b.F0, b.F0, h, P0, form=form) - P0).abs().max()) > 1e-3


@pytest.mark.parametrize("form", ["eq8", "local_identity", "global_identity", "global"])
def test_loss_of_each_form_is_eq9_with_its_gradient(form):
    """The fused loss of every form equals mean ||grad Psi - Ptilde||^2 with that form's grad Psi (for
    "global", the paper's L = E_F ||grad N(F) - Ptilde(F)||^2 of sec. 5.2), and trains the network."""
    m, net, b, h, P, P0 = _setup("sand", 2)
    loss = energy_loss(net, b.F, b.F0, h, P, P0, form=form)
    ref = ((psi_gradient(net, b.F, b.F0, h, P0, form=form) - P) ** 2).sum((-2, -1)).mean()
    assert torch.allclose(loss, ref, rtol=1e-12)
    loss.backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in list(net.parameters())[:-1])


def test_unknown_form_is_refused():
    m, net, b, h, P, P0 = _setup("sand", 2, n=4)
    with pytest.raises(ValueError, match="energy_form = 'polar': expected one of eq8, local_identity"):
        psi_gradient(net, b.F, b.F0, h, P0, form="polar")
