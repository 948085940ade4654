"""The training loop and train.py: the loss falls, resuming is exact, outputs are written, bad arguments
exit with code 2 and a message."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import plasticitynet
from plasticitynet.training import TrainConfig, Trainer, train
from plasticitynet.training.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[2]
TRAIN_PY = ROOT / "train.py"


pytestmark = pytest.mark.usefixtures("one_thread")


def _config(tmp_path, **kw):
    base = dict(material="sand", dim=2, epochs=200, batch=256, seed=0, out=str(tmp_path / "model.pt"),
                checkpoint_every=1000, eval_samples=0, progress=False)
    base.update(kw)
    return TrainConfig(**base)


def _loss_factor(rows, first=5, last=20):
    losses = [r[1] for r in rows]
    return (sum(losses[:first]) / first) / (sum(losses[-last:]) / last)


def test_energy_training_lowers_the_loss(tmp_path):
    """200 steps of batch 256 on 2D sand (constant lr 0.01): the loss falls by a factor ~38 (measured with
    seeds 0, 1, 2: 38, 97, 47); assert 15."""
    result = train(_config(tmp_path))
    trainer_rows = list(csv.reader(open(result.paths["log"])))
    assert trainer_rows[0] == ["step", "loss", "lr", "wall_seconds"] and len(trainer_rows) == 201
    rows = [(int(r[0]), float(r[1]), float(r[2]), float(r[3])) for r in trainer_rows[1:]]
    assert [r[0] for r in rows] == list(range(1, 201)) and all(r[2] == 0.01 for r in rows)
    assert _loss_factor(rows) > 15
    assert result.paths["model"].is_file() and result.paths["plot"].stat().st_size > 1000
    assert result.metadata["recipe"]["epochs"] == 200 and result.metadata["recipe"]["batch"] == 256


def test_return_map_training_lowers_the_loss(tmp_path):
    """200 steps of batch 256, 2D metal_nh_rm: factor ~80 (seeds 0, 1, 2: 81, 76, 213); assert 20."""
    trainer = Trainer(_config(tmp_path, material="metal_nh_rm"))
    trainer.run(stop_at=200)
    assert _loss_factor(trainer.log_rows) > 20


@pytest.mark.parametrize("material", ["snow", "metal_nh_rm"])
def test_float64_training_follows_float32(tmp_path, material):
    """--precision float64: the network and the loss in float64 (parameters, Adam state, recipe), from the
    same initialisation and batches as float32: the first loss agrees to float32's round-off, and a resume
    in the other precision is refused."""
    kw = dict(material=material, epochs=5, batch=64, checkpoint_every=5, hessian_weight=0.1 if material == "snow" else 0.0)
    lo = Trainer(_config(tmp_path / "32", **kw))
    hi = Trainer(_config(tmp_path / "64", precision="float64", **kw))
    assert all(q.dtype == torch.float64 for q in hi.net.parameters())
    assert all(q.dtype == torch.float32 for q in lo.net.parameters())
    for a, b in zip(lo.net.parameters(), hi.net.parameters()):
        assert torch.equal(a.double(), b)  # float64 starts from float32's initial weights
    lo.run()
    hi.run()
    first32, first64 = lo.log_rows[0][1], hi.log_rows[0][1]
    assert first32 != first64 and abs(first32 - first64) <= 1e-5 * abs(first64)
    assert hi.recipe()["dtype"] == "float64" and lo.recipe()["dtype"] == "float32"
    with pytest.raises(ValueError, match="precision"):
        Trainer(_config(tmp_path / "64", resume=True, **{**kw, "epochs": 10}))
    with pytest.raises(ValueError, match="precision = 'float16'"):
        _config(tmp_path, precision="float16")


def test_hidden_widths(tmp_path):
    """--hidden: any number and width of hidden layers, exported and reloaded with them; a resume with other
    widths is refused; the default is Table 2's."""
    kw = dict(material="metal", epochs=4, batch=32, checkpoint_every=2)
    assert Trainer(_config(tmp_path / "default", **kw)).net.widths == [7, 32, 32, 32, 1]
    result = train(_config(tmp_path / "deep", hidden=(16, 24, 16, 8), **kw))
    assert result.metadata["widths"] == [7, 16, 24, 16, 8, 1]
    model = plasticitynet.load_model(result.paths["model"])
    assert model.metadata["widths"] == [7, 16, 24, 16, 8, 1]
    with pytest.raises(ValueError, match="hidden"):
        Trainer(_config(tmp_path / "deep", resume=True, **{**kw, "epochs": 6}))
    with pytest.raises(ValueError, match=r"hidden = \[16, 0\]"):
        _config(tmp_path, hidden=(16, 0))


@pytest.mark.parametrize("material", ["metal", "metal_nh_rm"])
def test_export_does_not_compile_again(tmp_path, monkeypatch, material):
    """The network is scripted when training starts and that module (sharing the trained parameters) is
    exported: compiling at the end re-read the package's source, so editing nets.py during a run broke the
    export after 40000 steps (TorchScript 'Don't support conversion in JoinedStr' at a shifted line)."""
    trainer = Trainer(_config(tmp_path, material=material, epochs=3, batch=32, eval_samples=64))

    def no_compiling(*args, **kwargs):
        raise RuntimeError("compiled at export")

    monkeypatch.setattr(torch.jit, "script", no_compiling)
    result = trainer.run()
    assert result.finished and result.paths["model"].is_file()
    exported = torch.jit.load(str(result.paths["model"]))
    for (name, a), b in zip(trainer.net.state_dict().items(), exported.state_dict().values()):
        assert b.dtype == torch.float64 and torch.equal(a.double().cpu(), b), name


def test_lr_schedule(tmp_path):
    trainer = Trainer(_config(tmp_path, epochs=12, batch=16, lr=0.02, lr_decay=0.5, decay_steps=5))
    trainer.run(stop_at=12)
    assert [r[2] for r in trainer.log_rows] == [0.02] * 5 + [0.01] * 5 + [0.005] * 2


def test_resume_equals_uninterrupted(tmp_path):
    kw = dict(epochs=30, batch=64, checkpoint_every=10, lr_decay=0.5, decay_steps=7, eval_every=10)
    full = Trainer(_config(tmp_path / "a", **kw))
    full.run()
    # Interrupted at 15 (after the checkpoint at 10; one is also written at the stop), then resumed twice:
    # once from the stop and once from the periodic checkpoint at 10 (as after a crash).
    part = Trainer(_config(tmp_path / "b", **kw))
    assert not part.run(stop_at=15).finished
    ckpt = part.config.paths["checkpoint"]
    assert torch.load(ckpt)["step"] == 15
    resumed = Trainer(_config(tmp_path / "b", resume=True, **kw))
    assert resumed.step == 15
    resumed.run()
    for a, b in zip(full.net.state_dict().values(), resumed.net.state_dict().values()):
        assert torch.equal(a, b)
    assert [r[:3] for r in full.log_rows] == [r[:3] for r in resumed.log_rows]
    assert [r[3:] for r in full.eval_rows] == [r[3:] for r in resumed.eval_rows]
    # The CSV log of the resumed run is the whole history, once.
    steps = [int(r[0]) for r in list(csv.reader(open(resumed.config.paths["log"])))[1:]]
    assert steps == list(range(1, 31))
    # Exported models agree bit for bit.
    x = torch.randn(50, 8, dtype=torch.float64)
    out_a = torch.jit.load(str(full.config.paths["model"]))(x)
    out_b = torch.jit.load(str(resumed.config.paths["model"]))(x)
    assert torch.equal(out_a, out_b)
    # A checkpoint of another recipe is refused.
    with pytest.raises(ValueError, match="batch"):
        Trainer(_config(tmp_path / "b", resume=True, **{**kw, "batch": 32}))
    with pytest.raises(ValueError, match="wide_fraction"):
        Trainer(_config(tmp_path / "b", resume=True, **{**kw, "wide_fraction": 0.25}))


def test_a_wide_share_trains_on_twice_the_perturbation_and_is_recorded(tmp_path):
    """--wide-fraction: the batches' last share has deps beyond the trained range, the run differs from one
    without it, and the exported model's recipe records the share and its range."""
    kw = dict(epochs=3, batch=64, checkpoint_every=10)
    plain = Trainer(_config(tmp_path / "plain", **kw))
    plain.run()
    wide = Trainer(_config(tmp_path / "wide", wide_fraction=0.25, **kw))
    wide.run()
    assert wide.task.spec.wide_fraction == 0.25
    assert [r[1] for r in plain.log_rows] != [r[1] for r in wide.log_rows]
    distribution = wide.recipe()["distribution"]
    assert distribution["wide_fraction"] == 0.25
    assert distribution["wide_deps_range"] == [-2 * distribution["deps_range"][1], 2 * distribution["deps_range"][1]]


def test_train_py_end_to_end(tmp_path):
    """train.py for the learned return mapping, then the metal_nh energy trained against it (tiny runs)."""
    rm = tmp_path / "rm" / "metal_nh_rm_2d.pt"
    common = ["--dim", "2", "--no-progress", "--threads", "1", "--eval-samples", "2000"]
    run = subprocess.run(
        [sys.executable, str(TRAIN_PY), "--material", "metal_nh_rm", "--epochs", "30", "--batch", "256",
         "--out", str(rm), *common], capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert f"wrote model:      {rm}" in run.stdout and "learned return mapping on" in run.stdout
    out = tmp_path / "e" / "metal_nh_2d.pt"
    run = subprocess.run(
        [sys.executable, str(TRAIN_PY), "--material", "metal_nh", "--epochs", "20", "--batch", "128",
         "--return-map", str(rm), "--out", str(out), "--eval-every", "10", "--lr-decay", "0.9",
         "--decay-steps", "5", "--sampling", "mixed", "--hessian-weight", "0.2", *common],
        capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 0, run.stderr
    for p in (out, out.with_suffix(".csv"), out.with_suffix(".ckpt"), out.with_name("metal_nh_2d_loss.png"),
              out.with_name("metal_nh_2d_eval.csv")):
        assert p.is_file() and str(p) in run.stdout
    assert "against the library's root-find return mapping" in run.stdout
    model = plasticitynet.load_model(out)  # finds ../rm/metal_nh_rm_2d.pt through the metadata
    meta = model.metadata
    assert meta["return_map"]["type"] == "learned" and meta["return_map"]["file"] == "../rm/metal_nh_rm_2d.pt"
    recipe = meta["recipe"]
    assert (recipe["epochs"], recipe["batch"], recipe["decay"], recipe["decay_steps"], recipe["sampling"]) == (
        20, 128, 0.9, 5, "mixed")
    assert (recipe["representation"], recipe["hessian_weight"]) == ("principal", 0.2)
    assert meta["representation"] == "principal" and model.representation == "principal"
    assert 0 < meta["errors"]["hessian_rel_rms_near"] < 10
    assert "principal input, Hessian weight 0.2" in run.stdout
    assert recipe["command"].startswith("python train.py --material metal_nh")
    assert meta["errors"]["at_F0_max_rel"] < 1e-10 and meta["errors"]["samples"] == 2000
    assert json.loads(json.dumps(meta)) == meta


@pytest.mark.parametrize(
    "args,message",
    [
        (["--material", "granite", "--dim", "2"], "invalid choice: 'granite'"),
        (["--material", "sand", "--dim", "4"], "invalid choice: 4"),
        (["--material", "sand", "--dim", "2", "--batch", "-5"], "--batch: -5 must be > 0"),
        (["--material", "sand", "--dim", "2", "--epochs", "0"], "--epochs: 0 must be > 0"),
        (["--material", "sand", "--dim", "2", "--lr", "nan"], "--lr: nan must be finite and > 0"),
        (["--material", "sand", "--dim", "2", "--lr-decay", "1.5"], "must be in (0, 1]"),
        (["--material", "metal_nh", "--dim", "2", "--return-map", "/no/such/rm.pt"], "/no/such/rm.pt: no such file"),
        (["--material", "sand", "--dim", "2", "--return-map", "x.pt"], "applies to --material metal_nh only"),
        (["--material", "sand", "--dim", "2", "--resume", "--out", "/no/such/dir/m.pt"], "no checkpoint"),
        (["--material", "sand", "--dim", "2", "--out", "model.bin"], "must end in .pt"),
        (["--material", "sand", "--dim", "2", "--representation", "polar"], "invalid choice: 'polar'"),
        (["--material", "sand", "--dim", "2", "--hessian-weight", "-1"], "must be finite and >= 0, got -1"),
        (["--material", "sand", "--dim", "2", "--hessian-weight", "inf"], "must be finite and >= 0, got inf"),
        (["--material", "sand", "--dim", "2", "--sampling", "far"], "invalid choice: 'far'"),
        (["--material", "sand", "--dim", "2", "--energy-form", "eq9"], "invalid choice: 'eq9'"),
        (["--material", "metal_nh_rm", "--dim", "2", "--energy-form", "global"], "--energy-form applies to energies"),
        (["--material", "sand", "--dim", "2", "--hidden", "64", "0"], "--hidden: 0 must be > 0"),
        (["--material", "sand", "--dim", "2", "--precision", "float16"], "invalid choice: 'float16'"),
        (["--material", "sand", "--dim", "2", "--wide-fraction", "1"], "--wide-fraction: 1.0 must be in [0, 1)"),
        (["--material", "metal_nh_rm", "--dim", "2", "--wide-fraction", "0.2"], "wide_fraction applies to energies"),
    ],
)
def test_bad_arguments_exit_2(args, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli_main(args)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_bad_arguments_through_train_py():
    for args, message in (
        (["--material", "granite", "--dim", "2"], "invalid choice: 'granite'"),
        (["--material", "sand", "--dim", "4"], "invalid choice: 4"),
        (["--material", "sand", "--dim", "2", "--batch", "-1"], "--batch: -1 must be > 0"),
    ):
        run = subprocess.run([sys.executable, str(TRAIN_PY), *args], capture_output=True, text=True, timeout=120)
        assert run.returncode == 2 and message in run.stderr and "usage: train.py" in run.stderr


@pytest.mark.parametrize("form", ["global", "local_identity"])
def test_train_py_rejected_energy_form(tmp_path, form):
    """train.py --energy-form (the ablation of the paper's Fig. 11): the form is in the printed line, the
    metadata and the recipe, load_model evaluates it, and eq. 8's exactness at F0 is (rightly) not there."""
    out = tmp_path / f"sand_2d_{form}.pt"
    run = subprocess.run(
        [sys.executable, str(TRAIN_PY), "--material", "sand", "--dim", "2", "--epochs", "10", "--batch", "128",
         "--representation", "raw", "--energy-form", form, "--out", str(out), "--no-progress", "--threads", "1",
         "--eval-samples", "500"], capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert f"energy form {form}" in run.stdout
    model = plasticitynet.load_model(out)
    assert model.energy_form == form and model.metadata["energy_form"] == form
    assert model.metadata["recipe"]["energy_form"] == form
    assert "rejected" in model.metadata["energy"]
    assert model.metadata["errors"]["at_F0_max_rel"] > 1e-6
    eye = torch.eye(2, dtype=torch.float64)
    F0 = torch.tensor([[1.1, 0.05], [0.0, 0.9]], dtype=torch.float64)
    if form == "local_identity":
        assert float(model.gradient(eye, F0).abs().max()) < 1e-9
    else:
        assert torch.allclose(model.gradient(F0, F0), model.gradient(F0, eye), rtol=1e-13, atol=1e-15)


def test_init_from_starts_at_a_trained_models_weights_and_records_it(tmp_path):
    """--init-from (fine-tuning): the run's network starts with the shipped sand_2d's weights, so its held-out
    error before any step is the model's; the recipe names the file and its sha256; a resume must start from
    the same weights; a model of another material or other widths is refused naming the field."""
    shipped = ROOT / "models" / "sand_2d.pt"
    kw = dict(hidden=(64, 64, 64), representation="principal", sampling="mixed", epochs=4, batch=64,
              lr=1e-4, checkpoint_every=2, init_from=str(shipped))
    trainer = Trainer(_config(tmp_path / "a", **kw))
    model = plasticitynet.load_model(shipped)
    for k, v in model.network.state_dict().items():
        assert torch.equal(trainer.net.state_dict()[k], v.to(torch.float32))
    fresh = Trainer(_config(tmp_path / "b", **{**kw, "init_from": ""}))
    assert trainer.task.curve_error()["paper"] < 0.02 < fresh.task.curve_error()["paper"]
    assert trainer.run(stop_at=2).finished is False
    resumed = Trainer(_config(tmp_path / "a", resume=True, **kw))
    recipe = resumed.recipe()
    assert recipe["init_from"]["file"] == "sand_2d.pt" and len(recipe["init_from"]["sha256"]) == 64
    with pytest.raises(ValueError, match="init_from"):  # resumed without the starting weights
        Trainer(_config(tmp_path / "a", resume=True, **{**kw, "init_from": ""}))
    with pytest.raises(ValueError, match="layer widths"):
        Trainer(_config(tmp_path / "c", **{**kw, "hidden": (32, 32, 32)}))
    with pytest.raises(ValueError, match="its material is 'sand', this run trains 'snow'"):
        Trainer(_config(tmp_path / "d", **{**kw, "material": "snow"}))


def test_init_from_cli_errors(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli_main(["--material", "sand", "--dim", "2", "--init-from", str(tmp_path / "none.pt"),
                  "--out", str(tmp_path / "m.pt")])
    assert exit_info.value.code == 2 and "--init-from" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        cli_main(["--material", "metal_nh_rm", "--dim", "2", "--init-from", str(ROOT / "models" / "sand_2d.pt"),
                  "--out", str(tmp_path / "m.pt")])
    assert exit_info.value.code == 2 and "applies to energies" in capsys.readouterr().err
