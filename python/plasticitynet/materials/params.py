"""Material parameters, grouped per model and validated on construction (material spec §Validation).

Each error is a ValueError naming the description field ("elasticity.E", "plasticity.xi", ...)
and what was expected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real


def _real(field: str, value) -> float:
    """value as a float; ValueError naming `field` if it is not a finite-or-not real number."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{field} = {value!r}: expected a number, got {type(value).__name__}")
    return float(value)


def _require(field: str, value: float, ok: bool, expected: str) -> None:
    if not math.isfinite(value):
        raise ValueError(f"{field} = {value!r}: must be finite ({expected})")
    if not ok:
        raise ValueError(f"{field} = {value!r}: must be {expected}")


def friction_alpha(friction_angle_deg: float) -> float:
    """alpha = sqrt(2/3) * 2 sin(phi) / (3 - sin(phi)) (Klar et al. 2016; docs/physics.md)."""
    s = math.sin(friction_angle_deg * math.pi / 180.0)
    return math.sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s)


@dataclass(frozen=True)
class ElasticParams:
    """Young's modulus E (Pa) and Poisson ratio nu, with the derived moduli."""

    E: float
    nu: float

    def __post_init__(self):
        E = _real("elasticity.E", self.E)
        nu = _real("elasticity.nu", self.nu)
        _require("elasticity.E", E, E > 0.0, "> 0 (Young's modulus, Pa)")
        _require("elasticity.nu", nu, -1.0 < nu < 0.5, "in (-1, 0.5) (Poisson ratio)")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)

    @property
    def mu(self) -> float:
        """Shear modulus mu = E / (2 (1 + nu)), Pa."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lam(self) -> float:
        """First Lame parameter lambda = E nu / ((1 + nu)(1 - 2 nu)), Pa."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def K(self) -> float:
        """Bulk modulus K = E / (3 (1 - 2 nu)), Pa; the paper uses this K in 2D and 3D alike."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))


@dataclass(frozen=True)
class DruckerPragerParams:
    """Drucker-Prager sand (Klar et al. 2016). No hardening."""

    friction_angle_deg: float = 30.0  # phi_f, degrees, in (0, 90)

    def __post_init__(self):
        phi = _real("plasticity.friction_angle_deg", self.friction_angle_deg)
        _require("plasticity.friction_angle_deg", phi, 0.0 < phi < 90.0, "in (0, 90) degrees")
        object.__setattr__(self, "friction_angle_deg", phi)

    @property
    def alpha(self) -> float:
        """Cone slope alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi))."""
        return friction_alpha(self.friction_angle_deg)


CAM_CLAY_VARIANTS = ("exact", "paper")


@dataclass(frozen=True)
class CamClayParams:
    """Non-associative Cam-Clay snow (Wolper et al. 2019, CD-MPM).

    variant "exact" projects at fixed J onto the ellipse (idempotent); "paper" is the
    paper's eq. 20 (keeps tr(b), lands on the surface only to first order).
    """

    friction_angle_deg: float = 45.0  # degrees, in (0, 90); sets the ellipse aspect M
    xi: float = 0.5  # hardening factor in p0 = K sinh(xi max(-a, 0)), >= 0
    beta: float = 0.3  # cohesion: tension tip at p = -beta p0, >= 0
    variant: str = "exact"

    def __post_init__(self):
        phi = _real("plasticity.friction_angle_deg", self.friction_angle_deg)
        xi = _real("plasticity.xi", self.xi)
        beta = _real("plasticity.beta", self.beta)
        _require("plasticity.friction_angle_deg", phi, 0.0 < phi < 90.0, "in (0, 90) degrees")
        _require("plasticity.xi", xi, xi >= 0.0, ">= 0 (hardening factor)")
        _require("plasticity.beta", beta, beta >= 0.0, ">= 0 (cohesion ratio)")
        if self.variant not in CAM_CLAY_VARIANTS:
            raise ValueError(
                f"plasticity.variant = {self.variant!r}: unknown Cam-Clay variant "
                f"(expected one of {', '.join(CAM_CLAY_VARIANTS)})"
            )
        object.__setattr__(self, "friction_angle_deg", phi)
        object.__setattr__(self, "xi", xi)
        object.__setattr__(self, "beta", beta)

    def M(self, dim: int) -> float:
        """Ellipse aspect M = sqrt(2/3) 2 sin(phi)/(3 - sin(phi)) * d / sqrt(2/(6-d))."""
        return friction_alpha(self.friction_angle_deg) * dim / math.sqrt(2.0 / (6.0 - dim))


@dataclass(frozen=True)
class VonMisesParams:
    """von Mises metal; state h = tau_Y / (2 mu) >= 0, updated h += hardening_coefficient dgamma."""

    hardening_coefficient: float = 0.1  # xi, dimensionless, >= 0 (0: perfect plasticity)

    def __post_init__(self):
        xi = _real("plasticity.hardening_coefficient", self.hardening_coefficient)
        _require("plasticity.hardening_coefficient", xi, xi >= 0.0, ">= 0")
        object.__setattr__(self, "hardening_coefficient", xi)
