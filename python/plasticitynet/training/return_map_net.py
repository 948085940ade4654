"""The learned volume-preserving return mapping (paper sec. 4.3, eqs. 12-13; appendix A.2.4), used for
von Mises plasticity with the metal neo-Hookean elasticity, which has no closed form.

Diagonal space, Sigma_c = max(Sigma, 1e-4), eps = log(Sigma_c), L = ||dev(eps)||, n = dev(eps) / L.
Plastic flow follows the volume-preserving path H(dg) = eps - dg n (det Z = det Sigma):

    dgamma_theta(Sigma, h) = min(N(x), L),   x = [Sigma_c (d values, in the caller's order), h],
    Z_theta = exp(eps - dgamma_theta n)   where y(Sigma_c, h) > 0 (and L > 0),   Z_theta = Sigma_c elsewhere,  (eq. 12)

with y(Sigma, h) = ||dev tau(Sigma)||^2 - (2 mu h)^2 the library's (differentiable) yield function.
Training loss over the yielding samples (y(Sigma, h) > 0; the others contribute nothing), eq. 13:

    l = r(Z_theta, h)^2 + max(N(x) - L, 0),

with r the yield function made dimensionless in one of two ways (`residual`):
- "paper": r = y / (2 mu)^2 = ||dev tau / (2 mu)||^2 - h^2, eq. 13 as printed. Near the surface
  r ~ 2 h (||dev tau||/(2 mu) - h), so points with a small yield radius h barely count.
- "radius" (default): r = y / (2 mu (||dev tau|| + 2 mu h)) = ||dev tau||/(2 mu) - h, the same zero
  set with every h weighted alike. Measured on 2D metal_nh, 3000 steps of batch 4096: mean
  |dgamma_theta - dgamma_exact| 5.1e-3 against 1.8e-2 with "paper", mean |y|/(2 mu h)^2 0.044
  against 0.26.

Two deliberate readings of eq. 13:
- y is divided by (2 mu)^2, so y / (2 mu)^2 = ||dev tau / (2 mu)||^2 - h^2 is dimensionless and
  O(h^2) near the surface (h in [0, 1]); the loss is then O(1) and independent of E.
- The penalty acts on the raw output N(x): written with the clamped dgamma_theta = min(N, L) it
  would be identically zero. Its purpose (sec. 4.3) is to keep N below L, so that points are
  projected to the first intersection of the path with the surface, not clamped onto the diagonal.
The loss is the mean over the yielding samples of the batch (the paper's per-sample loss is 0 for
the others; dividing by their count instead of the batch size only rescales the learning rate).
"""

from __future__ import annotations

import torch
from torch import nn

from ..materials import Material, clamp_sigma


def return_map_input(Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """x = [Sigma_c (d), h], shape (B, d + 1)."""
    return torch.cat([clamp_sigma(Sigma), h.reshape(-1, 1).to(Sigma.dtype)], dim=1)


def flow_path(Sigma: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(eps, L, n): eps = log(Sigma_c), L = ||dev eps||, n = dev eps / L (n = 0 where L = 0)."""
    eps = torch.log(clamp_sigma(Sigma))
    dev = eps - eps.mean(-1, keepdim=True)
    L = torch.linalg.vector_norm(dev, dim=-1)
    safe_L = torch.where(L > 0, L, torch.ones_like(L))
    return eps, L, dev / safe_L[:, None]


def dgamma(net: nn.Module, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """dgamma_theta = min(N(Sigma_c, h), ||dev eps||), (B,)."""
    _, L, _ = flow_path(Sigma)
    return torch.minimum(net(return_map_input(Sigma, h))[:, 0], L)


def yielding(material: Material, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """y(Sigma_c, h) > 0 and L > 0 (the rows the learned mapping projects), (B,) bool."""
    _, L, _ = flow_path(Sigma)
    return (material.yield_function(clamp_sigma(Sigma), h) > 0) & (L > 0)


def project(net: nn.Module, material: Material, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """Z_theta(Sigma, h) of eq. 12, (B, d)."""
    eps, _, n = flow_path(Sigma)
    dg = dgamma(net, Sigma, h)
    Z = torch.exp(eps - dg[:, None] * n)
    return torch.where(yielding(material, Sigma, h)[:, None], Z, clamp_sigma(Sigma))


def yield_unit(material: Material) -> float:
    """(2 mu)^2: y / (2 mu)^2 is dimensionless."""
    return (2.0 * material.mu) ** 2


#: Ways to make the yield function dimensionless in the loss (module docstring).
RESIDUALS = ("radius", "paper")


def return_map_loss(
    net: nn.Module, material: Material, Sigma: torch.Tensor, h: torch.Tensor, residual: str = "radius"
) -> torch.Tensor:
    """Eq. 13 (see the module docstring) averaged over the yielding samples; 0 if none yields."""
    if residual not in RESIDUALS:
        raise ValueError(f"residual = {residual!r}: expected one of {', '.join(RESIDUALS)}")
    with torch.no_grad():
        mask = yielding(material, Sigma, h)
    if not bool(mask.any()):
        return net(return_map_input(Sigma[:1], h[:1])).sum() * 0.0
    Sigma, h = Sigma[mask], h[mask]
    eps, L, n = flow_path(Sigma)
    raw = net(return_map_input(Sigma, h))[:, 0]
    dg = torch.minimum(raw, L)
    Z = torch.exp(eps - dg[:, None] * n)
    y = material.yield_function(Z, h)
    if residual == "paper":
        r = y / yield_unit(material)
    else:  # y = (a - b)(a + b) with a = ||dev tau||, b = 2 mu h: r = (a - b) / (2 mu)
        tau = material.tau(Z)
        a = torch.linalg.vector_norm(tau - tau.mean(-1, keepdim=True), dim=-1)
        r = y / (2.0 * material.mu * (a + 2.0 * material.mu * h))
    return (r * r + torch.relu(raw - L)).mean()
