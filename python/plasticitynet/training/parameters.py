"""Material parameters as network inputs: parametric energies (the paper's future work 5; docs/physics.md).

A dedicated model is trained for one material and refused for any other. A parametric model is trained for
a family: a reference material (a preset at E = 1) whose listed fields vary over ranges,

    sand:   plasticity.friction_angle_deg in [20, 45], elasticity.nu in [0.2, 0.45]
    snow:   plasticity.friction_angle_deg, plasticity.xi, plasticity.beta, elasticity.nu
    metal:  plasticity.hardening_coefficient, elasticity.nu

(E stays a scale, as for every model: the stress is linear in E for fixed nu; targets.py). The network
takes each parameter p_k after the hardening input, normalised to the unit interval's double,

    u_k = 2 (p_k - min_k) / (max_k - min_k) - 1   in [-1, 1],

so the file's forward(x) takes x = [vec F, vec F0, (h), u_1 .. u_K]. Within a solve u is a constant of
each object, like Sigma0 and h. The model file records the ranges (metadata "parameters": a list of
{"field", "min", "max"} in input order); a scene whose value of a field lies outside its range is
refused with a message naming the field and the range.

Training draws p uniformly in the box, in groups of GROUP_SIZE consecutive samples sharing one p (at most
MAX_GROUPS groups per part of a batch; the targets are the material library's, built per group;
sampling.sample_batch).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import torch

from ..materials import Material

#: Consecutive samples of a batch that share one parameter vector (one material evaluation per group), and
#: the most groups per part of a batch (larger parts have larger groups; sampling.sample_batch).
GROUP_SIZE = 32
MAX_GROUPS = 64


@dataclass(frozen=True)
class ParameterRange:
    """One network input: the material description's `field` ("plasticity.xi", ...) over [lo, hi]."""

    field: str
    lo: float
    hi: float

    def __post_init__(self):
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo < self.hi):
            raise ValueError(f"parameter {self.field}: range [{self.lo}, {self.hi}] must be finite with min < max")

    def normalise(self, value):
        return 2.0 * (value - self.lo) / (self.hi - self.lo) - 1.0

    def to_dict(self) -> dict:
        return {"field": self.field, "min": self.lo, "max": self.hi}


#: The parameters of each family and their ranges (issue 36): sand after Klar et al. 2016's friction angles
#: and common Poisson ratios, snow after Stomakhin et al. 2013 / Wolper et al. 2019's ranges, metal around
#: the preset's linear hardening.
FAMILIES: dict[str, tuple[ParameterRange, ...]] = {
    "sand": (ParameterRange("plasticity.friction_angle_deg", 20.0, 45.0), ParameterRange("elasticity.nu", 0.2, 0.45)),
    "snow": (
        ParameterRange("plasticity.friction_angle_deg", 30.0, 60.0),
        ParameterRange("plasticity.xi", 0.2, 1.0),
        ParameterRange("plasticity.beta", 0.1, 0.5),
        ParameterRange("elasticity.nu", 0.15, 0.35),
    ),
    "metal": (ParameterRange("plasticity.hardening_coefficient", 0.0, 0.3), ParameterRange("elasticity.nu", 0.25, 0.45)),
}


def field_value(description: dict, field: str) -> float:
    """The value of `field` ("section.key") in a material description (ValueError if absent)."""
    section, _, key = field.partition(".")
    try:
        return float(description[section][key])
    except (KeyError, TypeError):
        raise ValueError(f"material.{field}: missing (a parameter of this model)") from None


class ParameterSpace:
    """A family: the reference material (E = 1) and the ranges of its free fields, in input order."""

    def __init__(self, material: Material, ranges: tuple[ParameterRange, ...] | list[ParameterRange]):
        self.material = material
        self.ranges = tuple(ranges)
        reference = material.to_dict()
        seen = set()
        for r in self.ranges:
            if r.field in seen:
                raise ValueError(f"parameter {r.field}: listed twice")
            seen.add(r.field)
            field_value(reference, r.field)  # the field exists for this material's models
        self.material_at([0.5 * (r.lo + r.hi) for r in self.ranges])  # the box is valid for the library

    @classmethod
    def family(cls, name: str, material: Material) -> "ParameterSpace":
        if name not in FAMILIES:
            raise ValueError(f"no parametric family {name!r} (expected one of {', '.join(FAMILIES)})")
        return cls(material, FAMILIES[name])

    @classmethod
    def from_metadata(cls, entries, material: Material, where: str) -> "ParameterSpace":
        """From a model file's "parameters" list; ValueError naming `where` on a malformed entry."""
        if not isinstance(entries, list):
            raise ValueError(f"{where}: parameters: expected a list, got {type(entries).__name__}")
        ranges = []
        for k, e in enumerate(entries):
            if not (isinstance(e, dict) and isinstance(e.get("field"), str)
                    and all(isinstance(e.get(b), (int, float)) and not isinstance(e.get(b), bool) for b in ("min", "max"))):
                raise ValueError(f"{where}: parameters[{k}]: expected {{\"field\": str, \"min\": number, \"max\": number}}")
            try:
                ranges.append(ParameterRange(e["field"], float(e["min"]), float(e["max"])))
            except ValueError as err:
                raise ValueError(f"{where}: parameters[{k}]: {err}") from None
        try:
            return cls(material, ranges)
        except ValueError as err:
            raise ValueError(f"{where}: parameters: {err}") from None

    def __len__(self) -> int:
        return len(self.ranges)

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(r.field for r in self.ranges)

    def to_metadata(self) -> list[dict]:
        return [r.to_dict() for r in self.ranges]

    def reference_values(self) -> list[float]:
        """The reference material's values (the dedicated model's point)."""
        reference = self.material.to_dict()
        return [field_value(reference, r.field) for r in self.ranges]

    def description_at(self, values) -> dict:
        """The reference description with the fields set to `values` (physical units)."""
        desc = copy.deepcopy(self.material.to_dict())
        for r, v in zip(self.ranges, values):
            section, _, key = r.field.partition(".")
            desc[section][key] = float(v)
        return desc

    def material_at(self, values) -> Material:
        return Material.from_dict(self.description_at(values), self.material.dim)

    def values_of(self, material: Material | dict, where: str) -> list[float]:
        """The parameter values of a material (a Material or its description), checked against this family:
        each in its range, and every other constitutive field (elasticity and plasticity, E aside) equal to
        the reference's. ValueError naming `where` and the field, e.g. "<where>: material.elasticity.nu =
        0.48 is outside the range [0.2, 0.45] this parametric model was trained for"."""
        if not isinstance(material, Material):
            material = Material.from_dict(material, self.material.dim)
        elif material.dim != self.material.dim:
            raise ValueError(f"{where}: a {material.dim}D material for a {self.material.dim}D model")
        description = material.to_dict()
        values = []
        for r in self.ranges:
            v = field_value(description, r.field)
            if not r.lo <= v <= r.hi:
                raise ValueError(f"{where}: material.{r.field} = {v:g} is outside the range [{r.lo:g}, {r.hi:g}] "
                                 "this parametric model was trained for")
            values.append(v)
        reference = self.description_at(values)
        for section in ("elasticity", "plasticity"):
            for key, expected in reference[section].items():
                if key == "E" or f"{section}.{key}" in self.fields:
                    continue
                given = description[section].get(key)
                if given != expected:
                    raise ValueError(f"{where}: material.{section}.{key} = {given!r}, but this parametric model's "
                                     f"family has {expected!r} (only {', '.join(self.fields)} vary)")
        return values

    def inputs(self, p: torch.Tensor) -> torch.Tensor:
        """The network's inputs u (B, K) for physical values p (B, K)."""
        lo, hi = bounds(self.ranges, p.dtype, p.device)
        return 2.0 * (p - lo) / (hi - lo) - 1.0


def bounds(ranges, dtype=torch.float64, device=None) -> tuple[torch.Tensor, torch.Tensor]:
    """(min, max) of each range, (K,) tensors each."""
    return (torch.tensor([r.lo for r in ranges], dtype=dtype, device=device),
            torch.tensor([r.hi for r in ranges], dtype=dtype, device=device))


def runs(p: torch.Tensor):
    """(start, end) of the maximal runs of equal consecutive rows of p (B, K): the groups of a batch."""
    B = p.shape[0]
    if B == 0:
        return []
    change = (p[1:] != p[:-1]).any(dim=1).nonzero().flatten().tolist() if B > 1 else []
    starts = [0] + [c + 1 for c in change]
    ends = [c + 1 for c in change] + [B]
    return list(zip(starts, ends))
