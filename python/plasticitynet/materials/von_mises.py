"""von Mises return mapping for metal (paper appendix A.2.3 and eq. 24; docs/physics.md).

State h = tau_Y / (2 mu) >= 0 (dimensionless yield stress). With eps = log(Sigma_c),
L = ||dev(eps)|| and n = dev(eps) / L, plastic flow follows the volume-preserving path
eps(dg) = eps - dg n, dg in [0, L], and hardens h_new = h + xi dg in the yield branch.
"""

from __future__ import annotations

import torch

from .branches import ELASTIC, YIELD
from .device import should_test, sync_interval
from .elasticity import StVKHencky
from .params import VonMisesParams
from .plasticity import PlasticityModel

#: Number of uniform steps of the bracketing scan over dg in [0, L] (neo-Hookean root find).
SCAN_STEPS = 16
#: Upper bound on bisection steps: the bracket L/16 shrinks to adjacent floats long before.
MAX_BISECTION_STEPS = 80


class VonMises(PlasticityModel):
    name = "von_mises"
    BRANCHES = (ELASTIC, YIELD)
    PARAMS = VonMisesParams

    def _checked(self, Sigma, h):
        Sigma, h = super()._checked(Sigma, h)
        negative = h < 0
        if negative.any():
            i = int(torch.nonzero(negative)[0, 0])
            raise ValueError(
                f"hardening: von Mises hardening h = tau_Y/(2 mu) must be >= 0, got {h[i].item()!r} at index {i}"
            )
        return Sigma, h

    def yield_function(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """y = ||dev tau(Sigma)||^2 - (2 mu h)^2, Pa^2 (<= 0 elastic). Differentiable in Sigma by autograd."""
        tau = self.elasticity.tau(Sigma)
        dev_tau = tau - tau.mean(-1, keepdim=True)
        two_mu_h = 2.0 * self.elasticity.mu * h
        return (dev_tau * dev_tau).sum(-1) - two_mu_h * two_mu_h

    def yield_scale(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """||dev tau||^2 + (2 mu h)^2, Pa^2."""
        tau = self.elasticity.tau(Sigma)
        dev_tau = tau - tau.mean(-1, keepdim=True)
        two_mu_h = 2.0 * self.elasticity.mu * h
        return (dev_tau * dev_tau).sum(-1) + two_mu_h * two_mu_h

    def return_map(self, Sigma: torch.Tensor, h: torch.Tensor):
        """StVK-Hencky: closed form dgamma = L - h. Other elasticity: smallest root of
        g(dg) = y(exp(eps - dg n), h) on [0, L], bracketed by a 16-step scan and bisected to
        adjacent floats (|bracket| <= 1e-14 L). Z = exp(eps - dg n)."""
        Sigma, h = self._checked(Sigma, h)
        eps = torch.log(Sigma)
        dev_eps = eps - eps.mean(-1, keepdim=True)
        L = torch.linalg.vector_norm(dev_eps, dim=-1)
        safe_L = torch.where(L > 0, L, torch.ones_like(L))
        n = dev_eps / safe_L[:, None]

        if isinstance(self.elasticity, StVKHencky):
            dgamma = L - h
            yielding = dgamma > 0
        else:
            yielding = (self.yield_function(Sigma, h) > 0) & (L > 0)
            dgamma = self._root(eps, n, L, h, yielding)

        dgamma = torch.where(yielding, dgamma, torch.zeros_like(dgamma))
        Z = torch.where(yielding[:, None], torch.exp(eps - dgamma[:, None] * n), Sigma)
        h_new = torch.where(yielding, h + self.params.hardening_coefficient * dgamma, h)
        branch = torch.where(
            yielding, torch.full_like(L, YIELD, dtype=torch.int64), torch.full_like(L, ELASTIC, dtype=torch.int64)
        )
        return Z, h_new, branch

    def _root(self, eps, n, L, h, yielding):
        """dg with g(dg) = 0 for the rows in `yielding` (others: arbitrary finite values)."""
        B = eps.shape[0]
        d = eps.shape[-1]
        if not bool(yielding.any()):
            return torch.zeros_like(L)

        def g(dg: torch.Tensor, h_: torch.Tensor) -> torch.Tensor:
            # dg: (B, m) -> g at eps - dg n, shape (B, m)
            path = eps[:, None, :] - dg[..., None] * n[:, None, :]
            m = dg.shape[1]
            y = self.yield_function(torch.exp(path).reshape(B * m, d), h_[:, None].expand(B, m).reshape(B * m))
            return y.reshape(B, m)

        # Scan dg_k = k L / 16, k = 1..16; take the first k with g(dg_k) <= 0 (k = 16 if none).
        k = torch.arange(1, SCAN_STEPS + 1, dtype=eps.dtype, device=eps.device)
        dg_scan = k[None, :] * L[:, None] / SCAN_STEPS
        inside = g(dg_scan, h) <= 0
        inside[:, -1] = True
        first = (torch.cumsum(inside.to(torch.int64), dim=1) == 0).sum(-1)  # 0-based index of k
        hi = torch.gather(dg_scan, 1, first[:, None])[:, 0]
        lo = first.to(eps.dtype) * L / SCAN_STEPS  # dg_{k-1}; g(lo) > 0

        # Bisection keeping g(lo) > 0 >= g(hi) until lo and hi are adjacent floats.
        every = sync_interval(eps.device)
        for it in range(MAX_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            done = (mid <= lo) | (mid >= hi) | ~yielding
            if should_test(it, every) and bool(done.all()):
                break
            above = g(mid[:, None], h)[:, 0] > 0
            lo = torch.where(above & ~done, mid, lo)
            hi = torch.where(~above & ~done, mid, hi)
        return hi
