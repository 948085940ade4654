"""The training target: the elastoplastic stress Ptilde(F, h) = tau(Z(F, h)) F^{-T} (paper eqs. 5-6),
from the material library, with the analytic return mapping Z or a learned one (paper sec. 4.3).

Nondimensional training (E = 1). Every elasticity model's Kirchhoff stress is linear in E (mu,
lambda and K are all proportional to E, with nu fixed), and every return mapping is E-invariant:
Drucker-Prager's dgamma uses only (d lambda + 2 mu) / (2 mu); Cam-Clay's p, p0 = K sinh(...) and s
all scale with E, so its ellipse y / E^2 (and Z) does not change; von Mises uses h = tau_Y / (2 mu)
and y / E^2. Hence Ptilde(F, h; E) = E Ptilde(F, h; E = 1): the networks learn the E = 1 stress and
the simulator multiplies Psi, grad Psi and Hess Psi by the scene's E.
"""

from __future__ import annotations

import copy
from typing import Callable

import torch

from ..materials import Material, clamp_sigma, compose, polar_svd
from .parameters import runs

#: Young's modulus of every training material (dimensionless stress).
TRAINING_E = 1.0


def with_young_modulus(material: Material | dict, dim: int | None = None, E: float = TRAINING_E) -> Material:
    """A copy of `material` (a Material, or a description dict with `dim`) with elasticity.E = E."""
    if isinstance(material, Material):
        desc, dim = material.to_dict(), material.dim
    else:
        desc = copy.deepcopy(material)
    desc["elasticity"] = dict(desc["elasticity"], E=float(E))
    return Material.from_dict(desc, dim)


def nondimensional_material(name: str, dim: int) -> Material:
    """The preset `name` ("sand", "snow", "metal", "metal_nh") with E = 1."""
    return with_young_modulus(Material.preset(name, dim))


#: Z(Sigma_c, h) -> Z_Sigma, both (B, d): the projection in diagonal space.
ReturnMap = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


class ElastoplasticStress:
    """Ptilde(F, h) = U diag(tau_i(Z) / Sigma_c_i) V^T, with Z the material's own return mapping or
    `return_map` (e.g. a learned one). Batched (B, d, d); float32 or float64.

    With `parameters` (a parametric model's family, parameters.ParameterSpace), the methods take the
    rows' material parameters p (B, K) too, and each run of equal rows uses the family's material at
    its p (the analytic return mapping only)."""

    def __init__(self, material: Material, return_map: ReturnMap | None = None, parameters=None):
        if parameters is not None and return_map is not None:
            raise ValueError("a parametric model uses the analytic return mapping (no learned one)")
        self.material = material
        self.return_map = return_map
        self.parameters = parameters if parameters is not None and len(parameters) else None

    def _per_material(self, fn, rows: int, p: torch.Tensor | None, *args) -> torch.Tensor:
        """fn(stress, *args) for a single material; per run of equal parameters for a parametric one."""
        if self.parameters is None:
            return fn(self, *args)
        if p is None or p.shape != (rows, len(self.parameters)):
            raise ValueError(f"a parametric stress needs the parameters p of the {rows} rows, (B, {len(self.parameters)})")
        parts = []
        for start, end in runs(p):
            one = ElastoplasticStress(self.parameters.material_at(p[start].tolist()))
            parts.append(fn(one, *(a[start:end] for a in args)))
        return torch.cat(parts)

    def project(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """Z(Sigma_c, h), (B, d)."""
        if self.return_map is None:
            return self.material.return_map(Sigma, h)[0]
        return self.return_map(clamp_sigma(Sigma), h)

    def from_factors(self, U: torch.Tensor, Sigma: torch.Tensor, V: torch.Tensor, h: torch.Tensor,
                     p: torch.Tensor | None = None) -> torch.Tensor:
        """Ptilde of F = U diag(Sigma) V^T given its factors (U, V rotations; Sigma > 0 in any order,
        every model being a symmetric function of Sigma): no SVD needed."""
        if self.parameters is not None:
            return self._per_material(lambda s, *a: s.from_factors(*a), U.shape[0], p, U, Sigma, V, h)
        Sigma_c = clamp_sigma(Sigma)
        Z = self.project(Sigma_c, h)
        return compose(U, self.material.tau(Z) / Sigma_c, V)

    def __call__(self, F: torch.Tensor, h: torch.Tensor, p: torch.Tensor | None = None) -> torch.Tensor:
        """Ptilde(F, h) through the library's polar SVD."""
        if self.parameters is not None:
            return self._per_material(lambda s, *a: s(*a), F.shape[0], p, F, h)
        if self.return_map is None:
            return self.material.elastoplastic_stress(F, h)
        U, Sigma, V = polar_svd(F)
        return self.from_factors(U, Sigma, V, h)
