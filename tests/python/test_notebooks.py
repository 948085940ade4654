"""The notebooks of notebooks/ execute (`jupyter nbconvert --execute`, Debian's jupyter-nbconvert)
from the committed results, draw their figures, and match their source, notebooks/build_notebooks.py."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_every_notebook_is_listed():
    names = {p.stem for p in NOTEBOOKS}
    assert {"fig04_training_curves", "fig05_accuracy", "table1_timings", "fig11_energy_representations", "fig12_regularizer", "fig13_gallery_3d",
            "fig14_16_elastic_regions", "fig06_10_scenes_2d", "inverse_identification"} <= names


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes_and_draws(tmp_path, path):
    out = tmp_path / path.name
    r = subprocess.run([sys.executable, "-m", "jupyter", "nbconvert", "--to", "notebook", "--execute",
                        "--ExecutePreprocessor.timeout=300", "--output", str(out), str(path)],
                       capture_output=True, text=True, timeout=600, env={**os.environ, "PNET_NOTEBOOK_TINY": "1"})
    assert r.returncode == 0, r.stderr[-3000:]
    cells = json.loads(out.read_text())["cells"]
    outputs = [o for c in cells if c["cell_type"] == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o["output_type"] == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert images, f"{path.name} drew nothing"


def test_committed_notebooks_match_their_source(tmp_path):
    """build_notebooks.py is the notebooks' source: the committed cells are the ones it writes."""
    spec_path = ROOT / "notebooks" / "build_notebooks.py"
    namespace = {"__name__": "build_notebooks", "__file__": str(spec_path)}
    exec(compile(spec_path.read_text(), str(spec_path), "exec"), namespace)
    for name, cells in namespace["NOTEBOOKS"].items():
        committed = json.loads((ROOT / "notebooks" / f"{name}.ipynb").read_text())["cells"]
        sources = ["".join(c["source"]) if isinstance(c["source"], list) else c["source"] for c in committed]
        assert sources == [c["source"] for c in cells], f"{name}.ipynb differs from build_notebooks.py: rebuild it"
