"""Cross-check of the Python and C++ material libraries through the test vectors
(material spec, "Test-vector JSON"), and reproducibility of the Python vectors.

tests/data/material_vectors_cpp.json is written by the C++ generator; every case is recomputed here
from its description and F and compared quantity by quantity:
    max|a - b| <= 1e-10 * max(max|b|, floor),
floor = mu 1e-6 for tau, P, Ptilde, dPdF and 1e-300 (a tiny guard) otherwise; branch names must match.
A missing C++ file is a failure, not a skip: the cross-check must not silently never run.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest
import torch

from plasticitynet.materials import BRANCH_NAMES, Material

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
CPP_VECTORS = DATA / "material_vectors_cpp.json"
PY_VECTORS = DATA / "material_vectors_python.json"
GENERATOR = ROOT / "scripts" / "gen_material_vectors.py"

TOLERANCE = 1e-10
QUANTITIES = ("Sigma", "branch", "Z_Sigma", "hardening_new", "F_elastic", "psi", "tau", "P", "dPdF", "Ptilde")
STRESS_LIKE = ("tau", "P", "Ptilde", "dPdF")


def load_vectors(path: Path, generator: str) -> list:
    data = json.loads(path.read_text())
    assert data.get("format") == "plasticitynet-material-vectors", f"{path}: wrong format {data.get('format')!r}"
    assert data.get("version") == 1, f"{path}: unsupported version {data.get('version')!r}"
    assert data.get("generator") == generator, f"{path}: generator {data.get('generator')!r}, expected {generator!r}"
    assert len(data["cases"]) > 0, f"{path}: no cases"
    return data["cases"]


def compute_expect(case: dict) -> dict:
    """The "expect" object of a case, recomputed by the Python library in float64."""
    dim = case["dim"]
    m = Material.from_dict(case["material"], dim)
    F = torch.tensor(case["F"], dtype=torch.float64).reshape(dim, dim)
    out = m.evaluate(F, torch.tensor(case["hardening"], dtype=torch.float64))
    expect = {k: out[k].reshape(-1).tolist() for k in ("Sigma", "Z_Sigma", "F_elastic", "tau", "P", "dPdF", "Ptilde")}
    expect.update(branch=BRANCH_NAMES[int(out["branch"])], hardening_new=float(out["hardening_new"]),
                  psi=float(out["psi"]))
    return expect, m.mu


def discrepancies(actual: dict, expected: dict, mu: float) -> dict:
    """quantity -> max|a - b| / max(max|b|, floor); a branch mismatch is +inf."""
    out = {}
    for key in QUANTITIES:
        assert key in expected, f"expected quantity {key!r} missing"
        if key == "branch":
            out[key] = 0.0 if actual[key] == expected[key] else math.inf
            continue
        a = torch.tensor(actual[key], dtype=torch.float64).reshape(-1)
        b = torch.tensor(expected[key], dtype=torch.float64).reshape(-1)
        assert a.shape == b.shape, f"{key}: {a.numel()} numbers, expected {b.numel()}"
        floor = mu * 1e-6 if key in STRESS_LIKE else 1e-300
        out[key] = float((a - b).abs().max() / max(float(b.abs().max()), floor))
    return out


def compare_cases(cases: list, tolerance: float, label: str) -> tuple[dict, list]:
    """Largest discrepancy per quantity (with its case) and the failing (case, quantity, value)."""
    worst = {key: (0.0, "") for key in QUANTITIES}
    failures = []
    for case in cases:
        actual, mu = compute_expect(case)
        for key, value in discrepancies(actual, case["expect"], mu).items():
            if value > worst[key][0]:
                worst[key] = (value, case["name"])
            if not value <= tolerance:
                failures.append((case["name"], key, value))
    print(f"\n[{label}: {len(cases)} cases] largest relative discrepancy per quantity:")
    for key, (value, name) in worst.items():
        print(f"  {key:14s} {value:.3e}  {name}")
    return worst, failures


def test_cpp_vectors_match_python():
    if not CPP_VECTORS.exists():
        pytest.fail(
            f"{CPP_VECTORS.relative_to(ROOT)} is missing: build the C++ library and run its material-vector "
            f"generator to write it; the Python/C++ cross-check cannot run without it."
        )
    cases = load_vectors(CPP_VECTORS, "cpp")
    _, failures = compare_cases(cases, TOLERANCE, "C++ vectors vs Python")
    assert not failures, f"{len(failures)} discrepancies above {TOLERANCE}, first: " + "; ".join(
        f"{n} {k} {v:.2e}" for n, k, v in failures[:10]
    )


def _generator_module():
    spec = importlib.util.spec_from_file_location("gen_material_vectors", GENERATOR)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def python_cases():
    return load_vectors(PY_VECTORS, "python")


def test_python_vectors_are_reproducible(python_cases):
    """Regenerating in memory gives the same cases, inputs and numbers (to 1e-12)."""
    regenerated = _generator_module().generate()["cases"]
    assert [c["name"] for c in regenerated] == [c["name"] for c in python_cases]
    worst = {}
    for new, old in zip(regenerated, python_cases):
        assert new["dim"] == old["dim"] and new["material"] == old["material"], new["name"]
        assert new["F"] == pytest.approx(old["F"], rel=1e-12, abs=0), new["name"]
        assert new["hardening"] == pytest.approx(old["hardening"], rel=1e-12, abs=0), new["name"]
        mu = Material.from_dict(old["material"], old["dim"]).mu
        for key, value in discrepancies(new["expect"], old["expect"], mu).items():
            assert value <= 1e-12, f"{new['name']} {key}: {value:.2e}"
            worst[key] = max(worst.get(key, 0.0), value)
    print(f"\n[python vectors regenerated, {len(python_cases)} cases] worst: {max(worst.values()):.1e}")


def test_python_vectors_cover_every_branch(python_cases):
    """Each material, in 2D and in 3D, has cases in every branch its return mapping can take,
    and the vectors hold ~200-400 cases with every quantity of the format."""
    assert 200 <= len(python_cases) <= 450
    seen: dict = {}
    for case in python_cases:
        material, dim_label = case["name"].split("/")[:2]
        assert set(case["expect"]) == set(QUANTITIES), case["name"]
        d = case["dim"]
        assert len(case["F"]) == d * d and len(case["expect"]["dPdF"]) == d**4
        seen.setdefault((material, dim_label, case["dim"]), set()).add(case["expect"]["branch"])
    materials = {m for m, _, _ in seen}
    assert {"sand", "snow", "snow_paper", "metal", "metal_perfect", "metal_nh", "metal_nh_perfect"} <= materials
    assert {"elastic_stvk_hencky", "elastic_neo_hookean_snow", "elastic_neo_hookean_metal"} <= materials
    example = {c["name"].split("/")[0]: c for c in python_cases}
    for material in materials:
        expected = set(Material.from_dict(example[material]["material"], 2).branch_names)
        for dim in (2, 3):
            assert seen.get((material, f"{dim}d", dim)) == expected, (material, dim)
    # Special categories: reflected F (det < 0), large stretch and compression, near identity.
    names = [c["name"] for c in python_cases]
    for category in ("reflected", "stretch", "compression", "near_identity"):
        assert sum(f"/{category}/" in n for n in names) >= 2 * len(materials) * 2
    for c in python_cases:
        if "/reflected/" in c["name"]:
            assert c["expect"]["Sigma"][-1] < 0


def test_python_vectors_match_library_and_checker_can_fail(python_cases):
    """The file agrees with the library under the cross-check's own rule, and that rule does flag
    a perturbation (so that it cannot pass vacuously)."""
    sample = python_cases[::7]
    _, failures = compare_cases(sample, TOLERANCE, "Python vectors vs Python library")
    assert not failures
    case = json.loads(json.dumps(sample[-1]))
    actual, mu = compute_expect(case)
    for key in ("dPdF", "Sigma", "psi", "hardening_new"):
        perturbed = json.loads(json.dumps(case["expect"]))
        if isinstance(perturbed[key], list):
            perturbed[key][0] += 1e-8 * max(abs(x) for x in perturbed[key]) + 1e-300
        else:
            perturbed[key] = perturbed[key] * (1 + 1e-8) + 1e-12
        assert discrepancies(actual, perturbed, mu)[key] > TOLERANCE, key
    perturbed = dict(case["expect"], branch="apex" if case["expect"]["branch"] != "apex" else "cone")
    assert discrepancies(actual, perturbed, mu)["branch"] == math.inf
