"""The frame-indifferent ("principal") energy input and the Hessian-aware loss (issue 16).

The frame: F0 = U diag(Sigma0) V^T (frames.principal_frame, the C++ polar_svd batched), the MLP sees
[U^T F V, Sigma0, h]. Checked: the decomposition itself (also at repeated and near-repeated singular
values), invariance under rotations on both sides (exact in 2D; in 3D exact up to the 4-element sign
group of the frame, which is checked exactly), exactness at F0, FD of the energy's gradient and Hessian,
export/load, and the Hessian loss (gradcheck, its target against the full Jacobian).
"""

import math

import pytest
import torch

from plasticitynet.model import LearnedEnergy, load_model
from plasticitynet.training import (
    ElastoplasticStress,
    TrainConfig,
    Trainer,
    energy_input,
    energy_loss,
    nondimensional_material,
    psi,
    psi_gradient,
    sample_batch,
    sampling_spec,
)
from plasticitynet.training.energy import stress_directional_derivative
from plasticitynet.training.export import energy_metadata, export_model, script_network
from plasticitynet.training.frames import principal_frame, to_frame
from plasticitynet.training.nets import EnergyNet, make_energy_net, make_mlp, mlp_input_width

D64 = torch.float64


def _rotations(n, d, seed):
    g = torch.Generator().manual_seed(seed)
    Q = torch.linalg.qr(torch.randn(n, d, d, dtype=D64, generator=g))[0]
    Q[torch.linalg.det(Q) < 0, :, 0] *= -1
    return Q


def _F(n, d, seed, scale=0.4):
    g = torch.Generator().manual_seed(seed)
    return torch.eye(d, dtype=D64) + scale * torch.randn(n, d, d, dtype=D64, generator=g)


def _repeated(d):
    """F0 with repeated or nearly repeated singular values, rotated and not, inverted and not."""
    R1, R2 = _rotations(6, d, 7), _rotations(6, d, 8)
    if d == 2:
        S = torch.tensor([[1.0, 1.0], [0.7, 0.7], [1.3, 1.3 + 1e-13], [1.1, 1.1 - 1e-9], [1.0, -1.0], [0.9, 0.9]], dtype=D64)
    else:
        S = torch.tensor(
            [[1.0, 1.0, 1.0], [1.2, 1.2, 0.8], [1.2, 0.8, 0.8], [1.0, 1.0 + 1e-12, 1.0 - 1e-12], [1.1, 1.1, -0.9],
             [0.9, 0.9, 0.9]],
            dtype=D64,
        )
    F0 = R1 @ torch.diag_embed(S) @ R2
    eye = torch.eye(d, dtype=D64).expand(2, d, d)
    diag = torch.diag_embed(S[:2])
    return torch.cat([F0, eye, diag])


@pytest.mark.parametrize("dim", [2, 3])
def test_principal_frame_is_a_polar_svd(dim):
    F0 = torch.cat([torch.randn(500, dim, dim, dtype=D64, generator=torch.Generator().manual_seed(dim)), _repeated(dim)])
    U, S, V = principal_frame(F0)
    eye = torch.eye(dim, dtype=D64)
    assert float((U @ torch.diag_embed(S) @ V.transpose(1, 2) - F0).abs().max()) < 1e-13
    assert float((U.transpose(1, 2) @ U - eye).abs().max()) < 1e-13
    assert float((V.transpose(1, 2) @ V - eye).abs().max()) < 1e-13
    assert float((torch.linalg.det(U) - 1).abs().max()) < 1e-13 and float((torch.linalg.det(V) - 1).abs().max()) < 1e-13
    assert bool((S[:, :-1] >= S[:, 1:].abs() - 1e-13).all()) and bool((S[:, :-1] >= 0).all())
    assert torch.equal(S[:, -1] < 0, torch.linalg.det(F0) < 0)
    # F0 = I (the rest state) and diagonal F0 give U = V = I exactly.
    U, S, V = principal_frame(torch.eye(dim, dtype=D64).expand(3, dim, dim))
    assert torch.equal(U, torch.eye(dim, dtype=D64).expand(3, dim, dim)) and torch.equal(V, U)
    assert torch.equal(S, torch.ones(3, dim, dtype=D64))
    # float32 input: the frame is computed in float64 and returned in float32.
    U32, _, _ = principal_frame(F0.float())
    assert U32.dtype == torch.float32


@pytest.mark.parametrize("dim", [2, 3])
def test_principal_input_is_frame_indifferent(dim):
    """Psi(Q F R, Q F0 R) = Psi(F, F0) and grad Psi(Q F R) = Q grad Psi(F) R: exactly (1e-12) in 2D, whose
    frame is unique up to (U, V) -> (-U, -V), which leaves G unchanged; in 3D the frame of Q F0 R is
    (Q U D, R^T V D) for one of the four D = diag(+-1) with det D = 1 (checked exactly), G becomes D G D, and
    invariance holds for nets invariant under that group: checked by symmetrizing a random net over it."""
    n = 200
    F0, F = _F(n, dim, 1), _F(n, dim, 2)
    h = torch.rand(n, dtype=D64, generator=torch.Generator().manual_seed(3))
    Q, R = _rotations(n, dim, 4), _rotations(n, dim, 5)
    U, _, V = principal_frame(F0)
    U2, _, V2 = principal_frame(Q @ F0 @ R)
    D = U2.transpose(1, 2) @ Q @ U
    Dv = V2.transpose(1, 2) @ R.transpose(1, 2) @ V
    diag = torch.diagonal(D, dim1=1, dim2=2)
    assert float((D - torch.diag_embed(diag)).abs().max()) < 1e-12 and float((D - Dv).abs().max()) < 1e-12
    assert float((diag.abs() - 1).abs().max()) < 1e-12
    net = make_energy_net(dim, True, "principal", 0).double()
    if dim == 3:
        assert len(torch.unique(torch.round(diag), dim=0)) > 1  # the sign group is really exercised

        class Symmetrized(torch.nn.Module):
            def __init__(self, inner):
                super().__init__()
                self.inner = inner

            def forward(self, x):
                B, m = x.shape[0], 9
                G = x[:, :m].reshape(B, 3, 3)
                out = 0
                for s in ([1, 1, 1], [-1, -1, 1], [-1, 1, -1], [1, -1, -1]):
                    Dg = torch.diag(torch.tensor(s, dtype=x.dtype))
                    out = out + self.inner(torch.cat([(Dg @ G @ Dg).reshape(B, m), x[:, m:]], 1))
                return out / 4

        net.mlp = Symmetrized(net.mlp)
    m = nondimensional_material("snow", dim)
    P0 = ElastoplasticStress(m)(F0, h)
    P0r = ElastoplasticStress(m)(Q @ F0 @ R, h)
    a = psi(net, F, F0, h, P0)
    b = psi(net, Q @ F @ R, Q @ F0 @ R, h, P0r)
    assert float((a - b).abs().max()) <= 1e-12 * (1 + float(a.abs().max()))
    ga = psi_gradient(net, F, F0, h, P0)
    gb = psi_gradient(net, Q @ F @ R, Q @ F0 @ R, h, P0r)
    assert float((Q @ ga @ R - gb).abs().max()) <= 1e-12 * (1 + float(ga.abs().max()))
    # The raw input of the paper is not invariant (a sanity check that the test can fail).
    raw = make_energy_net(dim, True, "raw", 0).double()
    assert float((psi(raw, F, F0, h, P0) - psi(raw, Q @ F @ R, Q @ F0 @ R, h, P0r)).abs().max()) > 1e-4


@pytest.mark.parametrize("dim", [2, 3])
def test_exact_at_F0_including_repeated_singular_values(dim):
    F0 = torch.cat([_F(20, dim, 9), _repeated(dim)])
    F0 = F0[torch.linalg.det(F0) > 0.05]  # the library's stress clamps inverted directions
    n = F0.shape[0]
    h = -0.2 * torch.rand(n, dtype=D64, generator=torch.Generator().manual_seed(1))
    m = nondimensional_material("snow", dim)
    P0 = ElastoplasticStress(m)(F0, h)
    net = make_energy_net(dim, True, "principal", 2).double()
    for w in (0.0, 1.0):
        g = psi_gradient(net, F0, F0, h, P0, w=w, mu=m.mu)
        assert bool(torch.isfinite(g).all())
        assert float((g - P0).abs().max()) <= 1e-13 * (1 + float(P0.abs().max()))


def _learned(dim, seed=0, representation="principal"):
    m = nondimensional_material("snow", dim)
    net = make_energy_net(dim, True, representation, seed)
    meta = energy_metadata(m, net, True, {"note": "test"})
    return LearnedEnergy(script_network(net), meta), net


@pytest.mark.parametrize("dim", [2, 3])
def test_finite_differences_of_the_principal_energy(dim):
    """LearnedEnergy on a principal net: gradient vs central differences of psi, Hessian vs central
    differences of the gradient, at generic F0 and at F0 with repeated singular values (incl. I)."""
    model, _ = _learned(dim)
    F0 = torch.cat([_F(4, dim, 11), _repeated(dim)[:4]])
    n = F0.shape[0]
    F = F0 + 0.05 * torch.randn(n, dim, dim, dtype=D64, generator=torch.Generator().manual_seed(12))
    h = torch.full((n,), -0.1, dtype=D64)
    g = model.gradient(F, F0, h, w=1.0)
    H = model.hessian(F, F0, h, w=1.0)
    eps = 1e-6
    checked = 0
    for k in range(dim * dim):
        E = torch.zeros(dim * dim, dtype=D64)
        E[k] = eps
        E = E.reshape(dim, dim)
        dpsi = (model.psi(F + E, F0, h, w=1.0) - model.psi(F - E, F0, h, w=1.0)) / (2 * eps)
        assert float((dpsi - g.reshape(n, -1)[:, k]).abs().max()) <= 1e-6 * (1 + float(g.abs().max()))
        dg = (model.gradient(F + E, F0, h, w=1.0) - model.gradient(F - E, F0, h, w=1.0)).reshape(n, -1) / (2 * eps)
        assert float((dg - H[:, :, k]).abs().max()) <= 1e-6 * (1 + float(H.abs().max()))
        checked += 2
    assert checked == 2 * dim * dim
    assert float((H - H.transpose(1, 2)).abs().max()) <= 1e-12 * float(H.abs().max())


@pytest.mark.parametrize("dim", [2, 3])
def test_export_and_load_round_trip(tmp_path, dim):
    m = nondimensional_material("snow", dim)
    net = make_energy_net(dim, True, "principal", 4)
    assert net.widths == [dim * dim + dim + 1, *([32] * 3 if dim == 2 else [64] * 3), 1]
    assert mlp_input_width(dim, True, "principal") == net.widths[0]
    path = export_model(tmp_path / "p.pt", net, energy_metadata(m, net, True, {"note": "test"}))
    model = load_model(path)
    assert model.representation == "principal" and model.has_hardening
    assert model.metadata["input_width"] == net.widths[0]
    assert model.metadata["layer_parameters"][0] == ["mlp.layers.0.weight", "mlp.layers.0.bias"]
    F0, F = _F(8, dim, 1), _F(8, dim, 2)
    h = torch.full((8,), -0.1, dtype=D64)
    x = energy_input(F, F0, h)
    assert float((model.network(x) - net.double()(x)).abs().max()) == 0.0
    U, S, V = principal_frame(F0)
    direct = net.mlp(torch.cat([to_frame(F, U, V).reshape(8, -1), S, h[:, None]], 1))
    assert float((model.network(x) - direct).abs().max()) <= 1e-14


def test_energy_net_rejects_bad_widths_and_representations():
    with pytest.raises(ValueError, match="representation"):
        EnergyNet(make_mlp([7, 8, 1], 0), 2, "fancy")
    with pytest.raises(ValueError, match="not a 2D principal energy network"):
        EnergyNet(make_mlp([9, 8, 1], 0), 2, "principal")
    with pytest.raises(ValueError, match="representation"):
        TrainConfig(material="sand", dim=2, representation="fancy")
    with pytest.raises(ValueError, match="hessian_weight"):
        TrainConfig(material="sand", dim=2, hessian_weight=-1.0)
    with pytest.raises(ValueError, match="hessian_weight"):
        TrainConfig(material="sand", dim=2, hessian_weight=math.nan)


# --- the Hessian loss --------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_stress_directional_derivative_matches_the_jacobian(dim):
    """J v by two stress evaluations equals the full central-difference Jacobian applied to v."""
    m = nondimensional_material("sand", dim)
    stress = ElastoplasticStress(m)
    b = sample_batch(sampling_spec(m, "paper"), 32, seed=1)
    v = torch.randn(32, dim, dim, dtype=D64, generator=torch.Generator().manual_seed(2))
    Jv = stress_directional_derivative(stress, b.F, b.h, v)
    cols = []
    for k in range(dim * dim):
        E = torch.zeros(dim * dim, dtype=D64)
        E[k] = 1e-6
        E = E.reshape(dim, dim)
        cols.append(((stress(b.F + E, b.h) - stress(b.F - E, b.h)) / 2e-6).reshape(32, -1))
    J = torch.stack(cols, -1)
    ref = (J @ v.reshape(32, -1, 1)).reshape(32, dim, dim)
    assert float((Jv - ref).abs().max()) <= 1e-5 * float(ref.abs().max())


def test_hessian_loss_is_the_hessian_residual_and_passes_gradcheck():
    """The Hessian term equals mean ||Hess_F N v - J v||^2/||v||^2 computed with an explicit Hessian, and
    its derivative in the parameters passes torch.autograd.gradcheck (float64, small net)."""
    dim, n = 2, 6
    m = nondimensional_material("snow", dim)
    spec = sampling_spec(m, "paper")
    b = sample_batch(spec, n, seed=3)
    stress = ElastoplasticStress(m)
    P = stress.from_factors(b.U, b.Sigma, b.V, b.h)
    P0 = stress.from_factors(b.U0, b.Sigma0, b.V0, b.h)
    v = torch.randn(n, dim, dim, dtype=D64, generator=torch.Generator().manual_seed(4))
    Jv = stress_directional_derivative(stress, b.F, b.h, v)
    net = EnergyNet(make_mlp([7, 5, 5, 1], 0), dim, "principal").double()
    parts = {}
    total = energy_loss(net, b.F, b.F0, b.h, P, P0, 0.5, v, Jv, parts)
    # explicit Hessian of N in F
    H = []
    for i in range(n):
        f = lambda Fi: net(energy_input(Fi[None], b.F0[i : i + 1], b.h[i : i + 1]))[0, 0]  # noqa: E731
        H.append(torch.autograd.functional.hessian(f, b.F[i]).reshape(dim * dim, dim * dim))
    H = torch.stack(H)
    r = (H @ v.reshape(n, -1, 1)).reshape(n, dim, dim) - Jv
    expected = ((r * r).sum((1, 2)) / (v * v).sum((1, 2))).mean()
    assert abs(parts["hessian"] - float(expected)) <= 1e-10 * float(expected)
    assert abs(float(total) - (parts["gradient"] + 0.5 * parts["hessian"])) <= 1e-12 * float(total)

    from torch.nn.utils.stateless import functional_call

    names = [name for name, _ in net.named_parameters()]

    class WithParameters(torch.nn.Module):
        def __init__(self, values):
            super().__init__()
            self.values = values

        def forward(self, x):
            return functional_call(net, dict(zip(names, self.values)), (x,))

    def loss_of(*values):
        return energy_loss(WithParameters(values), b.F, b.F0, b.h, P, P0, 0.5, v, Jv)

    values = tuple(p.detach().clone().requires_grad_(True) for p in net.parameters())
    assert abs(float(loss_of(*values)) - float(total)) <= 1e-14 * float(total)
    assert torch.autograd.gradcheck(loss_of, values, eps=1e-6, atol=1e-7, rtol=1e-5)


def test_trainer_with_hessian_weight_runs_and_resumes(tmp_path):
    """A few steps with the Hessian loss on, interrupted and resumed: the same weights as straight through;
    a checkpoint written with another representation or weight is refused."""
    common = dict(material="sand", dim=2, epochs=6, batch=64, progress=False, eval_samples=0, checkpoint_every=3)
    straight = Trainer(TrainConfig(out=str(tmp_path / "a.pt"), hessian_weight=0.3, **common))
    straight.run()
    Trainer(TrainConfig(out=str(tmp_path / "b.pt"), hessian_weight=0.3, **common)).run(stop_at=3)
    resumed = Trainer(TrainConfig(out=str(tmp_path / "b.pt"), hessian_weight=0.3, resume=True, **common))
    resumed.run()
    for p, q in zip(straight.net.parameters(), resumed.net.parameters()):
        assert torch.equal(p, q)
    assert "hessian" in straight.task.loss_parts
    with pytest.raises(ValueError, match="hessian_weight"):
        Trainer(TrainConfig(out=str(tmp_path / "b.pt"), hessian_weight=0.0, resume=True, **common))
    with pytest.raises(ValueError, match="representation"):
        Trainer(TrainConfig(out=str(tmp_path / "b.pt"), hessian_weight=0.3, representation="raw", resume=True, **common))


@pytest.mark.parametrize("form", ["eq8", "global"])
def test_loss_with_the_frame_computed_beforehand_is_the_same_loss(form):
    """energy_loss given principal_frame of the F0 slot (what training prepares for many steps at once) gives
    the loss and parameter gradient of the network computing the frame itself, in 3D (Jacobi SVD) and for a
    form whose F0 slot is the identity."""
    dim, n = 3, 40
    m = nondimensional_material("sand", dim)
    b = sample_batch(sampling_spec(m, "paper"), n, seed=5)
    stress = ElastoplasticStress(m)
    P = stress.from_factors(b.U, b.Sigma, b.V, b.h)
    P0 = stress.from_factors(b.U0, b.Sigma0, b.V0, b.h)
    v = torch.randn(n, dim, dim, dtype=D64, generator=torch.Generator().manual_seed(6))
    Jv = stress_directional_derivative(stress, b.F, b.h, v)
    net = make_energy_net(dim, False, "principal", seed=2).double()
    from plasticitynet.training.energy import network_reference

    results = []
    for frame in (None, principal_frame(network_reference(form, b.F0))):
        net.zero_grad()
        loss = energy_loss(net, b.F, b.F0, None, P, P0, 0.3, v, Jv, form=form, frame=frame)
        loss.backward()
        results.append((loss.detach(), [torch.zeros_like(p) if p.grad is None else p.grad.clone() for p in net.parameters()]))
    (l1, g1), (l2, g2) = results
    assert torch.equal(l1, l2)
    for a, c in zip(g1, g2):
        torch.testing.assert_close(a, c, rtol=1e-12, atol=0.0)


def test_steps_prepared_together_train_as_steps_prepared_one_by_one(tmp_path):
    """A GPU training prepares PREFETCH_STEPS steps' batches, targets and frames in one go; forced on the CPU
    (groups of 4, resumed in the middle of a group), it trains the same weights as one step at a time."""
    common = dict(material="snow", dim=3, epochs=7, batch=32, progress=False, eval_samples=0, checkpoint_every=3,
                  hessian_weight=0.2)
    one = Trainer(TrainConfig(out=str(tmp_path / "a.pt"), **common))
    one.run()
    grouped = Trainer(TrainConfig(out=str(tmp_path / "b.pt"), **common))
    grouped.task.prefetch_steps = 4
    grouped.run(stop_at=3)
    resumed = Trainer(TrainConfig(out=str(tmp_path / "b.pt"), resume=True, **common))
    resumed.task.prefetch_steps = 4
    resumed.run()
    for p, q in zip(one.net.parameters(), resumed.net.parameters()):
        torch.testing.assert_close(p, q, rtol=1e-6, atol=1e-7)
