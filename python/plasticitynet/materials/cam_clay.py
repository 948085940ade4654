"""Non-associative Cam-Clay return mapping for snow with the snow neo-Hookean elasticity
(Wolper et al. 2019, CD-MPM; paper appendix A.2.2, eqs. 17-20; docs/physics.md).

Hardening state h = a, the log of the plastic volume ratio (a < 0 hardens). With J = prod(Sigma_c),
b = Sigma_c^2, compression-positive pressure p = -K/2 (J^2 - 1), p0 = K sinh(xi max(-a, 0)),
deviatoric stress s = mu J^{-2/d} dev(b), the yield function is the ellipse
    y = (6-d)/2 (1 + 2 beta) ||s||^2 + M^2 (p + beta p0)(p - p0)      (Pa^2),
with tips at p = p0 (compression) and p = -beta p0 (tension).
"""

from __future__ import annotations

import torch

from .branches import COMPRESSION_TIP, ELASTIC, ELLIPSE, TENSION_TIP
from .device import should_test, sync_interval
from .elasticity import NeoHookeanSnow
from .params import CamClayParams
from .plasticity import PlasticityModel
from .svd import clamp_sigma


class CamClay(PlasticityModel):
    name = "cam_clay"
    BRANCHES = (ELASTIC, COMPRESSION_TIP, TENSION_TIP, ELLIPSE)
    PARAMS = CamClayParams
    REQUIRED_ELASTICITY = NeoHookeanSnow

    def _state(self, Sigma: torch.Tensor, a: torch.Tensor):
        """J, b, p, p0, s, M for clamped Sigma."""
        d = Sigma.shape[-1]
        mu, K = self.elasticity.mu, self.elasticity.K
        log_J = torch.log(Sigma).sum(-1)
        J = torch.exp(log_J)
        b = Sigma * Sigma
        p = -0.5 * K * torch.expm1(2.0 * log_J)  # -K/2 (J^2 - 1)
        p0 = K * torch.sinh(self.params.xi * torch.clamp(-a, min=0.0))
        s = mu * torch.exp(-2.0 / d * log_J)[:, None] * (b - b.sum(-1, keepdim=True) / d)
        return J, b, p, p0, s, self.params.M(d)

    def yield_function(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """y = (6-d)/2 (1+2 beta) ||s||^2 + M^2 (p + beta p0)(p - p0), Pa^2 (<= 0 inside the ellipse)."""
        Sigma = clamp_sigma(Sigma)
        d = Sigma.shape[-1]
        beta = self.params.beta
        _, _, p, p0, s, M = self._state(Sigma, h)
        return (6 - d) / 2 * (1 + 2 * beta) * (s * s).sum(-1) + M * M * (p + beta * p0) * (p - p0)

    def yield_scale(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """(6-d)/2 (1+2 beta) ||s||^2 + M^2 (|p| + beta p0)(|p| + p0), Pa^2."""
        Sigma = clamp_sigma(Sigma)
        d = Sigma.shape[-1]
        beta = self.params.beta
        _, _, p, p0, s, M = self._state(Sigma, h)
        return (6 - d) / 2 * (1 + 2 * beta) * (s * s).sum(-1) + M * M * (p.abs() + beta * p0) * (p.abs() + p0)

    def return_map(self, Sigma: torch.Tensor, h: torch.Tensor):
        """Z(Sigma, a), tested in the spec's order: compression tip (p > p0), tension tip
        (p < -beta p0), elastic (y <= 0), else ellipse; a += log(J / J_x) off the elastic branch."""
        Sigma, a = self._checked(Sigma, h)
        d = Sigma.shape[-1]
        mu, K = self.elasticity.mu, self.elasticity.K
        beta = self.params.beta
        J, b, p, p0, s, M = self._state(Sigma, a)
        s_norm2 = (s * s).sum(-1)
        y = (6 - d) / 2 * (1 + 2 * beta) * s_norm2 + M * M * (p + beta * p0) * (p - p0)

        compression = p > p0
        tension = ~compression & (p < -beta * p0)
        elastic = ~compression & ~tension & (y <= 0)
        ellipse = ~compression & ~tension & ~elastic

        # Tips: Z = J_new^{1/d} 1. p < K/2 always, so p > p0 implies 1 - 2 p0/K > 0; the clamp
        # only keeps rows of other branches finite.
        J_compression = torch.sqrt(torch.clamp(1.0 - 2.0 * p0 / K, min=0.0))
        J_tension = torch.sqrt(1.0 + 2.0 * beta * p0 / K)

        # Ellipse at fixed p: s_new = sqrt(-M^2 (p + beta p0)(p - p0) / ((6-d)/2 (1+2 beta))) s/||s||.
        s_norm = torch.sqrt(s_norm2)
        safe_s_norm = torch.where(s_norm > 0, s_norm, torch.ones_like(s_norm))
        q_new = torch.sqrt(torch.clamp(-M * M * (p + beta * p0) * (p - p0), min=0.0) / ((6 - d) / 2 * (1 + 2 * beta)))
        s_new = (q_new / safe_s_norm)[:, None] * s
        if self.params.variant == "exact":
            # Keep J: bbar_new = c 1 + t, t = s_new / mu, prod(c + t_i) = 1, Z = J^{1/d} sqrt(bbar_new).
            t = s_new / mu
            c = unimodular_shift(t)
            Z_ellipse = (J ** (1.0 / d))[:, None] * torch.sqrt(c[:, None] + t)
        else:
            # Paper eq. 20 (as in Ziran): b_new = J^{2/d}/mu s_new + tr(b)/d 1, Z = sqrt(b_new).
            b_new = (J ** (2.0 / d) / mu)[:, None] * s_new + b.sum(-1, keepdim=True) / d
            Z_ellipse = torch.sqrt(torch.clamp(b_new, min=0.0))

        # J_x: where the ray from the ellipse centre (pc, 0) through (p, q) meets the ellipse (CD-MPM).
        pc = (1.0 - beta) * p0 / 2
        R = (1.0 + beta) * p0 / 2
        u = p - pc
        q2 = (6 - d) / 2 * s_norm2
        ray_den = torch.sqrt((1 + 2 * beta) * q2 + M * M * u * u)
        t_ray = M * R / torch.where(ray_den > 0, ray_den, torch.ones_like(ray_den))
        p_x = pc + t_ray * u
        J_ellipse = torch.sqrt(torch.clamp(1.0 - 2.0 * p_x / K, min=1e-12))

        ones = torch.ones_like(Sigma)
        Z = torch.where(elastic[:, None], Sigma, Z_ellipse)
        Z = torch.where(tension[:, None], (J_tension ** (1.0 / d))[:, None] * ones, Z)
        Z = torch.where(compression[:, None], (J_compression ** (1.0 / d))[:, None] * ones, Z)

        J_x = torch.where(compression, J_compression, torch.where(tension, J_tension, J_ellipse))
        safe_J_x = torch.where(elastic | (J_x <= 0), torch.ones_like(J_x), J_x)
        a_new = torch.where(elastic, a, a + torch.log(J / safe_J_x))

        branch = torch.full_like(p, ELASTIC, dtype=torch.int64)
        branch = torch.where(ellipse, torch.full_like(branch, ELLIPSE), branch)
        branch = torch.where(tension, torch.full_like(branch, TENSION_TIP), branch)
        branch = torch.where(compression, torch.full_like(branch, COMPRESSION_TIP), branch)
        return Z, a_new, branch


def unimodular_shift(t: torch.Tensor) -> torch.Tensor:
    """c with prod_i (c + t_i) = 1 and c + t_i > 0, for deviatoric t of shape (B, d).

    2D: (c + t_0)(c - t_0) = 1, so c = sqrt(1 + t_0^2). 3D: f(c) = prod(c + t_i) - 1 is increasing
    and convex for c > -min t_i, so Newton from c = 1 + max|t_i| (where f >= 0) decreases monotonically
    to the root; stop when |dc| <= 1e-15 c (float64; a few ulps in float32), at most 100 iterations.
    """
    d = t.shape[-1]
    if d == 2:
        return torch.sqrt(1.0 + t[:, 0] * t[:, 0])
    tol = max(1e-15, 4.0 * torch.finfo(t.dtype).eps)
    c = 1.0 + t.abs().amax(-1)
    active = torch.ones_like(c, dtype=torch.bool)
    every = sync_interval(t.device)
    for it in range(100):
        x = c[:, None] + t
        f = x.prod(-1) - 1.0
        fp = x[:, 0] * x[:, 1] + x[:, 0] * x[:, 2] + x[:, 1] * x[:, 2]
        dc = f / fp
        c = torch.where(active, c - dc, c)
        active = active & ~(dc.abs() <= tol * c)
        if should_test(it, every) and not bool(active.any()):
            break
    return c

