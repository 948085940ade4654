"""scripts/ship_model.py: a model trained elsewhere is copied into a models folder with its logs, and a
metal_nh energy's reference to its learned return mapping is rewritten so that the copy loads."""

import importlib.util
import shutil
from pathlib import Path

import pytest

import plasticitynet
from plasticitynet.training import TrainConfig, train

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("ship_model", ROOT / "scripts" / "ship_model.py")
ship_model = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ship_model)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A 2-step metal_nh energy trained deep in a run folder against a copy of the shipped return map."""
    base = tmp_path_factory.mktemp("ship")
    shipped = base / "models"
    shipped.mkdir()
    shutil.copyfile(ROOT / "models" / "metal_nh_rm_2d.pt", shipped / "metal_nh_rm_2d.pt")
    run = base / "study" / "runs" / "a" / "model.pt"
    train(TrainConfig(material="metal_nh", dim=2, epochs=2, batch=16, eval_samples=0, progress=False,
                      return_map=str(shipped / "metal_nh_rm_2d.pt"), out=str(run)))
    return base, shipped, run


def test_shipped_copy_loads_and_keeps_its_logs(trained, one_thread):
    base, shipped, run = trained
    assert plasticitynet.load_model(run).metadata["return_map"]["file"] == "../../../models/metal_nh_rm_2d.pt"
    assert ship_model.main([str(run), "metal_nh_2d", "--models", str(shipped)]) == 0
    model = plasticitynet.load_model(shipped / "metal_nh_2d.pt")
    assert model.metadata["return_map"]["file"] == "metal_nh_rm_2d.pt"
    assert (shipped / "metal_nh_2d.csv").read_text() == run.with_suffix(".csv").read_text()
    assert (shipped / "metal_nh_2d_loss.png").is_file()


def test_a_different_return_map_is_refused_and_nothing_written(trained, tmp_path, capsys):
    base, shipped, run = trained
    other = base / "other.pt"
    shutil.copyfile(run, other)  # now ../../../models/metal_nh_rm_2d.pt is resolved from base: missing
    dest = tmp_path / "models"
    dest.mkdir()
    assert ship_model.main([str(other), "x", "--models", str(dest)]) == 2
    assert "is not at" in capsys.readouterr().err and not any(dest.iterdir())
    # the right path but another file: refused by its sha256
    moved = base / "study" / "runs" / "b" / "c"  # ../../../models is then study/models
    moved.mkdir(parents=True)
    shutil.copyfile(run, moved / "model.pt")
    (base / "study" / "models").mkdir(exist_ok=True)
    shutil.copyfile(ROOT / "models" / "metal_nh_2d.pt", base / "study" / "models" / "metal_nh_rm_2d.pt")
    assert ship_model.main([str(moved / "model.pt"), "x", "--models", str(dest)]) == 2
    assert "sha256 differs" in capsys.readouterr().err and not any(dest.iterdir())


def test_a_long_loss_log_is_thinned_to_every_kth_step_and_the_last(tmp_path):
    source = tmp_path / "run.csv"
    source.write_text("step,loss\n" + "".join(f"{s},{1.0 / s}\n" for s in range(1, 25)))
    dest = tmp_path / "shipped.csv"
    assert ship_model.thin_loss_log(source, dest, max_rows=10) == 3
    steps = [int(line.split(",")[0]) for line in dest.read_text().splitlines()[1:]]
    assert steps == [3, 6, 9, 12, 15, 18, 21, 24]
    source.write_text("step,loss\n" + "".join(f"{s},0\n" for s in range(1, 26)))
    ship_model.thin_loss_log(source, dest, max_rows=10)
    assert [int(line.split(",")[0]) for line in dest.read_text().splitlines()[1:]][-2:] == [24, 25]
    ship_model.thin_loss_log(source, dest, max_rows=100)  # a short log is copied whole
    assert dest.read_text() == source.read_text()
