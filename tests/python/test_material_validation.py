"""Bad input is a ValueError naming the field and the problem; NaN is never propagated silently."""

import copy
import math

import pytest
import torch

from plasticitynet.materials import (
    PRESETS,
    CamClayParams,
    DruckerPragerParams,
    ElasticParams,
    Material,
    VonMisesParams,
)


def description(preset="snow", **changes):
    """A preset description with changes given as "section.field" (or "field") = value; None deletes."""
    desc = copy.deepcopy(PRESETS[preset])
    for path, value in changes.items():
        *parents, key = path.split("__")
        target = desc
        for parent in parents:
            target = target[parent]
        if value is None:
            del target[key]
        else:
            target[key] = value
    return desc


BAD_DESCRIPTIONS = [
    # (preset, changes, regex the message must match)
    ("sand", {"elasticity__E": float("nan")}, r"elasticity\.E = nan: must be finite"),
    ("sand", {"elasticity__E": float("inf")}, r"elasticity\.E = inf: must be finite"),
    ("sand", {"elasticity__E": -1.0}, r"elasticity\.E = -1\.0: must be > 0"),
    ("sand", {"elasticity__E": 0.0}, r"elasticity\.E = 0\.0: must be > 0"),
    ("sand", {"elasticity__E": "1e5"}, r"elasticity\.E = '1e5': expected a number"),
    ("sand", {"elasticity__nu": 0.5}, r"elasticity\.nu = 0\.5: must be in \(-1, 0\.5\)"),
    ("sand", {"elasticity__nu": 0.7}, r"elasticity\.nu = 0\.7: must be in \(-1, 0\.5\)"),
    ("sand", {"elasticity__nu": -1.0}, r"elasticity\.nu = -1\.0: must be in \(-1, 0\.5\)"),
    ("sand", {"elasticity__nu": float("nan")}, r"elasticity\.nu = nan: must be finite"),
    ("sand", {"elasticity__nu": None}, r"elasticity\.nu: missing"),
    ("sand", {"elasticity": None}, r"material\.elasticity: missing"),
    ("sand", {"elasticity__model": "hooke"}, r"elasticity\.model = 'hooke': unknown elasticity model"),
    ("sand", {"plasticity__model": "mohr_coulomb"}, r"plasticity\.model = 'mohr_coulomb': unknown plasticity model"),
    ("sand", {"plasticity__friction_angle_deg": 0.0}, r"plasticity\.friction_angle_deg = 0\.0: must be in \(0, 90\)"),
    ("sand", {"plasticity__friction_angle_deg": 90.0}, r"plasticity\.friction_angle_deg = 90\.0: must be in \(0, 90\)"),
    ("sand", {"plasticity__friction_angle_deg": float("nan")}, r"plasticity\.friction_angle_deg = nan: must be finite"),
    ("sand", {"elasticity__model": "neo_hookean_snow"},
     r"'drucker_prager' requires elasticity\.model = 'stvk_hencky', got 'neo_hookean_snow'"),
    ("snow", {"elasticity__model": "stvk_hencky"},
     r"'cam_clay' requires elasticity\.model = 'neo_hookean_snow', got 'stvk_hencky'"),
    ("snow", {"elasticity__model": "neo_hookean_metal"}, r"'cam_clay' requires elasticity\.model = 'neo_hookean_snow'"),
    ("snow", {"plasticity__xi": -0.1}, r"plasticity\.xi = -0\.1: must be >= 0"),
    ("snow", {"plasticity__beta": -0.1}, r"plasticity\.beta = -0\.1: must be >= 0"),
    ("snow", {"plasticity__beta": float("nan")}, r"plasticity\.beta = nan: must be finite"),
    ("snow", {"plasticity__variant": "ziran"}, r"plasticity\.variant = 'ziran': unknown Cam-Clay variant"),
    ("snow", {"plasticity__hardening_coefficient": 0.1}, r"plasticity\.hardening_coefficient: unknown field"),
    ("metal", {"plasticity__hardening_coefficient": -0.1}, r"plasticity\.hardening_coefficient = -0\.1: must be >= 0"),
    ("metal", {"plasticity__hardening_coefficient": float("inf")}, r"plasticity\.hardening_coefficient = inf"),
    ("metal", {"initial_hardening": -0.01}, r"initial_hardening = -0\.01: must be >= 0 for von_mises"),
    ("metal", {"initial_hardening": float("nan")}, r"initial_hardening = nan: must be a finite number"),
    ("metal", {"density": -5.0}, r"density = -5\.0: must be finite and > 0"),
    ("metal", {"colour": "grey"}, r"material\.colour: unknown field"),
    ("metal", {"elasticity__G": 1.0}, r"elasticity\.G: unknown field"),
    ("metal", {"plasticity": "von_mises"}, r"plasticity: expected an object"),
]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("preset,changes,message", BAD_DESCRIPTIONS)
def test_bad_description(dim, preset, changes, message):
    with pytest.raises(ValueError, match=message) as info:
        Material.from_dict(description(preset, **changes), dim)
    assert f"material '{preset}'" in str(info.value) or "material." in str(info.value)


@pytest.mark.parametrize("dim", [1, 4, 2.5, True])
def test_bad_dim(dim):
    with pytest.raises(ValueError, match=r"dim = .*: expected 2 or 3"):
        Material.preset("sand", dim)


def test_bad_preset_and_params():
    with pytest.raises(ValueError, match=r"preset = 'gravel': unknown material preset"):
        Material.preset("gravel", 2)
    with pytest.raises(ValueError, match=r"elasticity\.nu"):
        ElasticParams(E=1.0, nu=0.5)
    with pytest.raises(ValueError, match=r"friction_angle_deg"):
        DruckerPragerParams(friction_angle_deg=-3.0)
    with pytest.raises(ValueError, match=r"plasticity\.xi"):
        CamClayParams(xi=float("nan"))
    with pytest.raises(ValueError, match=r"hardening_coefficient"):
        VonMisesParams(hardening_coefficient=-1.0)
    with pytest.raises(ValueError, match=r"material\.elasticity: missing"):
        Material.from_dict({}, 2)
    with pytest.raises(ValueError, match=r"material: expected an object"):
        Material.from_dict([1, 2], 2)


@pytest.mark.parametrize("dim", [2, 3])
def test_bad_F(dim):
    m = Material.preset("metal_nh", dim)
    good = torch.eye(dim, dtype=torch.float64).expand(4, dim, dim).clone()
    for method in (m.elastoplastic_stress, m.elastic_part, m.evaluate, m.P, m.dPdF, m.psi):
        for bad_value in (float("nan"), float("inf"), -float("inf")):
            F = good.clone()
            F[2, 1, 0] = bad_value
            with pytest.raises(ValueError, match=r"F: non-finite value .* at index \(2, 1, 0\)"):
                method(F)
        other = 5 - dim
        for shape in ((4, dim, other), (4, other, other), (dim * dim,), (2, 4, dim, dim), (4, dim, dim + 1)):
            with pytest.raises(ValueError, match=rf"F: wrong shape \({', '.join(map(str, shape))}[,)]"):
                method(torch.ones(shape, dtype=torch.float64))
        with pytest.raises(ValueError, match=r"F: dtype torch\.int64 not supported"):
            method(torch.ones(dim, dim, dtype=torch.int64))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_bad_hardening(dim, preset):
    m = Material.preset(preset, dim)
    F = torch.eye(dim, dtype=torch.float64).expand(3, dim, dim)
    Sigma = torch.ones(3, dim, dtype=torch.float64)
    for h in (float("nan"), float("inf"), torch.tensor([0.1, float("nan"), 0.1], dtype=torch.float64)):
        with pytest.raises(ValueError, match=r"hardening: non-finite value"):
            m.elastoplastic_stress(F, h)
        with pytest.raises(ValueError, match=r"hardening: non-finite value"):
            m.return_map(Sigma, h)
    with pytest.raises(ValueError, match=r"hardening: wrong shape \(2,\)"):
        m.elastoplastic_stress(F, torch.zeros(2, dtype=torch.float64))
    if m.plasticity.name == "von_mises":
        for h in (-0.1, torch.tensor([0.1, 0.2, -1e-9], dtype=torch.float64)):
            with pytest.raises(ValueError, match=r"hardening: von Mises hardening .* must be >= 0, got -"):
                m.elastoplastic_stress(F, h)
            with pytest.raises(ValueError, match=r"hardening: von Mises hardening .* must be >= 0"):
                m.return_map(Sigma, h)


@pytest.mark.parametrize("dim", [2, 3])
def test_bad_Sigma(dim):
    m = Material.preset("snow", dim)
    with pytest.raises(ValueError, match=r"Sigma: non-finite value"):
        m.return_map(torch.tensor([[1.0] * (dim - 1) + [math.nan]], dtype=torch.float64))
    with pytest.raises(ValueError, match=r"Sigma: wrong shape"):
        m.return_map(torch.ones(2, dim + 1, dtype=torch.float64))
    with pytest.raises(ValueError, match=r"Sigma: non-finite value"):
        m.yield_function(torch.tensor([[math.inf] * dim], dtype=torch.float64))
