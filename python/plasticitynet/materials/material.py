"""A material = an elasticity model + a plastic return mapping + its hardening state, with the
elastoplastic stress Ptilde(F, h) = tau(Z(F, h)) F^{-T} = U diag(tau_i(Z) / Sigma_c_i) V^T
(paper eqs. 5-6; docs/physics.md), built from the JSON/dict material description of the spec.

All F-space methods accept one (d, d) matrix or a (B, d, d) batch, float32 or float64, and return
results of the same batching; the hardening argument is a scalar or a (B,) tensor (None: the
material's initial_hardening).
"""

from __future__ import annotations

import copy
import math
from numbers import Real

import torch

from .branches import BRANCH_NAMES
from .cam_clay import CamClay
from .drucker_prager import DruckerPrager
from .elasticity import ELASTICITY_MODELS, ElasticityModel, make_elasticity
from .params import CamClayParams, DruckerPragerParams, ElasticParams, VonMisesParams
from .plasticity import NoPlasticity, PlasticityModel
from .svd import clamp_sigma, compose, polar_svd
from .validation import as_batch_F, as_batch_hardening, as_batch_Sigma
from .von_mises import VonMises

__all__ = ["Material", "BRANCH_NAMES", "ALL_QUANTITIES", "PLASTICITY_MODELS", "PRESETS"]

#: plasticity model name -> (return-mapping class, parameter dataclass or None)
PLASTICITY_MODELS = {
    "none": (NoPlasticity, None),
    "drucker_prager": (DruckerPrager, DruckerPragerParams),
    "cam_clay": (CamClay, CamClayParams),
    "von_mises": (VonMises, VonMisesParams),
}

#: The materials of docs/physics.md (E in Pa, density in kg/m^3).
PRESETS = {
    "sand": {
        "name": "sand", "density": 2200.0, "initial_hardening": 0.0,
        "elasticity": {"model": "stvk_hencky", "E": 3.537e5, "nu": 0.3},
        "plasticity": {"model": "drucker_prager", "friction_angle_deg": 30.0},
    },
    "snow": {
        "name": "snow", "density": 400.0, "initial_hardening": -0.1,
        "elasticity": {"model": "neo_hookean_snow", "E": 1.4e5, "nu": 0.2},
        "plasticity": {"model": "cam_clay", "friction_angle_deg": 45.0, "xi": 0.5, "beta": 0.3, "variant": "exact"},
    },
    "metal": {
        "name": "metal", "density": 7800.0, "initial_hardening": 0.05,
        "elasticity": {"model": "stvk_hencky", "E": 1e7, "nu": 0.3},
        "plasticity": {"model": "von_mises", "hardening_coefficient": 0.1},
    },
    "metal_nh": {
        "name": "metal_nh", "density": 7800.0, "initial_hardening": 0.05,
        "elasticity": {"model": "neo_hookean_metal", "E": 1e7, "nu": 0.3},
        "plasticity": {"model": "von_mises", "hardening_coefficient": 0.1},
    },
}

#: Everything Material.evaluate computes (the "expect" object of a test-vector case).
ALL_QUANTITIES = ("Sigma", "Z_Sigma", "hardening_new", "branch", "F_elastic", "Ptilde", "psi", "tau", "P", "dPdF")

_TOP_FIELDS = ("name", "density", "initial_hardening", "elasticity", "plasticity")
_ELASTIC_FIELDS = ("model", "E", "nu")


def _fields(path: str, obj, allowed) -> dict:
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: expected an object (dict), got {type(obj).__name__}")
    for key in obj:
        if key not in allowed:
            raise ValueError(f"{path}.{key}: unknown field (expected one of {', '.join(allowed)})")
    return obj


def _required(path: str, obj: dict, key: str):
    if key not in obj:
        raise ValueError(f"{path}.{key}: missing")
    return obj[key]


def _model_name(path: str, value) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{path}: expected a string, got {type(value).__name__}")
    return value


class Material:
    """Elastoplastic material in d = 2 or 3 dimensions (see the module docstring)."""

    def __init__(
        self,
        dim: int,
        elasticity: ElasticityModel,
        plasticity: PlasticityModel,
        name: str = "custom",
        density: float = 1000.0,  # kg/m^3
        initial_hardening: float = 0.0,  # a (Cam-Clay) or h = tau_Y/(2 mu) (von Mises)
    ):
        if isinstance(dim, bool) or dim not in (2, 3):
            raise ValueError(f"dim = {dim!r}: expected 2 or 3")
        if not isinstance(density, Real) or isinstance(density, bool) or not math.isfinite(density) or density <= 0:
            raise ValueError(f"density = {density!r}: must be finite and > 0 (kg/m^3)")
        if (
            not isinstance(initial_hardening, Real)
            or isinstance(initial_hardening, bool)
            or not math.isfinite(initial_hardening)
        ):
            raise ValueError(f"initial_hardening = {initial_hardening!r}: must be a finite number")
        if isinstance(plasticity, VonMises) and initial_hardening < 0:
            raise ValueError(
                f"initial_hardening = {initial_hardening!r}: must be >= 0 for von_mises (h = tau_Y / (2 mu))"
            )
        self.dim = dim
        self.elasticity = elasticity
        self.plasticity = plasticity
        self.name = str(name)
        self.density = float(density)
        self.initial_hardening = float(initial_hardening)

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, description: dict, dim: int) -> "Material":
        """Material from the spec's description, e.g.
        {"name": "snow", "density": 400, "initial_hardening": -0.1,
         "elasticity": {"model": "neo_hookean_snow", "E": 1.4e5, "nu": 0.2},
         "plasticity": {"model": "cam_clay", "friction_angle_deg": 45, "xi": 0.5, "beta": 0.3, "variant": "exact"}}.
        name, density, initial_hardening and plasticity (default "none") are optional, as are the
        plasticity parameters (spec defaults). Raises ValueError naming the field and the problem."""
        desc = _fields("material", description, _TOP_FIELDS)
        name = desc.get("name", "custom")
        try:
            e = _fields("elasticity", _required("material", desc, "elasticity"), _ELASTIC_FIELDS)
            e_model = _model_name("elasticity.model", _required("elasticity", e, "model"))
            if e_model not in ELASTICITY_MODELS:
                raise ValueError(
                    f"elasticity.model = {e_model!r}: unknown elasticity model "
                    f"(expected one of {', '.join(ELASTICITY_MODELS)})"
                )
            elastic = ElasticParams(E=_required("elasticity", e, "E"), nu=_required("elasticity", e, "nu"))
            elasticity = make_elasticity(e_model, elastic)

            p = desc.get("plasticity", {"model": "none"})
            if not isinstance(p, dict):
                raise ValueError(f"plasticity: expected an object (dict), got {type(p).__name__}")
            p_model = _model_name("plasticity.model", _required("plasticity", p, "model"))
            if p_model not in PLASTICITY_MODELS:
                raise ValueError(
                    f"plasticity.model = {p_model!r}: unknown plasticity model "
                    f"(expected one of {', '.join(PLASTICITY_MODELS)})"
                )
            model_cls, params_cls = PLASTICITY_MODELS[p_model]
            if params_cls is None:
                _fields("plasticity", p, ("model",))
                plasticity = model_cls(None, elasticity)
            else:
                allowed = ("model",) + tuple(params_cls.__dataclass_fields__)
                _fields("plasticity", p, allowed)
                plasticity = model_cls(params_cls(**{k: v for k, v in p.items() if k != "model"}), elasticity)
            return cls(
                dim,
                elasticity,
                plasticity,
                name=name,
                density=desc.get("density", 1000.0),
                initial_hardening=desc.get("initial_hardening", 0.0),
            )
        except ValueError as err:
            raise ValueError(f"material {name!r}: {err}") from None

    @classmethod
    def preset(cls, name: str, dim: int) -> "Material":
        """One of the materials of docs/physics.md: "sand", "snow", "metal", "metal_nh"."""
        if name not in PRESETS:
            raise ValueError(f"preset = {name!r}: unknown material preset (expected one of {', '.join(PRESETS)})")
        return cls.from_dict(copy.deepcopy(PRESETS[name]), dim)

    def to_dict(self) -> dict:
        """The description (without dim), with every parameter spelled out."""
        params = self.elasticity.params
        plasticity = {"model": self.plasticity.name}
        if self.plasticity.params is not None:
            for key in self.plasticity.params.__dataclass_fields__:
                plasticity[key] = getattr(self.plasticity.params, key)
        return {
            "name": self.name,
            "density": self.density,
            "initial_hardening": self.initial_hardening,
            "elasticity": {"model": self.elasticity.name, "E": params.E, "nu": params.nu},
            "plasticity": plasticity,
        }

    def __repr__(self) -> str:
        return f"Material(dim={self.dim}, {self.to_dict()!r})"

    # --- moduli --------------------------------------------------------------------------------
    @property
    def mu(self) -> float:
        return self.elasticity.mu

    @property
    def lam(self) -> float:
        return self.elasticity.lam

    @property
    def K(self) -> float:
        return self.elasticity.K

    @property
    def branch_names(self) -> tuple[str, ...]:
        """Names of the branches the return mapping of this material can take."""
        return tuple(BRANCH_NAMES[code] for code in self.plasticity.BRANCHES)

    # --- diagonal space ------------------------------------------------------------------------
    def _hardening(self, h, batch: int, like: torch.Tensor) -> torch.Tensor:
        return as_batch_hardening(self.initial_hardening if h is None else h, batch, like)

    def return_map(self, Sigma, h=None):
        """Z(Sigma_c, h) -> (Z_Sigma, h_new, branch); Sigma (d,) or (B, d), branch int64 codes."""
        Sigma, single = as_batch_Sigma(Sigma, self.dim)
        Z, h_new, branch = self.plasticity.return_map(Sigma, self._hardening(h, Sigma.shape[0], Sigma))
        return (Z[0], h_new[0], branch[0]) if single else (Z, h_new, branch)

    def yield_function(self, Sigma, h=None) -> torch.Tensor:
        """The plasticity model's yield function at (Sigma_c, h) (<= 0 elastic); Pa for Drucker-Prager,
        Pa^2 for Cam-Clay and von Mises, 0 for "none". Differentiable in Sigma by autograd."""
        Sigma, single = as_batch_Sigma(Sigma, self.dim)
        y = self.plasticity.yield_function(Sigma, self._hardening(h, Sigma.shape[0], Sigma))
        return y[0] if single else y

    def yield_scale(self, Sigma, h=None) -> torch.Tensor:
        """Size of the terms of yield_function (same units): |y| / scale is a relative surface distance."""
        Sigma, single = as_batch_Sigma(Sigma, self.dim)
        s = self.plasticity.yield_scale(Sigma, self._hardening(h, Sigma.shape[0], Sigma))
        return s[0] if single else s

    def tau(self, Sigma) -> torch.Tensor:
        """Kirchhoff stress of the elasticity in diagonal space, tau(Sigma_c)."""
        Sigma, single = as_batch_Sigma(Sigma, self.dim)
        t = self.elasticity.tau(Sigma)
        return t[0] if single else t

    # --- F space -------------------------------------------------------------------------------
    def elastoplastic_stress(self, F, h=None) -> torch.Tensor:
        """Ptilde(F, h) = U diag(tau_i(Z) / Sigma_c_i) V^T with Z = Z(Sigma_c, h)."""
        return self.evaluate(F, h, quantities=("Ptilde",))["Ptilde"]

    def elastic_part(self, F, h=None) -> tuple[torch.Tensor, torch.Tensor]:
        """(F_elastic, h_new) with F_elastic = U diag(Z) V^T."""
        out = self.evaluate(F, h, quantities=("F_elastic",))
        return out["F_elastic"], out["hardening_new"]

    def psi(self, F) -> torch.Tensor:
        """Elastic energy density psi(Sigma_c(F)), J/m^3 (no plasticity)."""
        return self.evaluate(F, quantities=("psi",))["psi"]

    def P(self, F) -> torch.Tensor:
        """Elastic first Piola stress P(F) (no plasticity)."""
        return self.evaluate(F, quantities=("P",))["P"]

    def dPdF(self, F) -> torch.Tensor:
        """Elastic dP/dF, (d*d, d*d) or (B, d*d, d*d), entry (i*d+j, k*d+l) = dP_ij/dF_kl."""
        return self.evaluate(F, quantities=("dPdF",))["dPdF"]

    def evaluate(self, F, h=None, quantities=ALL_QUANTITIES) -> dict:
        """Every quantity of a test-vector case from one polar SVD: Sigma (raw polar singular values,
        last one negative for det F < 0), Z_Sigma, hardening_new, branch, F_elastic, Ptilde
        (elastoplastic), and psi, tau (= tau(Sigma_c)), P, dPdF of the elasticity alone."""
        F, single = as_batch_F(F, self.dim)
        U, Sigma, V = polar_svd(F)
        Sigma_c = clamp_sigma(Sigma)
        out = {"Sigma": Sigma}
        if {"Z_Sigma", "hardening_new", "branch", "F_elastic", "Ptilde"} & set(quantities):
            Z, h_new, branch = self.plasticity.return_map(Sigma_c, self._hardening(h, F.shape[0], F))
            out.update(Z_Sigma=Z, hardening_new=h_new, branch=branch)
            out["F_elastic"] = compose(U, Z, V)
            out["Ptilde"] = compose(U, self.elasticity.tau(Z) / Sigma_c, V)
        if "psi" in quantities:
            out["psi"] = self.elasticity.psi(Sigma_c)
        if "tau" in quantities:
            out["tau"] = self.elasticity.tau(Sigma_c)
        if "P" in quantities:
            out["P"] = compose(U, self.elasticity.tau(Sigma_c) / Sigma_c, V)
        if "dPdF" in quantities:
            out["dPdF"] = self.elasticity.dPdF_from_svd(U, Sigma_c, V)
        if single:
            out = {k: v[0] for k, v in out.items()}
        return out
