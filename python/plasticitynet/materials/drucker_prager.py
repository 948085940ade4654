"""Drucker-Prager return mapping for sand with StVK-Hencky elasticity (Klar et al. 2016;
paper appendix A.2.1, eqs. 15-16; docs/physics.md). No hardening: h is passed through."""

from __future__ import annotations

import torch

from .branches import APEX, CONE, ELASTIC
from .elasticity import ElasticityModel, StVKHencky
from .params import DruckerPragerParams
from .plasticity import PlasticityModel


class DruckerPrager(PlasticityModel):
    name = "drucker_prager"
    BRANCHES = (ELASTIC, APEX, CONE)
    PARAMS = DruckerPragerParams
    REQUIRED_ELASTICITY = StVKHencky

    def __init__(self, params: DruckerPragerParams, elasticity: ElasticityModel):
        super().__init__(params, elasticity)
        self.alpha = params.alpha

    def return_map(self, Sigma: torch.Tensor, h: torch.Tensor):
        """Z(Sigma, h), eps = log(Sigma_c):
        tr(eps) > 0 -> Z = 1 (apex); else eh = dev(eps),
        dgamma = ||eh|| + alpha (d lambda + 2 mu) tr(eps) / (2 mu);
        dgamma <= 0 -> Z = Sigma_c (elastic); else Z = exp(eps - dgamma eh / ||eh||) (cone)."""
        Sigma, h = self._checked(Sigma, h)
        d = Sigma.shape[-1]
        mu, lam = self.elasticity.mu, self.elasticity.lam
        eps = torch.log(Sigma)
        tr_eps = eps.sum(-1)
        eps_hat = eps - tr_eps[:, None] / d
        eps_hat_norm = torch.linalg.vector_norm(eps_hat, dim=-1)
        dgamma = eps_hat_norm + self.alpha * (d * lam + 2.0 * mu) * tr_eps / (2.0 * mu)
        apex = tr_eps > 0
        cone = ~apex & (dgamma > 0)
        # dgamma > 0 with tr(eps) <= 0 implies ||eh|| > 0; the guard only keeps other rows finite.
        safe_norm = torch.where(eps_hat_norm > 0, eps_hat_norm, torch.ones_like(eps_hat_norm))
        Z_cone = torch.exp(eps - (dgamma / safe_norm)[:, None] * eps_hat)
        Z = torch.where(apex[:, None], torch.ones_like(Sigma), torch.where(cone[:, None], Z_cone, Sigma))
        branch = torch.full_like(tr_eps, ELASTIC, dtype=torch.int64)
        branch = torch.where(cone, torch.full_like(branch, CONE), branch)
        branch = torch.where(apex, torch.full_like(branch, APEX), branch)
        return Z, h.clone(), branch

    def yield_function(self, Sigma: torch.Tensor, h: torch.Tensor | None = None) -> torch.Tensor:
        """y = ||dev tau|| + alpha tr(tau), Pa (<= 0 elastic; = 2 mu dgamma for StVK-Hencky; apex: tau = 0)."""
        tau = self.elasticity.tau(Sigma)
        d = tau.shape[-1]
        tr = tau.sum(-1)
        return torch.linalg.vector_norm(tau - tr[:, None] / d, dim=-1) + self.alpha * tr

    def yield_scale(self, Sigma: torch.Tensor, h: torch.Tensor | None = None) -> torch.Tensor:
        """||dev tau|| + alpha |tr(tau)|, Pa."""
        tau = self.elasticity.tau(Sigma)
        d = tau.shape[-1]
        tr = tau.sum(-1)
        return torch.linalg.vector_norm(tau - tr[:, None] / d, dim=-1) + self.alpha * tr.abs()
