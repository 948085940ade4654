"""Isotropic hyperelastic models in diagonal (principal) space (docs/physics.md; paper eqs. 14, 17, 24).

With F = U diag(Sigma) V^T (polar SVD), Sigma_c = max(Sigma, SIGMA_MIN) and the Hencky strain
eps = log(Sigma_c), each model gives psi(Sigma), the Kirchhoff stress tau_i = d psi / d eps_i and
the first Piola stress P = U diag(tau_i / Sigma_c_i) V^T. All diagonal-space functions take
Sigma of shape (B, d) and clamp it themselves; F-space functions take F of shape (B, d, d).

dP/dF is analytic (Irving et al. 2004; Teran et al. 2005): in the basis rotated by U and V it
splits into the d x d Hessian d^2 psi / d Sigma_i d Sigma_j on the diagonal entries and, per pair
i < j, a 2x2 block [[a, b], [b, a]] on the (ij, ji) entries, where a = (D + E)/2, b = (D - E)/2,
D = (P_i - P_j)/(Sigma_i - Sigma_j), E = (P_i + P_j)/(Sigma_i + Sigma_j), P_i = tau_i / Sigma_i.
D is formed from a closed-form difference quotient of tau, so that it stays exact (no 0/0) as
Sigma_i -> Sigma_j. The result is the exact Hessian of psi at the clamped F_c = U diag(Sigma_c) V^T.
"""

from __future__ import annotations

import torch

from .params import ElasticParams
from .svd import clamp_sigma, compose, polar_svd


def _log_difference_quotient(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(log a - log b) / (a - b) for a, b > 0, exact also as a -> b (= log1p(x) / (x b), x = a/b - 1)."""
    x = (a - b) / b
    x_safe = torch.where(x == 0, torch.ones_like(x), x)
    return torch.where(x == 0, 1.0 / b, torch.log1p(x_safe) / (x_safe * b))


class ElasticityModel:
    """Common face of every elasticity model: psi, tau, dtau/deps in diagonal space; psi, P, dP/dF in F space."""

    name = ""

    def __init__(self, params: ElasticParams):
        if not isinstance(params, ElasticParams):
            raise ValueError(f"elasticity: expected ElasticParams, got {type(params).__name__}")
        self.params = params
        self.mu = params.mu  # Pa
        self.lam = params.lam  # Pa
        self.K = params.K  # Pa

    # --- model-specific, diagonal space (Sigma: (B, d), already clamped) ---------------------
    def _psi(self, Sigma: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _tau(self, Sigma: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _dtau_deps(self, Sigma: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _tau_difference_quotient(self, Sigma: torch.Tensor, eps: torch.Tensor, i: int, j: int) -> torch.Tensor:
        """(tau_i - tau_j) / (Sigma_i - Sigma_j) in closed form, exact for Sigma_i == Sigma_j."""
        raise NotImplementedError

    # --- public, diagonal space ----------------------------------------------------------------
    def psi(self, Sigma: torch.Tensor) -> torch.Tensor:
        """Energy density psi(Sigma_c), J/m^3, shape (B,); zero at Sigma = 1."""
        Sigma = clamp_sigma(Sigma)
        return self._psi(Sigma, torch.log(Sigma))

    def tau(self, Sigma: torch.Tensor) -> torch.Tensor:
        """Kirchhoff stress in diagonal space tau_i = d psi / d eps_i at Sigma_c, Pa, shape (B, d)."""
        Sigma = clamp_sigma(Sigma)
        return self._tau(Sigma, torch.log(Sigma))

    def dtau_deps(self, Sigma: torch.Tensor) -> torch.Tensor:
        """d tau_i / d eps_j at Sigma_c, shape (B, d, d)."""
        Sigma = clamp_sigma(Sigma)
        return self._dtau_deps(Sigma, torch.log(Sigma))

    # --- public, F space ------------------------------------------------------------------------
    def psi_F(self, F: torch.Tensor) -> torch.Tensor:
        """psi(Sigma_c(F)), shape (B,)."""
        _, Sigma, _ = polar_svd(F)
        return self.psi(Sigma)

    def P(self, F: torch.Tensor) -> torch.Tensor:
        """First Piola stress P = U diag(tau_i / Sigma_c_i) V^T, shape (B, d, d)."""
        U, Sigma, V = polar_svd(F)
        Sigma = clamp_sigma(Sigma)
        return compose(U, self.tau(Sigma) / Sigma, V)

    def dPdF(self, F: torch.Tensor) -> torch.Tensor:
        """dP/dF, shape (B, d*d, d*d), entry (i*d+j, k*d+l) = dP_ij / dF_kl (row-major vec)."""
        U, Sigma, V = polar_svd(F)
        return self.dPdF_from_svd(U, clamp_sigma(Sigma), V)

    def dPdF_from_svd(self, U: torch.Tensor, Sigma: torch.Tensor, V: torch.Tensor) -> torch.Tensor:
        """dP/dF from a polar SVD with clamped Sigma (see the module docstring for the blocks)."""
        B, d = Sigma.shape
        eps = torch.log(Sigma)
        t = self._tau(Sigma, eps)
        H_eps = self._dtau_deps(Sigma, eps)
        # d^2 psi / d Sigma_i d Sigma_j = (d tau_i/d eps_j - delta_ij tau_i) / (Sigma_i Sigma_j)
        H_sigma = (H_eps - torch.diag_embed(t)) / (Sigma[:, :, None] * Sigma[:, None, :])
        A = Sigma.new_zeros(B, d * d, d * d)
        diag = torch.arange(d) * (d + 1)
        A[:, diag[:, None], diag[None, :]] = H_sigma
        for i in range(d):
            for j in range(i + 1, d):
                Si, Sj, ti, tj = Sigma[:, i], Sigma[:, j], t[:, i], t[:, j]
                Q = self._tau_difference_quotient(Sigma, eps, i, j)
                # D = (P_i - P_j)/(S_i - S_j) = (Q (S_i + S_j)/2 - (t_i + t_j)/2) / (S_i S_j)
                D = (0.5 * Q * (Si + Sj) - 0.5 * (ti + tj)) / (Si * Sj)
                E = (ti / Si + tj / Sj) / (Si + Sj)
                a, b = 0.5 * (D + E), 0.5 * (D - E)
                ij, ji = i * d + j, j * d + i
                A[:, ij, ij] = a
                A[:, ji, ji] = a
                A[:, ij, ji] = b
                A[:, ji, ij] = b
        # Back to F space: column (k*d+l) of W is vec(u_k v_l^T), W[(ij), (kl)] = U_ik V_jl.
        W = torch.einsum("bik,bjl->bijkl", U, V).reshape(B, d * d, d * d)
        return W @ A @ W.transpose(-1, -2)


class StVKHencky(ElasticityModel):
    """psi = mu ||eps||^2 + lambda/2 tr(eps)^2; tau = 2 mu eps + lambda tr(eps) 1 (paper eq. 14)."""

    name = "stvk_hencky"

    def _psi(self, Sigma, eps):
        tr = eps.sum(-1)
        return self.mu * (eps * eps).sum(-1) + 0.5 * self.lam * tr * tr

    def _tau(self, Sigma, eps):
        return 2.0 * self.mu * eps + self.lam * eps.sum(-1, keepdim=True)

    def _dtau_deps(self, Sigma, eps):
        d = Sigma.shape[-1]
        eye = torch.eye(d, dtype=Sigma.dtype, device=Sigma.device)
        return (2.0 * self.mu * eye + self.lam * torch.ones_like(eye)).expand(Sigma.shape[0], d, d)

    def _tau_difference_quotient(self, Sigma, eps, i, j):
        # 2 mu (eps_i - eps_j) / (Sigma_i - Sigma_j)
        return 2.0 * self.mu * _log_difference_quotient(Sigma[:, i], Sigma[:, j])


class NeoHookeanSnow(ElasticityModel):
    """psi = mu/2 (J^{-2/d} tr(b) - d) + K/4 (J^2 - 1) - K/2 log J;
    tau = mu J^{-2/d} dev(b) + K/2 (J^2 - 1) 1 (paper eq. 17), b = Sigma^2, J = prod(Sigma)."""

    name = "neo_hookean_snow"

    def _psi(self, Sigma, eps):
        d = Sigma.shape[-1]
        log_J = eps.sum(-1)
        # J^{-2/d} tr(b) - d = sum_i (exp(2 dev(eps)_i) - 1); K/4 (J^2 - 1) - K/2 log J via expm1.
        iso = torch.expm1(2.0 * (eps - log_J[:, None] / d)).sum(-1)
        return 0.5 * self.mu * iso + 0.25 * self.K * (torch.expm1(2.0 * log_J) - 2.0 * log_J)

    def _tau(self, Sigma, eps):
        d = Sigma.shape[-1]
        log_J = eps.sum(-1, keepdim=True)
        b = Sigma * Sigma
        dev_b = b - b.sum(-1, keepdim=True) / d
        return self.mu * torch.exp(-2.0 / d * log_J) * dev_b + 0.5 * self.K * torch.expm1(2.0 * log_J)

    def _dtau_deps(self, Sigma, eps):
        # d/d eps_j of mu J^{-2/d}(b_i - tr(b)/d) + K/2 (J^2 - 1), with dJ/d eps_j = J, db_i/d eps_j = 2 b_i delta_ij:
        # mu J^{-2/d} (-2/d dev(b)_i + 2 b_i delta_ij - 2/d b_j) + K J^2.
        d = Sigma.shape[-1]
        log_J = eps.sum(-1)
        b = Sigma * Sigma
        dev_b = b - b.sum(-1, keepdim=True) / d
        iso = (self.mu * torch.exp(-2.0 / d * log_J))[:, None, None]
        H = -2.0 / d * dev_b[:, :, None] + torch.diag_embed(2.0 * b) - 2.0 / d * b[:, None, :]
        return iso * H + (self.K * torch.exp(2.0 * log_J))[:, None, None]

    def _tau_difference_quotient(self, Sigma, eps, i, j):
        # mu J^{-2/d} (b_i - b_j) / (Sigma_i - Sigma_j) = mu J^{-2/d} (Sigma_i + Sigma_j)
        d = Sigma.shape[-1]
        return self.mu * torch.exp(-2.0 / d * eps.sum(-1)) * (Sigma[:, i] + Sigma[:, j])


class NeoHookeanMetal(ElasticityModel):
    """psi = mu/2 (tr(b) - d) - mu log J + lambda/2 (log J)^2; tau = mu (b - 1) + lambda log(J) 1 (paper eq. 24)."""

    name = "neo_hookean_metal"

    def _psi(self, Sigma, eps):
        log_J = eps.sum(-1)
        return 0.5 * self.mu * torch.expm1(2.0 * eps).sum(-1) - self.mu * log_J + 0.5 * self.lam * log_J * log_J

    def _tau(self, Sigma, eps):
        return self.mu * torch.expm1(2.0 * eps) + self.lam * eps.sum(-1, keepdim=True)

    def _dtau_deps(self, Sigma, eps):
        d = Sigma.shape[-1]
        b = Sigma * Sigma
        return torch.diag_embed(2.0 * self.mu * b) + self.lam * Sigma.new_ones(Sigma.shape[0], d, d)

    def _tau_difference_quotient(self, Sigma, eps, i, j):
        # mu (b_i - b_j) / (Sigma_i - Sigma_j) = mu (Sigma_i + Sigma_j)
        return self.mu * (Sigma[:, i] + Sigma[:, j])


ELASTICITY_MODELS = {cls.name: cls for cls in (StVKHencky, NeoHookeanSnow, NeoHookeanMetal)}


def make_elasticity(model: str, params: ElasticParams) -> ElasticityModel:
    """The elasticity model called `model` ("stvk_hencky", "neo_hookean_snow", "neo_hookean_metal")."""
    if model not in ELASTICITY_MODELS:
        raise ValueError(
            f"elasticity.model = {model!r}: unknown elasticity model "
            f"(expected one of {', '.join(ELASTICITY_MODELS)})"
        )
    return ELASTICITY_MODELS[model](params)
