"""The evaluation scripts' own logic (scripts/evaluate_*.py), without running simulations."""
import hashlib
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def load_script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("scene", ["sand_column_2d", "stiff/sand_column_2d", "stiff/snowball_2d"])
def test_implicit_run_marker_hashes_the_scenes_own_model_file(scene):
    """Model paths in a scene file are relative to that file's folder (scenes/stiff/ for the
    stiff variants), so the marker must hash the model the simulator loads."""
    evaluate = load_script("evaluate_implicit")
    command = ["pnet", "simulate", f"scenes/{scene}.json", "--integrator", "plasticitynet",
               "--threads", "2", "--out", "somewhere"]
    marker = evaluate.run_marker(scene, command, explicit=False)
    assert marker["models"], "an implicit run depends on its model file"
    for model, digest in marker["models"].items():
        path = (ROOT / "scenes" / f"{scene}.json").parent / model
        assert digest == hashlib.sha256(path.read_bytes()).hexdigest()
    assert "--threads" not in marker["command"] and "somewhere" not in marker["command"]
