"""The PlasticityNet energy (paper eqs. 8, 9, 11; docs/physics.md) around an MLP N(x), x = [vec F, vec F0, h]:

    Psi(F, F0, h) = N(F, F0, h) - c : F + w mu/2 ||F - F0||^2,
    c = grad_F N(F0, F0, h) - Ptilde(F0, h),                                            (eq. 8, 11)

so that grad_F Psi(F0, F0, h) = Ptilde(F0, h) exactly, whatever N is:
    grad_F Psi = grad_F N(F, F0, h) - c + w mu (F - F0),
    Hess_F Psi = Hess_F N(F, F0, h) + w mu I.
c is a constant of F (the simulator computes it once per optimization); grad_F N means the
derivative with respect to the first d^2 inputs only. The regularizer weight w is 0 in training
(eq. 9 has none); eq. 11 adds it at simulation time, with w = 1 in the paper.

Training loss (eq. 9): L = mean_batch ||grad_F Psi(F, F0, h) - Ptilde(F, h)||_F^2, with grad_F N
taken by autograd and kept in the graph (create_graph=True): the loss is differentiated with respect
to the network's parameters through the input gradient (double backward).

Hessian-aware training (beyond the paper; its future work 3), `hessian_weight` w_H > 0:
    L = eq. 9 + w_H mean ||Hess_F Psi(F, F0, h) v - J(F, h) v||^2 / ||v||^2,  J = d Ptilde/dF,
with one random direction v per sample (E_v ||A v||^2 / ||v||^2 = ||A||_F^2 / d^2 for v ~ N(0, I), so
this is the Frobenius loss up to a factor at the cost of one more backward pass instead of d^2).
Hess_F Psi = Hess_F N at w = 0. The target is only the symmetric part of J = d Ptilde/dF (a return
mapping's J is not symmetric; only its symmetric part is the Hessian of some energy), and it needs no
symmetrization: for a symmetric H, ||H - J||_F^2 = ||H - sym J||_F^2 + ||skew J||_F^2, so the loss is
taken against J v itself (`stress_directional_derivative`: two stress evaluations, not 2 d^2) and differs
from the loss against sym(J) v by a constant of the network (E ||skew(J) v||^2 / ||v||^2).
"""

from __future__ import annotations

import torch
from torch import nn

from .nets import energy_input

#: The energy's form: eq. 8 (the paper's, and the only one the simulator should use) and the three forms
#: the paper tried and rejected (sec. 5.2, Fig. 11), kept for that ablation:
#:   "eq8"             Psi = N(F, F0, h) - (grad_F N(F0, F0, h) - Ptilde(F0, h)) : F
#:   "local_identity"  Psi = N(F, F0, h) - grad_F N(I, F0, h) : F    (zero stress at F = I)
#:   "global_identity" Psi = N(F, I, h) - grad_F N(I, I, h) : F      (one global energy, zero stress at I)
#:   "global"          Psi = N(F, I, h)                              (one global energy)
#: The global forms feed the identity in the network's F0 slot, so N is a function of F (and h) alone
#: while the network, its file and the simulator's kernel stay those of eq. 8.
ENERGY_FORMS = ("eq8", "local_identity", "global_identity", "global")


def check_form(form: str) -> str:
    if form not in ENERGY_FORMS:
        raise ValueError(f"energy_form = {form!r}: expected one of {', '.join(ENERGY_FORMS)}")
    return form


def _identities_like(F0: torch.Tensor) -> torch.Tensor:
    return torch.eye(F0.shape[-1], dtype=F0.dtype, device=F0.device).expand_as(F0)


def network_reference(form: str, F0: torch.Tensor) -> torch.Tensor:
    """What the network's F0 slot receives: F0 for the local forms, the identity for the global ones."""
    return F0 if check_form(form) in ("eq8", "local_identity") else _identities_like(F0)


def _correction_point(form: str, F0: torch.Tensor) -> torch.Tensor:
    """Where the linear correction takes grad_F N: F0 for eq. 8, the identity for the *_identity forms."""
    return F0 if form == "eq8" else _identities_like(F0)


def _frob_inner(A: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """A : B = sum_ij A_ij B_ij per batch entry, (B,)."""
    return (A * B).sum((-2, -1))


def network_gradient(
    net: nn.Module, F: torch.Tensor, F0: torch.Tensor, h: torch.Tensor | None, create_graph: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """(N(F, F0, h) (B,), grad_F N(F, F0, h) (B, d, d)): the derivative in the first argument only.
    With create_graph=True and an F that requires grad, grad_F N stays differentiable in F (Hessian)."""
    with torch.enable_grad():
        if not F.requires_grad:
            F = F.detach().requires_grad_(True)
        N = net(energy_input(F, F0, h))[:, 0]
        (dN,) = torch.autograd.grad(N.sum(), F, create_graph=create_graph)
    return N, dN


def correction(
    net: nn.Module,
    F0: torch.Tensor,
    h: torch.Tensor | None,
    Ptilde0: torch.Tensor,
    create_graph: bool = False,
    form: str = "eq8",
) -> torch.Tensor:
    """c, (B, d, d), a constant of F: grad_F N(F0, F0, h) - Ptilde(F0, h) for eq. 8, grad_F N(I, F0, h) or
    grad_F N(I, I, h) for the *_identity forms, 0 for "global" (ENERGY_FORMS)."""
    F0 = F0.detach()
    if check_form(form) == "global":
        return torch.zeros_like(F0)
    c = network_gradient(net, _correction_point(form, F0), network_reference(form, F0), h, create_graph)[1]
    return c - Ptilde0 if form == "eq8" else c


def psi(
    net: nn.Module,
    F: torch.Tensor,
    F0: torch.Tensor,
    h: torch.Tensor | None,
    Ptilde0: torch.Tensor,
    w: float = 0.0,
    mu: float = 0.0,
    form: str = "eq8",
) -> torch.Tensor:
    """Psi(F, F0, h) (eq. 8 or another ENERGY_FORMS; eq. 11 with w != 0), (B,). Differentiable in F."""
    c = correction(net, F0, h, Ptilde0, form=form).detach()
    value = net(energy_input(F, network_reference(form, F0), h))[:, 0] - _frob_inner(c, F)
    if w != 0.0:
        D = F - F0
        value = value + 0.5 * w * mu * _frob_inner(D, D)
    return value


def psi_gradient(
    net: nn.Module,
    F: torch.Tensor,
    F0: torch.Tensor,
    h: torch.Tensor | None,
    Ptilde0: torch.Tensor,
    w: float = 0.0,
    mu: float = 0.0,
    create_graph: bool = False,
    form: str = "eq8",
) -> torch.Tensor:
    """grad_F Psi(F, F0, h) = grad_F N(F, F0, h) - c + w mu (F - F0), (B, d, d) (the F0 slot and c of `form`)."""
    _, dN = network_gradient(net, F, network_reference(form, F0), h, create_graph)
    g = dN - correction(net, F0, h, Ptilde0, create_graph, form)
    if w != 0.0:
        g = g + w * mu * (F - F0)
    return g


def energy_loss(
    net: nn.Module,
    F: torch.Tensor,
    F0: torch.Tensor,
    h: torch.Tensor | None,
    Ptilde: torch.Tensor,
    Ptilde0: torch.Tensor,
    hessian_weight: float = 0.0,
    direction: torch.Tensor | None = None,
    S_direction: torch.Tensor | None = None,
    parts: dict | None = None,
    form: str = "eq8",
    frame: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """Eq. 9: mean ||grad_F Psi(F, F0, h) - Ptilde(F, h)||_F^2 with, for eq. 8,
    grad_F Psi = grad_F N(F, F0, h) - grad_F N(F0, F0, h) + Ptilde(F0, h).
    Both input gradients come from one forward/backward pass over the 2B inputs
    [F, F0, h] and [F0, F0, h], kept in the graph for the parameter gradient. The other ENERGY_FORMS
    change the F0 slot and the correction point (the identity) and drop Ptilde(F0, h); "global" has no
    correction, so its loss is the paper's L = E_F ||grad_F N(F) - Ptilde(F)||^2 of sec. 5.2.

    With hessian_weight > 0, plus hessian_weight * mean ||Hess_F N(F, F0, h) v - J v||^2 / ||v||^2 for the
    directions v = `direction` (B, d, d) and the targets J v = `S_direction` (B, d, d), J = d Ptilde/dF
    (see the module docstring). `parts`, if given, receives the two terms' values (floats).
    `frame`, for a principal network (nets.EnergyNet), is principal_frame of its F0 slot (B rows) computed
    beforehand: the same loss without the polar SVD inside it."""
    B = F.shape[0]
    slot = network_reference(form, F0)
    if form == "global":
        first = F.detach().requires_grad_(True)
        second = slot
        hh = h
    else:
        first = torch.cat([F, _correction_point(form, F0)]).detach().requires_grad_(True)
        second = torch.cat([slot, slot])
        hh = None if h is None else torch.cat([h, h])
    if frame is None:
        N = net(energy_input(first, second, hh))
    else:
        copies = first.shape[0] // B  # the frame of the F0 slot, once per block of `first`
        U, Sigma0, V = (torch.cat([t] * copies) for t in frame)
        rest = first.new_zeros(first.shape[0], 0) if hh is None else hh.reshape(first.shape[0], -1).to(first.dtype)
        N = net.in_frame(first, U, Sigma0, V, rest)
    (dN,) = torch.autograd.grad(N.sum(), first, create_graph=True)
    grad_psi = dN[:B]
    if form != "global":
        grad_psi = grad_psi - dN[B:]
    if form == "eq8":
        grad_psi = grad_psi + Ptilde0
    residual = grad_psi - Ptilde
    loss = _frob_inner(residual, residual).mean()
    if parts is not None:
        parts["gradient"] = float(loss.detach())
    if hessian_weight > 0.0:
        if direction is None or S_direction is None:
            raise ValueError("hessian_weight > 0 needs the directions and their targets S v")
        (Hv,) = torch.autograd.grad(_frob_inner(dN[:B], direction).sum(), first, create_graph=True)
        r = Hv[:B] - S_direction
        hess = (_frob_inner(r, r) / _frob_inner(direction, direction)).mean()
        if parts is not None:
            parts["hessian"] = float(hess.detach())
        loss = loss + hessian_weight * hess
    return loss


def stress_directional_derivative(
    stress, F: torch.Tensor, h: torch.Tensor, v: torch.Tensor, step: float = 1e-6, p: torch.Tensor | None = None
) -> torch.Tensor:
    """J v = (d Ptilde/dF)[v] at (F, h) by central differences of `stress(F, h)` in float64, (B, d, d)
    (`stress(F, h, p)` for a parametric model's rows with parameters p)."""
    F = F.to(torch.float64)
    v = v.to(torch.float64)
    extra = () if p is None else (p,)
    return (stress(F + step * v, h, *extra) - stress(F - step * v, h, *extra)) / (2.0 * step)
