"""scripts/continue_training.py, the recipe probe of issue 32's fourth pass: it continues a shipped energy's
training with the loss variant asked for and reports the held-out errors it measured."""

import subprocess
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]


def test_continues_a_shipped_energy_and_reports_its_errors(tmp_path):
    saved = tmp_path / "state.pt"
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "continue_training.py"), "--model", str(ROOT / "models" / "sand_2d.pt"),
         "--hessian-weight", "0.1", "--batch", "64", "--steps", "3", "--lr", "1e-2", "--save", str(saved)],
        capture_output=True, text=True, check=True, timeout=600,
    ).stdout
    lines = out.splitlines()
    assert lines[0].startswith("start: paper ") and "near" in lines[0]
    assert lines[1].startswith("step 3 ") and "loss gradient" in lines[1] and "hessian" in lines[1]
    assert lines[2].startswith("Hessian (near) ") and "paper 1x on 100000 samples" in lines[2]
    # The weights moved from the model file's (three Adam steps at lr 1e-2).
    start = torch.jit.load(str(ROOT / "models" / "sand_2d.pt")).state_dict()
    trained = torch.load(saved)
    assert start.keys() == trained.keys()
    assert any(not torch.equal(start[k], trained[k].to(start[k].dtype)) for k in start)


def test_refuses_a_file_that_is_not_an_energy():
    run = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "continue_training.py"), "--model",
         str(ROOT / "models" / "metal_nh_rm_2d.pt")], capture_output=True, text=True, timeout=600)
    assert run.returncode == 2 and "not an energy model" in run.stderr
