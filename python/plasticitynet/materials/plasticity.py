"""Common face of the plastic return mappings, and the "none" model (pure elasticity).

A return mapping acts in diagonal space: Z(Sigma, h) -> (Z_Sigma, h_new, branch) for Sigma of
shape (B, d) (clamped to Sigma_c = max(Sigma, SIGMA_MIN) first), hardening h of shape (B,),
branch an int64 tensor of codes from `branches`.
"""

from __future__ import annotations

import torch

from .branches import ELASTIC
from .elasticity import ElasticityModel
from .svd import clamp_sigma
from .validation import check_finite


class PlasticityModel:
    name = ""
    #: Branch codes this model can take.
    BRANCHES: tuple[int, ...] = (ELASTIC,)
    #: The parameter dataclass this model takes (None: no parameters).
    PARAMS: type | None = None
    #: The elasticity model the projection is exact for (None: any).
    REQUIRED_ELASTICITY: type | None = None

    def __init__(self, params, elasticity: ElasticityModel):
        if self.PARAMS is not None and not isinstance(params, self.PARAMS):
            raise ValueError(f"plasticity: expected {self.PARAMS.__name__}, got {type(params).__name__}")
        if self.REQUIRED_ELASTICITY is not None and not isinstance(elasticity, self.REQUIRED_ELASTICITY):
            raise ValueError(
                f"plasticity.model = {self.name!r} requires elasticity.model = {self.REQUIRED_ELASTICITY.name!r}, "
                f"got {elasticity.name!r}"
            )
        self.params = params
        self.elasticity = elasticity

    def _checked(self, Sigma: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        check_finite("Sigma", Sigma)
        check_finite("hardening", h)
        return clamp_sigma(Sigma), h

    def return_map(self, Sigma: torch.Tensor, h: torch.Tensor):
        raise NotImplementedError

    def yield_function(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def yield_scale(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """Size of the terms of yield_function (same units): |y| / scale is a relative distance to the surface."""
        raise NotImplementedError


class NoPlasticity(PlasticityModel):
    """Pure elasticity: Z = Sigma_c, always elastic, h unchanged."""

    name = "none"

    def __init__(self, params=None, elasticity: ElasticityModel | None = None):
        super().__init__(params, elasticity)

    def return_map(self, Sigma, h):
        Sigma, h = self._checked(Sigma, h)
        return Sigma, h.clone(), torch.full(Sigma.shape[:1], ELASTIC, dtype=torch.int64, device=Sigma.device)

    def yield_function(self, Sigma, h):
        """No yield surface: 0 everywhere (as the C++ library)."""
        return torch.zeros(Sigma.shape[:1], dtype=Sigma.dtype, device=Sigma.device)

    def yield_scale(self, Sigma, h):
        return torch.ones(Sigma.shape[:1], dtype=Sigma.dtype, device=Sigma.device)
