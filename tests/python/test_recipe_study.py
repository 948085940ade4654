"""scripts/recipe_study.py: one failing run does not cancel the others (they ran on after a failure
before: the pool's map cancelled every run still queued), and the study exits non-zero naming it."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("recipe_study", ROOT / "scripts" / "recipe_study.py")
recipe_study = importlib.util.module_from_spec(spec)
sys.modules["recipe_study"] = recipe_study  # its dataclasses look their module up there
spec.loader.exec_module(recipe_study)


def test_a_failed_run_leaves_the_queued_runs_running(monkeypatch, tmp_path, capsys):
    names = [r.name for r in recipe_study.RUNS[:4]]
    ran = []

    def fake_run_one(run, out_dir):
        ran.append(run.name)
        if run.name == names[0]:
            raise RuntimeError(f"{run.name}: train.py exited 1")
        return out_dir / "runs" / run.name / "model.pt"

    monkeypatch.setattr(recipe_study, "run_one", fake_run_one)
    monkeypatch.setattr(recipe_study, "summarize", lambda runs, out: None)
    monkeypatch.setattr("sys.argv", ["recipe_study.py", "--out", str(tmp_path), "--jobs", "1", "--runs", *names])
    assert recipe_study.main() == 1
    assert ran == names
    assert f"{names[0]}: train.py exited 1" in capsys.readouterr().err
