"""Material: presets and descriptions, F-space stresses (frame indifference, isotropy), float32."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from plasticitynet.materials import BRANCH_NAMES, PRESETS, SIGMA_MIN, Material, polar_svd
from plasticitynet.materials import material as material_module

ALL = ["sand", "snow", "snow_paper", "metal", "metal_perfect", "metal_nh", "metal_nh_perfect"]
VECTORS = Path(__file__).resolve().parents[1] / "data" / "material_vectors_python.json"


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_round_trip(dim, name):
    m = Material.preset(name, dim)
    assert m.dim == dim and m.name == name
    desc = m.to_dict()
    assert json.loads(json.dumps(desc)) == desc  # plain JSON
    assert Material.from_dict(desc, dim).to_dict() == desc
    # Spec values.
    spec = PRESETS[name]
    assert desc["elasticity"] == {k: float(v) if k != "model" else v for k, v in spec["elasticity"].items()}
    assert desc["density"] == spec["density"] and desc["initial_hardening"] == spec["initial_hardening"]
    for key, value in spec["plasticity"].items():
        assert desc["plasticity"][key] == value


def test_moduli_and_defaults():
    m = Material.preset("sand", 3)
    E, nu = 3.537e5, 0.3
    assert m.mu == pytest.approx(E / (2 * (1 + nu)), rel=1e-15)
    assert m.lam == pytest.approx(E * nu / ((1 + nu) * (1 - 2 * nu)), rel=1e-15)
    assert m.K == pytest.approx(E / (3 * (1 - 2 * nu)), rel=1e-15)
    # Optional fields take the spec defaults.
    m = Material.from_dict({"elasticity": {"model": "neo_hookean_snow", "E": 1e5, "nu": 0.2},
                            "plasticity": {"model": "cam_clay"}}, 2)
    assert m.to_dict()["plasticity"] == {"model": "cam_clay", "friction_angle_deg": 45.0, "xi": 0.5, "beta": 0.3,
                                         "variant": "exact"}
    m = Material.from_dict({"elasticity": {"model": "stvk_hencky", "E": 1e5, "nu": 0.2}}, 3)
    assert m.to_dict()["plasticity"] == {"model": "none"} and m.branch_names == ("elastic",)
    assert Material.preset("sand", 2).branch_names == ("elastic", "apex", "cone")
    assert BRANCH_NAMES == ("elastic", "apex", "cone", "compression_tip", "tension_tip", "ellipse", "yield")


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", ALL)
def test_elastoplastic_stress_frame_indifference(dim, name, material_factory, F_sampler, rotation_sampler):
    """Ptilde(Q F) = Q Ptilde(F) (objectivity) and Ptilde(F Q) = Ptilde(F) Q (isotropy); the same
    for F_elastic; h_new and the branch do not change."""
    m = material_factory(name, dim)
    F, h = F_sampler(m, 400, seed=21)
    g = torch.Generator().manual_seed(22)
    Q1, Q2 = rotation_sampler(400, dim, g), rotation_sampler(400, dim, g)
    base = m.evaluate(F, h)
    assert len(set(base["branch"].tolist())) == len(m.branch_names)  # every branch is exercised
    for F_rot, left, right in ((Q1 @ F, Q1, None), (F @ Q2, None, Q2), (Q1 @ F @ Q2, Q1, Q2)):
        out = m.evaluate(F_rot, h)
        assert torch.equal(out["branch"], base["branch"])
        torch.testing.assert_close(out["hardening_new"], base["hardening_new"], rtol=1e-12, atol=1e-14)
        for key in ("Ptilde", "F_elastic"):
            expected = base[key]
            if left is not None:
                expected = left @ expected
            if right is not None:
                expected = expected @ right
            scale = expected.abs().amax((-2, -1), keepdim=True) + 1e-6 * m.mu * (key == "Ptilde")
            assert ((out[key] - expected).abs() / scale).max() <= 1e-10, key


@pytest.mark.parametrize("dim", [2, 3])
def test_stress_free_and_pure_elastic(dim):
    I = torch.eye(dim, dtype=torch.float64)
    for name in PRESETS:
        m = Material.preset(name, dim)
        assert m.elastoplastic_stress(I).abs().max() <= 1e-9 * m.mu
        assert m.psi(I).abs() <= 1e-9 * m.mu
    # Without plasticity Ptilde = P and F_elastic = F (for det F > 0 and Sigma > SIGMA_MIN).
    m = Material.from_dict({"elasticity": {"model": "neo_hookean_metal", "E": 1e6, "nu": 0.3}}, dim)
    g = torch.Generator().manual_seed(1)
    F = torch.eye(dim, dtype=torch.float64) + 0.2 * torch.randn(20, dim, dim, generator=g, dtype=torch.float64)
    F = F[torch.linalg.det(F) > 0]
    torch.testing.assert_close(m.elastoplastic_stress(F), m.P(F), rtol=0, atol=0)
    F_e, h_new = m.elastic_part(F, 0.0)
    torch.testing.assert_close(F_e, F, rtol=1e-12, atol=1e-12)
    assert (m.yield_function(torch.ones(3, dim, dtype=torch.float64)) == 0).all()


@pytest.mark.parametrize("dim", [2, 3])
def test_single_matrix_numpy_and_batch_agree(dim):
    m = Material.preset("snow", dim)
    g = torch.Generator().manual_seed(3)
    F = torch.eye(dim, dtype=torch.float64) + 0.15 * torch.randn(6, dim, dim, generator=g, dtype=torch.float64)
    h = torch.linspace(-0.6, -0.1, 6, dtype=torch.float64)
    batch = m.evaluate(F, h)
    for i in range(6):
        single = m.evaluate(F[i], float(h[i]))
        from_numpy = m.evaluate(F[i].numpy(), float(h[i]))
        for key, value in batch.items():
            assert single[key].shape == value.shape[1:]
            torch.testing.assert_close(single[key], value[i], rtol=1e-13, atol=0.0)
            torch.testing.assert_close(from_numpy[key], value[i], rtol=1e-13, atol=0.0)
    P_single = m.elastoplastic_stress(F[0], h[0])
    assert P_single.shape == (dim, dim)
    F_e, h_new = m.elastic_part(F, h)
    assert F_e.shape == F.shape and h_new.shape == (6,)
    assert m.dPdF(F).shape == (6, dim * dim, dim * dim) and m.dPdF(F[0]).shape == (dim * dim, dim * dim)
    # Default hardening = initial_hardening.
    torch.testing.assert_close(m.elastoplastic_stress(F), m.elastoplastic_stress(F, -0.1))


def _vector_cases():
    return json.loads(VECTORS.read_text())["cases"]


@pytest.mark.parametrize("dim", [2, 3])
def test_float32_agrees_with_float64(dim):
    """Every case of the Python vectors (all materials and branches, margin 1e-4 from thresholds):
    float32 gives the same branch and agrees with float64 to ~1e-4 relative."""
    cases = [c for c in _vector_cases() if c["dim"] == dim]
    assert len(cases) > 100
    worst = {}
    checked = 0
    for c in cases:
        m = Material.from_dict(c["material"], dim)
        F64 = torch.tensor(c["F"], dtype=torch.float64).reshape(dim, dim)
        out64 = m.evaluate(F64, c["hardening"])
        out32 = m.evaluate(F64.to(torch.float32), c["hardening"])
        assert out32["Ptilde"].dtype == torch.float32
        assert int(out32["branch"]) == int(out64["branch"]), c["name"]
        for key in ("Ptilde", "F_elastic", "Z_Sigma", "P", "tau", "hardening_new", "psi"):
            a, b = out32[key].double(), out64[key]
            floor = {"Ptilde": 1e-3 * m.mu, "P": 1e-3 * m.mu, "tau": 1e-3 * m.mu, "psi": 1e-6 * m.mu}.get(key, 1e-3)
            rel = float((a - b).abs().max() / max(float(b.abs().max()), floor))
            worst[key] = max(worst.get(key, 0.0), rel)
        checked += 1
    assert checked == len(cases)
    print(f"\n[float32 vs float64, {dim}D, {checked} cases] worst relative difference: "
          + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert max(worst.values()) <= 2e-4, worst


@pytest.mark.parametrize("dim", [2, 3])
def test_reflected_F_is_clamped(dim, rotation_sampler):
    """det F < 0: the material sees F_c = U diag(max(Sigma, SIGMA_MIN)) V^T, so F_elastic has det > 0."""
    m = Material.preset("metal_nh", dim)
    g = torch.Generator().manual_seed(5)
    F = rotation_sampler(10, dim, g) @ torch.diag(torch.tensor([1.2, -0.9, 1.0][:dim], dtype=torch.float64))
    U, Sigma, V = polar_svd(F)
    assert (Sigma[:, -1] < 0).all()
    out = m.evaluate(F, 0.05)
    assert (torch.linalg.det(out["F_elastic"]) > 0).all()
    F_c = (U * torch.clamp(Sigma, min=SIGMA_MIN)[:, None, :]) @ V.transpose(-1, -2)
    torch.testing.assert_close(m.elastoplastic_stress(F_c, 0.05), out["Ptilde"], rtol=1e-10, atol=1e-6 * m.mu)


def test_description_is_not_mutated():
    desc = copy.deepcopy(material_module.PRESETS["snow"])
    before = copy.deepcopy(desc)
    Material.from_dict(desc, 2)
    assert desc == before


def test_numpy_float32_input():
    m = Material.preset("sand", 2)
    F = np.array([[1.1, 0.1], [0.0, 0.9]], dtype=np.float32)
    assert m.elastoplastic_stress(F).dtype == torch.float32
