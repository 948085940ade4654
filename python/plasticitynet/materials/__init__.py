"""Constitutive models of PlasticityNet: polar SVD, elasticity, plastic return mappings and the
`Material` that combines them (docs/physics.md; the material spec fixes every formula)."""

from .branches import (
    APEX,
    BRANCH_NAMES,
    COMPRESSION_TIP,
    CONE,
    ELASTIC,
    ELLIPSE,
    TENSION_TIP,
    YIELD,
)
from .cam_clay import CamClay, unimodular_shift
from .drucker_prager import DruckerPrager
from .elasticity import (
    ELASTICITY_MODELS,
    ElasticityModel,
    NeoHookeanMetal,
    NeoHookeanSnow,
    StVKHencky,
    make_elasticity,
)
from .material import PLASTICITY_MODELS, PRESETS, Material
from .params import CamClayParams, DruckerPragerParams, ElasticParams, VonMisesParams
from .plasticity import NoPlasticity, PlasticityModel
from .svd import SIGMA_MIN, clamp_sigma, compose, polar_svd
from .von_mises import VonMises

__all__ = [
    "APEX", "BRANCH_NAMES", "COMPRESSION_TIP", "CONE", "ELASTIC", "ELLIPSE", "TENSION_TIP", "YIELD",
    "CamClay", "unimodular_shift", "DruckerPrager",
    "ELASTICITY_MODELS", "ElasticityModel", "NeoHookeanMetal", "NeoHookeanSnow", "StVKHencky", "make_elasticity",
    "PLASTICITY_MODELS", "PRESETS", "Material",
    "CamClayParams", "DruckerPragerParams", "ElasticParams", "VonMisesParams",
    "NoPlasticity", "PlasticityModel",
    "SIGMA_MIN", "clamp_sigma", "compose", "polar_svd",
    "VonMises",
]
