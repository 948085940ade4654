"""Every model shipped in models/ is pinned by models/MANIFEST, loads, reproduces Ptilde exactly at
F = F0, and is as accurate on held-out samples as MANIFEST says (issue 3)."""

import json
from pathlib import Path

import pytest
import torch

import plasticitynet
from plasticitynet.training.held_out import EVAL_SEED, evaluate_return_map, gradient_errors, relative_rms_error
from plasticitynet.training.export import sha256_of
from plasticitynet.training.sampling import sample_batch, sampling_spec

MODELS = Path(__file__).resolve().parents[2] / "models"
SHIPPED = ("sand_2d", "snow_2d", "metal_2d", "metal_nh_rm_2d", "metal_nh_2d", "sand_3d", "snow_3d", "metal_3d",
           "sand_param_2d", "snow_param_2d", "metal_param_2d", "sand_param_3d", "snow_param_3d")
#: Held-out samples per check here (MANIFEST's figures use 1e5): the estimate's spread at this size is
#: a few percent of the error itself, hence the relative margin below.
SAMPLES = 1 << 13


def manifest() -> dict:
    return {e["file"]: e for e in json.loads((MODELS / "MANIFEST").read_text())["models"]}


def test_manifest_lists_every_shipped_model():
    entries = manifest()
    missing = [name for name in SHIPPED if f"{name}.pt" not in entries]
    assert not missing, f"models/MANIFEST lacks {missing}"
    for name in SHIPPED:
        e = entries[f"{name}.pt"]
        assert e["command"] and e["epochs"] > 0 and e["batch"] > 0 and e["wall_seconds"] > 0, name
        assert e["errors"], f"{name}: no measured errors in MANIFEST"


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_model_matches_manifest_and_is_exact_at_F0(name):
    path = MODELS / f"{name}.pt"
    entry = manifest()[path.name]
    assert sha256_of(path) == entry["sha256"], f"{path} does not match the sha256 in models/MANIFEST"
    model = plasticitynet.load_model(path)
    assert model.dim == entry["dim"] and model.metadata["kind"] == entry["kind"]
    if entry["kind"] == "return_map":
        errors = evaluate_return_map(model, samples=SAMPLES, seed=EVAL_SEED)
        assert errors["mean_abs_dgamma_error"] <= 1.2 * entry["errors"]["mean_abs_dgamma_error"] + 1e-4
        return
    assert model.representation == entry["representation"] == model.metadata["representation"]
    # grad Psi(F0, F0, h) = Ptilde(F0, h) by construction (eq. 8), to round-off in float64.
    spec = sampling_spec(model.training_material, "paper")
    b = sample_batch(spec, 512, seed=7, step=0, stream="eval")
    g = model.gradient(b.F0, b.F0, b.h) / model.E
    P0 = model.stress_nd(b.F0, b.h)
    floor = 1e-3 * model.training_material.mu
    rel = torch.linalg.matrix_norm(g - P0) / torch.clamp(torch.linalg.matrix_norm(P0), min=floor)
    assert float(rel.max()) < 1e-10
    # Held-out gradient error at the training perturbation: no worse than MANIFEST's figure.
    measured = relative_rms_error(model, "paper", 1.0, SAMPLES, EVAL_SEED)
    recorded = entry["errors"]["rel_rms"]["paper"]["1x"]
    assert measured <= 1.1 * recorded + 2e-3, f"{name}: {measured:.4f} vs MANIFEST {recorded:.4f}"


#: The largest gradient error of one held-out sample at twice the trained perturbation (near sampling), in units
#: of the RMS stress, over EXTRAPOLATION_SAMPLES samples (such samples are rare: 8192 missed the first
#: snow_param_2d's). The shipped energies measure 0.04-3.7; a snow_3d fine-tuned without samples beyond the
#: trained perturbation measured 141 (about 100 of 100000 samples wild), and the first snow_param_2d and
#: snow_param_3d 31.9 and 54.6 (`--wide-fraction`, docs/training.md).
WORST_SAMPLE_BOUND = 6.0
EXTRAPOLATION_SAMPLES = 1 << 15


@pytest.mark.parametrize("name", [n for n in SHIPPED if not n.endswith("_rm_2d")])
def test_shipped_energy_does_not_extrapolate_wildly_beyond_its_training(name):
    model = plasticitynet.load_model(MODELS / f"{name}.pt")
    rms, worst = gradient_errors(model, "near", 2.0, EXTRAPOLATION_SAMPLES, EVAL_SEED)
    assert worst <= WORST_SAMPLE_BOUND, (
        f"{name}: a held-out sample at twice the trained perturbation has a gradient error {worst:.1f} x the RMS "
        f"stress (relative RMS error {100 * rms:.1f}%)"
    )


def test_parametric_model_beside_its_dedicated_one():
    """Issue 36's targets, on MANIFEST's figures (1e5 held-out samples): at the dedicated model's material the
    parametric models' errors are within 1.5x of the dedicated models', and no bin of any parametric
    model's parameter box is worse than 2x the box's mean."""
    entries = manifest()
    for name, dedicated, reference, ratio in (("sand_param_2d", "sand_2d", [30.0, 0.3], 1.5),
                                              ("snow_param_2d", "snow_2d", [45.0, 0.5, 0.3, 0.2], 1.5),
                                              ("metal_param_2d", "metal_2d", [0.1, 0.3], 1.5),
                                              ("snow_param_3d", "snow_3d", [45.0, 0.5, 0.3, 0.2], 1.5),
                                              ("sand_param_3d", "sand_3d", [30.0, 0.3], 1.5)):
        errors = entries[f"{name}.pt"]["errors"]
        assert errors["parameter_values"] == reference
        dedicated_error = entries[f"{dedicated}.pt"]["errors"]["rel_rms"]["paper"]["1x"]
        assert errors["rel_rms"]["paper"]["1x"] <= ratio * dedicated_error, name
    parametric = [name for name in SHIPPED if "_param_" in name]
    assert len(parametric) >= 4
    for name in parametric:
        box = entries[f"{name}.pt"]["errors"]["parameter_map"]
        assert len(box["points"]) == box["bins"] ** len(box["fields"]), name
        assert box["max_over_mean"] <= 2.0, f"{name}: worst bin {box['max_over_mean']:.2f}x the mean"


def test_flow_curvature_puts_its_state_on_the_yield_cone(capsys):
    """scripts/flow_curvature.py (docs/integrators.md, "The stiff column"): at delta = 0 its state is on the
    Drucker-Prager cone (the return mapping's loading stiffness along the shear far below the unloading,
    elastic one), past it both sides are the same plastic stiffness; a von Mises model is refused."""
    import importlib.util

    script = MODELS.parent / "scripts" / "flow_curvature.py"
    spec = importlib.util.spec_from_file_location("flow_curvature", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--model", str(MODELS / "sand_2d.pt"), "--E", "3.537e5", "--deltas", "0", "1e-4"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[2:]]
    (d0, net0, load0, unload0, _), (d1, net1, load1, unload1, _) = [[float(x) for x in r] for r in rows]
    assert (d0, d1) == (0.0, 1e-4)
    assert load0 < 0.05 * unload0, "on the cone: plastic on loading, elastic on unloading"
    assert abs(load1 - unload1) <= 0.01 * unload1, "past the cone both sides flow"
    assert net0 > 0.0 and net1 > 0.0
    with pytest.raises(SystemExit):
        module.main(["--model", str(MODELS / "metal_2d.pt")])
    assert "needs a drucker_prager energy" in capsys.readouterr().err
