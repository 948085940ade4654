"""Training on a chosen device and across processes (torch.distributed): sharded batches, the 2-process
gloo run against the single process at equal global batch, device errors, sync-free loops, resume after
a kill."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from plasticitynet.materials import cam_clay, unimodular_shift
from plasticitynet.training import TrainConfig, Trainer
from plasticitynet.training.sampling import generator_for, sample_batch, sample_return_map_states, sampling_spec
from plasticitynet.training.targets import nondimensional_material
from plasticitynet.training.trainer import resolve_device

ROOT = Path(__file__).resolve().parents[2]
TRAIN_PY = ROOT / "train.py"

pytestmark = pytest.mark.usefixtures("one_thread")

CUDA = torch.cuda.is_available()


def _config(tmp_path, **kw):
    base = dict(material="sand", dim=2, epochs=8, batch=64, seed=0, out=str(tmp_path / "model.pt"),
                checkpoint_every=1000, eval_samples=0, progress=False)
    base.update(kw)
    return TrainConfig(**base)


def _environment():
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT / "python"))
    for key in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT"):
        env.pop(key, None)
    return env


@pytest.mark.parametrize("material", ["snow", "metal"])
def test_shards_partition_the_batch(material):
    spec = sampling_spec(nondimensional_material(material, 3), "mixed")
    whole = sample_batch(spec, 48, seed=3, step=7, shards=4)
    parts = [sample_batch(spec, 48, seed=3, step=7, shards=4, shard_range=(r, r + 2)) for r in (0, 2)]
    for key in ("F", "F0", "h", "U", "Sigma0"):
        assert torch.equal(getattr(whole, key), torch.cat([getattr(p, key) for p in parts]))
    # One shard is today's batch (shipped models were trained on it); more shards are other draws.
    assert torch.equal(sample_batch(spec, 48, seed=3, step=7, shards=1).F, sample_batch(spec, 48, 3, 7).F)
    assert not torch.equal(whole.F, sample_batch(spec, 48, 3, 7).F)
    Sigma, h = sample_return_map_states(3, 48, 3, 7, shards=4)
    Sigma2, h2 = sample_return_map_states(3, 48, 3, 7, shards=4, shard_range=(2, 4))
    assert torch.equal(Sigma[24:], Sigma2) and torch.equal(h[24:], h2)


@pytest.mark.parametrize(
    "kwargs, message",
    [(dict(shards=5), "divide the batch size"), (dict(shards=4, shard_range=(3, 5)), "shard_range"),
     (dict(shards=0), "shards")],
)
def test_bad_shards_are_refused(kwargs, message):
    spec = sampling_spec(nondimensional_material("sand", 2))
    with pytest.raises(ValueError, match=message):
        sample_batch(spec, 48, 0, 0, **kwargs)


def test_generators_live_on_the_requested_device():
    g = generator_for(0, 1, "train", "cpu", shard=2)
    assert g.device.type == "cpu"
    assert not torch.equal(torch.rand(4, generator=g), torch.rand(4, generator=generator_for(0, 1, "train", "cpu")))
    with pytest.raises(ValueError, match="shard"):
        generator_for(0, 1, "train", "cpu", shard=-1)


@pytest.mark.skipif(CUDA, reason="CUDA is available here: the error path is for machines without it")
@pytest.mark.parametrize("device", ["cuda", "cuda:0"])
def test_cuda_without_cuda_is_an_error_naming_it(device):
    with pytest.raises(ValueError, match=f"device = '{device}'.*no CUDA device"):
        resolve_device(device)


@pytest.mark.parametrize("device", ["gpu", "cuda:x", "cpu0"])
def test_unknown_device_is_refused(tmp_path, device):
    with pytest.raises(ValueError, match="expected cpu, cuda, cuda:N or auto"):
        _config(tmp_path, device=device)


def test_auto_device_trains_where_it_can(tmp_path):
    trainer = Trainer(_config(tmp_path, device="auto"))
    assert trainer.device.type == ("cuda" if CUDA else "cpu")
    trainer.run(stop_at=3)
    assert next(trainer.net.parameters()).device.type == trainer.device.type
    assert torch.load(trainer.config.paths["checkpoint"])["config"]["device_type"] == trainer.device.type


@pytest.mark.skipif(not CUDA, reason="no CUDA device on this machine: the CUDA training path runs where one exists")
def test_cuda_training_lowers_the_loss_and_exports_a_cpu_model(tmp_path):
    trainer = Trainer(_config(tmp_path, device="cuda", epochs=60, batch=256, eval_samples=1000))
    result = trainer.run()
    losses = [r[1] for r in trainer.log_rows]
    assert sum(losses[-10:]) < sum(losses[:10])
    model = torch.jit.load(str(result.paths["model"]), map_location="cpu")
    assert model(torch.randn(5, 8, dtype=torch.float64)).shape == (5, 1)


def test_resume_with_other_shards_is_refused(tmp_path):
    Trainer(_config(tmp_path, shards=2)).run(stop_at=2)
    with pytest.raises(ValueError, match="shards"):
        Trainer(_config(tmp_path, shards=4, resume=True))


def test_convergence_test_interval_does_not_change_results(monkeypatch):
    """The loops freeze converged rows, so testing every 8 iterations (as on a GPU) gives the same bits."""
    t = torch.randn(4096, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(5))
    t = t - t.mean(-1, keepdim=True)
    every_iteration = unimodular_shift(t)
    monkeypatch.setattr(cam_clay, "sync_interval", lambda device: 8)
    assert torch.equal(unimodular_shift(t), every_iteration)


def test_two_process_gloo_training_matches_one_process(tmp_path):
    """torchrun (our launcher: the same options) with 2 processes on the CPU, gloo, 2 shards, against one
    process with 2 shards: the same global batches, so the same weights to float32 round-off."""
    args = ["--material", "snow", "--dim", "2", "--epochs", "6", "--batch", "128", "--shards", "2",
            "--eval-samples", "0", "--no-progress", "--checkpoint-every", "3"]
    run = subprocess.run(
        [sys.executable, "-m", "plasticitynet.training.torchrun", "--nproc_per_node", "2", "--master_port", "29537",
         str(TRAIN_PY), *args, "--out", str(tmp_path / "two" / "model.pt")],
        capture_output=True, text=True, timeout=600, env=_environment(), cwd=tmp_path,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    assert "2 processes (2 shards)" in run.stdout
    two = torch.load(tmp_path / "two" / "model.ckpt")
    one = Trainer(_config(tmp_path / "one", material="snow", epochs=6, batch=128, shards=2))
    one.run()
    assert two["step"] == 6 and two["config"]["shards"] == 2
    for name, weight in one.net.state_dict().items():
        scale = weight.abs().max().item()
        assert (weight - two["model"][name]).abs().max().item() <= 1e-5 * scale, name
    for a, b in zip(one.log_rows, two["log_rows"]):
        assert a[1] == pytest.approx(b[1], rel=1e-5)
    # A single process with the default (one shard) draws other batches: the comparison above is not vacuous.
    plain = Trainer(_config(tmp_path / "plain", material="snow", epochs=6, batch=128))
    plain.run()
    assert plain.log_rows[0][1] != pytest.approx(one.log_rows[0][1], rel=1e-3)


def test_two_machines_through_torchrun_match_one_process(tmp_path):
    """Two launchers as on two machines (--nnodes 2, --node_rank 0 and 1, one process each, rendezvous over
    TCP at --master_addr), writing to one shared --out: the same weights as one process with 2 shards."""
    args = ["--material", "sand", "--dim", "2", "--epochs", "4", "--batch", "64", "--shards", "2",
            "--eval-samples", "0", "--no-progress", "--checkpoint-every", "2", "--out", str(tmp_path / "shared" / "model.pt")]
    launchers = [
        subprocess.Popen(
            [sys.executable, "-m", "plasticitynet.training.torchrun", "--nnodes", "2", "--node_rank", str(rank),
             "--nproc_per_node", "1", "--master_addr", "127.0.0.1", "--master_port", "29541", str(TRAIN_PY), *args],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=_environment(), cwd=tmp_path,
        )
        for rank in (0, 1)
    ]
    outputs = [launcher.communicate(timeout=600)[0] for launcher in launchers]
    for launcher, output in zip(launchers, outputs):
        assert launcher.returncode == 0, output[-4000:]
    assert "2 processes (2 shards)" in outputs[0]
    two = torch.load(tmp_path / "shared" / "model.ckpt")
    one = Trainer(_config(tmp_path / "one", material="sand", epochs=4, batch=64, shards=2))
    one.run()
    assert two["step"] == 4
    for name, weight in one.net.state_dict().items():
        assert (weight - two["model"][name]).abs().max().item() <= 1e-5 * weight.abs().max().item(), name


def test_resume_after_a_kill_equals_an_uninterrupted_run(tmp_path):
    """train.py killed (SIGKILL) once a checkpoint is on disk, then resumed: the model of an uninterrupted run."""
    args = ["--material", "sand", "--dim", "2", "--epochs", "300", "--batch", "512", "--eval-samples", "0",
            "--no-progress", "--checkpoint-every", "5", "--threads", "1"]
    killed_dir, full_dir = tmp_path / "killed", tmp_path / "full"
    proc = subprocess.Popen([sys.executable, str(TRAIN_PY), *args, "--out", str(killed_dir / "m.pt")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_environment())
    checkpoint = killed_dir / "m.ckpt"
    deadline = time.monotonic() + 300
    while not checkpoint.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    at_kill = torch.load(checkpoint)["step"]
    assert 0 < at_kill < 300, f"the run was not interrupted (checkpoint at step {at_kill})"
    resumed = subprocess.run([sys.executable, str(TRAIN_PY), *args, "--out", str(killed_dir / "m.pt"), "--resume"],
                             capture_output=True, text=True, timeout=600, env=_environment())
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert f"resuming at step {at_kill}" in resumed.stdout
    full = subprocess.run([sys.executable, str(TRAIN_PY), *args, "--out", str(full_dir / "m.pt")],
                          capture_output=True, text=True, timeout=600, env=_environment())
    assert full.returncode == 0, full.stderr[-3000:]
    a, b = torch.load(killed_dir / "m.ckpt"), torch.load(full_dir / "m.ckpt")
    assert a["step"] == b["step"] == 300
    for name in a["model"]:
        assert torch.equal(a["model"][name], b["model"][name]), name


def test_cosine_schedule_warms_up_then_anneals_to_its_floor(tmp_path):
    trainer = Trainer(_config(tmp_path, epochs=30, batch=16, lr=0.02, schedule="cosine", warmup=5, lr_min_fraction=0.1))
    trainer.run()
    lrs = [r[2] for r in trainer.log_rows]
    assert lrs[:5] == pytest.approx([0.004, 0.008, 0.012, 0.016, 0.02])
    assert lrs[5] == pytest.approx(0.02)
    assert all(a >= b for a, b in zip(lrs[5:], lrs[6:]))  # non-increasing after the warm-up
    assert lrs[-1] == pytest.approx(0.002, rel=0.05)  # near lr_min_fraction x lr at the end
    assert trainer.recipe()["schedule"] == "cosine" and trainer.recipe()["warmup"] == 5


def test_onecycle_rises_and_falls(tmp_path):
    trainer = Trainer(_config(tmp_path, epochs=40, batch=16, schedule="onecycle"))
    trainer.run()
    lrs = [r[2] for r in trainer.log_rows]
    peak = lrs.index(max(lrs))
    assert 0 < peak < 39 and max(lrs) == pytest.approx(0.01) and lrs[-1] < 1e-4 and lrs[0] < 0.002


@pytest.mark.parametrize("kwargs, message", [(dict(schedule="linear"), "schedule"),
                                             (dict(schedule="onecycle", warmup=3), "warmup"),
                                             (dict(lr_min_fraction=2.0), "lr_min_fraction")])
def test_bad_schedules_are_refused(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        _config(tmp_path, **kwargs)


def test_resume_with_another_schedule_or_length_is_refused(tmp_path):
    Trainer(_config(tmp_path, epochs=10, schedule="cosine")).run(stop_at=3)
    with pytest.raises(ValueError, match="schedule"):
        Trainer(_config(tmp_path, epochs=20, schedule="cosine", resume=True))  # its shape depends on the length
    with pytest.raises(ValueError, match="schedule"):
        Trainer(_config(tmp_path, epochs=10, schedule="step", resume=True))
    resumed = Trainer(_config(tmp_path, epochs=10, schedule="cosine", resume=True))
    assert resumed.step == 3


@pytest.mark.parametrize("material, hessian_weight", [("snow", 0.0), ("metal", 0.1), ("metal_nh_rm", 0.0)])
def test_the_weighted_mean_of_the_shards_losses_is_the_whole_batchs_loss(tmp_path, material, hessian_weight):
    """What the all-reduce relies on: the batch's loss (Hessian term and its random directions included)
    is its shards' losses averaged with the weights the tasks report (equal parts for the energies, the
    yielding samples for eq. 13)."""
    trainer = Trainer(_config(tmp_path, material=material, dim=3, batch=64, hessian_weight=hessian_weight))
    whole = trainer.task.loss(5, 4).item()
    parts, weights = [], []
    for k in (0, 2):
        parts.append(trainer.task.loss(5, 4, (k, k + 2)).item())
        weights.append(float(trainer.task.loss_weight))
    assert whole == pytest.approx(sum(w * l for w, l in zip(weights, parts)) / sum(weights), rel=1e-5)


def test_a_complete_run_from_another_device_is_finished_here(tmp_path):
    """A checkpoint written on another device (here: its device_type rewritten to cuda) resumes only if it has
    no steps left: then it is exported and evaluated on this one (how a GPU machine's run is shipped with this
    machine's torch); with steps left it is refused, naming the device."""
    trainer = Trainer(_config(tmp_path, epochs=4))
    trainer.run()
    ckpt, model = trainer.config.paths["checkpoint"], trainer.config.paths["model"]
    state = torch.load(ckpt)
    state["config"]["device_type"] = "cuda"
    torch.save(state, ckpt)
    model.unlink()
    with pytest.raises(ValueError, match="device_type = 'cuda'"):
        Trainer(_config(tmp_path, epochs=6, resume=True))
    resumed = Trainer(_config(tmp_path, epochs=4, resume=True))
    for p, q in zip(trainer.net.parameters(), resumed.net.parameters()):
        assert torch.equal(p, q)
    result = resumed.run()
    assert result.finished and model.is_file()
    assert result.metadata["recipe"]["device"] == "cuda" and result.metadata["recipe"]["exported_on"] == "cpu"
