"""The training loop (paper sec. 5.1, appendix A.1): Adam, learning rate lr decayed by lr_decay every
decay_steps steps (StepLR), one fresh batch of `batch` samples per epoch (= step), the network in float32 (or float64: precision).
The paper's recipe is the default: lr 0.01, x0.95 every 1000 steps, batch 2^16, 20000 epochs.

Outputs beside the model file OUT (default models/{material}_{dim}d.pt):
  OUT                      float64 TorchScript + metadata (export.py), written at the end;
  OUT.csv                  loss log: step, loss, lr, wall seconds (training time, summed over resumes);
  OUT_eval.csv             with eval_every > 0: relative RMS gradient error on 2^14 held-out samples
                           against training step and wall time (energy models);
  OUT_loss.png             the loss curve (log y) and, if logged, the error curve;
  OUT.ckpt                 checkpoint (model, Adam, StepLR, step, RNG state, logs), written atomically
                           every checkpoint_every steps and at the end.
Batch k depends only on (seed, k, the device type, shards) (sampling.py), so a resumed run sees the
batches an uninterrupted run would, and reaches the same weights.

Devices: `device` "cpu", "cuda", "cuda:N" or "auto" (CUDA where available); sampling, targets, loss and
the in-training error curve run there (the curve's held-out samples are drawn on the CPU and moved, so
every device measures the same set; the final evaluation of the exported float64 model runs on the CPU).

Data parallel (torch.distributed): started by `torchrun --nproc-per-node W train.py ...` (or any
launcher that sets RANK / WORLD_SIZE / MASTER_ADDR / MASTER_PORT), each of the W processes draws its
share of the `shards` parts of the global batch (sampling.sample_batch), computes the loss and its
parameter gradient on them, and one all-reduce per step averages the gradients (and the logged loss):
the update is the one a single process makes with the same batch and shards, to round-off. gloo on the
CPU, NCCL on CUDA (one GPU per process, cuda:LOCAL_RANK). DistributedDataParallel itself is not used:
eq. 9 differentiates through an input gradient (double backward), which DDP does not support
(pytorch/pytorch#47562); the explicit all-reduce of the flattened gradient is the same data parallelism.
Rank 0 writes the logs, checkpoints and the model.
"""

from __future__ import annotations

import csv
import math
import os
import shlex
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
import torch.distributed as dist

from . import return_map_net
from .energy import ENERGY_FORMS, energy_loss, network_reference, psi_gradient, stress_directional_derivative
from .frames import principal_frame
from .export import energy_metadata, export_model, return_map_metadata, script_network, sha256_of
from .nets import MLP, REPRESENTATIONS, hidden_widths, make_energy_net, make_mlp, return_map_widths
from .sampling import (
    SAMPLINGS, TRAINING_SAMPLINGS, DeformationBatch, generator_for, sample_batch, sample_return_map_states, sampling_spec, shard_parts,
)
from .parameters import FAMILIES, ParameterSpace
from .targets import ElastoplasticStress, nondimensional_material

#: --material choices: the energies of the four presets and the learned return mapping of metal_nh.
MATERIALS = ("sand", "snow", "metal", "metal_nh", "metal_nh_rm")
RETURN_MAP_MATERIAL = "metal_nh_rm"

#: Fields that must agree between a checkpoint and the run resuming it (epochs may grow).
_RESUME_FIELDS = (
    "material", "dim", "batch", "lr", "lr_decay", "decay_steps", "seed", "sampling", "rm_loss",
    "representation", "hessian_weight", "energy_form", "device_type", "shards", "schedule", "warmup", "precision",
    "hidden", "parametric", "init_from", "wide_fraction",
)

#: What checkpoints written before a field existed were trained with.
_LEGACY_FIELDS = {"representation": "raw", "hessian_weight": 0.0, "energy_form": "eq8", "device_type": "cpu", "shards": 1,
                  "schedule": "step", "warmup": 0, "precision": "float32",
                  "hidden": [], "parametric": False, "init_from": "", "wide_fraction": 0.0}

#: Learning-rate schedules (--schedule): the paper's step decay (lr x lr_decay every decay_steps), cosine
#: annealing from lr to lr_min_fraction x lr over the run, and one-cycle (up to lr and down, torch's
#: OneCycleLR with its default momentum cycling). `warmup` steps ramp the first two linearly from 0.
SCHEDULES = ("step", "cosine", "onecycle")

#: --device choices besides "cuda:N".
DEVICES = ("cpu", "cuda", "auto")

#: Held-out samples of the in-training error curve (eval_every), "eval" stream at this step index
#: (disjoint from the final evaluation, which uses steps 0, 1, ...).
CURVE_SAMPLES = 1 << 14
#: Steps whose inputs a GPU training prepares in one go (EnergyTask._prepare).
PREFETCH_STEPS = 32
CURVE_STEP = 1_000_000


#: The network's floating-point types in training (the exported model is float64 either way).
PRECISIONS = ("float32", "float64")


@dataclass
class TrainConfig:
    material: str
    dim: int
    epochs: int = 20000
    batch: int = 1 << 16
    lr: float = 0.01
    lr_decay: float = 0.95
    decay_steps: int = 1000
    schedule: str = "step"  # SCHEDULES
    warmup: int = 0  # steps of linear warm-up (step and cosine schedules)
    lr_min_fraction: float = 0.01  # cosine: the last step's lr / lr
    seed: int = 0
    sampling: str = "paper"
    wide_fraction: float = 0.0  # energies: share of each batch at twice the deps range (sampling.WIDE_SCALE)
    rm_loss: str = "radius"  # metal_nh_rm: residual of eq. 13 (return_map_net.RESIDUALS)
    representation: str = "principal"  # energies: nets.REPRESENTATIONS
    hessian_weight: float = 0.0  # energies: weight of the Hessian loss (energy.hessian_loss); 0: eq. 9 only
    energy_form: str = "eq8"  # energies: eq. 8 or a rejected form of the paper's Fig. 11 (energy.ENERGY_FORMS)
    out: str = ""  # model path; "" -> models/{material}_{dim}d.pt
    checkpoint_every: int = 500
    resume: bool = False
    return_map: str = ""  # metal_nh: the learned return-map model file
    eval_every: int = 0  # 0: no in-training error curve
    eval_samples: int = 100_000  # final evaluation (0: skip)
    progress: bool = True
    threads: int = 0  # 0: torch's default
    device: str = "cpu"  # DEVICES or "cuda:N"
    hidden: tuple = ()  # hidden layers' widths; (): Table 2's (nets.HIDDEN_WIDTHS)
    precision: str = "float32"  # PRECISIONS: the network's parameters and the loss (samples and targets: float64)
    shards: int = 0  # parts of each batch with their own random stream; 0: the data-parallel world size
    parametric: bool = False  # energies: the material's parameters as inputs (parameters.FAMILIES)
    init_from: str = ""  # energies: a trained model file whose weights start the run (fine-tuning); "": random
    command: str = ""  # the command line, recorded in the metadata

    def __post_init__(self):
        if self.material not in MATERIALS:
            raise ValueError(f"material = {self.material!r}: expected one of {', '.join(MATERIALS)}")
        if self.dim not in (2, 3):
            raise ValueError(f"dim = {self.dim!r}: expected 2 or 3")
        for name in ("epochs", "batch", "decay_steps", "checkpoint_every"):
            if int(getattr(self, name)) <= 0:
                raise ValueError(f"{name} = {getattr(self, name)!r}: must be > 0")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise ValueError(f"lr = {self.lr!r}: must be finite and > 0")
        if not (0 < self.lr_decay <= 1):
            raise ValueError(f"lr_decay = {self.lr_decay!r}: must be in (0, 1]")
        if self.seed < 0:
            raise ValueError(f"seed = {self.seed!r}: must be >= 0")
        self.hidden = tuple(int(w) for w in self.hidden)
        hidden_widths(self.dim, self.hidden)  # checks them
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision = {self.precision!r}: expected one of {', '.join(PRECISIONS)}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"schedule = {self.schedule!r}: expected one of {', '.join(SCHEDULES)}")
        if self.warmup < 0 or (self.warmup and self.schedule == "onecycle"):
            raise ValueError(f"warmup = {self.warmup!r}: must be >= 0, and 0 with the onecycle schedule (it has its own)")
        if not (0 <= self.lr_min_fraction <= 1):
            raise ValueError(f"lr_min_fraction = {self.lr_min_fraction!r}: must be in [0, 1]")
        if self.sampling not in TRAINING_SAMPLINGS:
            raise ValueError(f"sampling = {self.sampling!r}: expected one of {', '.join(TRAINING_SAMPLINGS)}")
        if not 0 <= self.wide_fraction < 1:
            raise ValueError(f"wide_fraction = {self.wide_fraction!r}: must be in [0, 1)")
        if self.wide_fraction and self.material == RETURN_MAP_MATERIAL:
            raise ValueError(f"wide_fraction applies to energies, not {RETURN_MAP_MATERIAL}")
        if self.rm_loss not in return_map_net.RESIDUALS:
            raise ValueError(f"rm_loss = {self.rm_loss!r}: expected one of {', '.join(return_map_net.RESIDUALS)}")
        if self.representation not in REPRESENTATIONS:
            raise ValueError(
                f"representation = {self.representation!r}: expected one of {', '.join(REPRESENTATIONS)}"
            )
        if self.energy_form not in ENERGY_FORMS:
            raise ValueError(f"energy_form = {self.energy_form!r}: expected one of {', '.join(ENERGY_FORMS)}")
        if self.material == RETURN_MAP_MATERIAL and self.energy_form != "eq8":
            raise ValueError(f"energy_form = {self.energy_form!r} applies to energies, not {RETURN_MAP_MATERIAL}")
        if not (math.isfinite(self.hessian_weight) and self.hessian_weight >= 0):
            raise ValueError(f"hessian_weight = {self.hessian_weight!r}: must be finite and >= 0")
        if self.eval_every < 0 or self.eval_samples < 0:
            raise ValueError("eval_every and eval_samples must be >= 0")
        if self.material == "metal_nh" and not self.return_map:
            raise ValueError("material metal_nh: return_map (the learned return-map model file) is required")
        if self.device not in DEVICES and not _is_cuda_index(self.device):
            raise ValueError(f"device = {self.device!r}: expected cpu, cuda, cuda:N or auto")
        if self.shards < 0:
            raise ValueError(f"shards = {self.shards!r}: must be >= 0 (0: one per process)")
        if self.parametric and self.material not in FAMILIES:
            raise ValueError(f"material = {self.material!r}: no parametric family (parametric models exist for "
                             f"{', '.join(FAMILIES)})")
        if not self.out:
            stem = f"{self.material}_param" if self.parametric else self.material
            self.out = str(Path("models") / f"{stem}_{self.dim}d.pt")

    @property
    def paths(self) -> dict:
        out = Path(self.out)
        return {
            "model": out,
            "log": out.with_suffix(".csv"),
            "eval_log": out.with_name(out.stem + "_eval.csv"),
            "plot": out.with_name(out.stem + "_loss.png"),
            "checkpoint": out.with_suffix(".ckpt"),
        }


def _is_cuda_index(device: str) -> bool:
    head, _, index = device.partition(":")
    return head == "cuda" and index.isdigit()


def resolve_device(name: str, local_rank: int = 0) -> torch.device:
    """The torch.device of a --device value: "auto" is CUDA where available; "cuda" in a data-parallel
    run is the process's own GPU, cuda:LOCAL_RANK. A CUDA device without CUDA is an error naming it."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise ValueError(f"device = {name!r}: this torch ({torch.__version__}) sees no CUDA device")
    device = torch.device(f"cuda:{local_rank}") if name == "cuda" else torch.device(name)
    if device.index is not None and device.index >= torch.cuda.device_count():
        raise ValueError(f"device = {device}: only {torch.cuda.device_count()} CUDA device(s) visible")
    return device


@dataclass(frozen=True)
class Parallel:
    """This process's place in a data-parallel run (world 1: a single process)."""

    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @staticmethod
    def from_environment() -> "Parallel":
        """RANK / WORLD_SIZE / LOCAL_RANK as torchrun sets them (absent: a single process)."""
        try:
            world = int(os.environ.get("WORLD_SIZE", "1"))
            rank = int(os.environ.get("RANK", "0"))
            local = int(os.environ.get("LOCAL_RANK", "0"))
        except ValueError as err:
            raise ValueError(f"RANK / WORLD_SIZE / LOCAL_RANK must be integers ({err})") from None
        if world < 1 or not 0 <= rank < world:
            raise ValueError(f"RANK = {rank}, WORLD_SIZE = {world}: expected 0 <= RANK < WORLD_SIZE")
        return Parallel(rank, world, local)

    @property
    def leader(self) -> bool:
        return self.rank == 0


# --- tasks: what is trained -------------------------------------------------------------------------
def _place(net: torch.nn.Module, config: TrainConfig, device: torch.device) -> tuple[torch.dtype, torch.jit.ScriptModule]:
    """Moves `net` to `device` in config.precision and compiles it now: (dtype, the ScriptModule, which shares
    net's parameters and is what the trainer exports at the end)."""
    dtype = getattr(torch, config.precision)
    net.to(device=device, dtype=dtype)
    return dtype, torch.jit.script(net)


class EnergyTask:
    """The energy MLP of eq. 8, trained with the loss of eq. 9."""

    kind = "energy"

    def __init__(self, config: TrainConfig, device: torch.device = torch.device("cpu")):
        self.config = config
        self.device = device
        self.material = nondimensional_material(config.material, config.dim)
        self.spec = sampling_spec(self.material, config.sampling).with_(wide_fraction=config.wide_fraction)
        self.return_map = None
        self.return_map_info = None
        if config.material == "metal_nh":
            from ..model import LearnedReturnMap, load_model

            rm = load_model(config.return_map)
            if not isinstance(rm, LearnedReturnMap) or rm.dim != config.dim:
                raise ValueError(f"{config.return_map}: not a {config.dim}D return-map model")
            rm.network.to(device)
            self.return_map = rm
            rel = os.path.relpath(Path(config.return_map).resolve(), Path(config.out).resolve().parent)
            self.return_map_info = {"type": "learned", "file": rel, "sha256": sha256_of(config.return_map)}
        self.parameters = ParameterSpace.family(config.material, self.material) if config.parametric else None
        if self.parameters is not None:
            self.spec = self.spec.with_(parameters=self.parameters.ranges)
        self.stress = ElastoplasticStress(self.material, self.return_map, self.parameters)
        self.net = make_energy_net(config.dim, self.spec.has_hardening, config.representation, config.seed, config.hidden,
                                   len(self.parameters or ()))
        self.dtype, self.scripted = _place(self.net, config, device)
        self.loss_parts: dict = {}  # the last step's loss terms (energy.energy_loss)
        # Steps whose batches, targets and frames are prepared together: on a GPU a step is bound by kernel
        # launches (issue 32's profile), and these are most of them; on the CPU one at a time.
        self.prefetch_steps = PREFETCH_STEPS if device.type == "cuda" else 1
        self._prepared: dict = {}

    def _tail(self, b: DeformationBatch):
        """The network's inputs after F0: h (with hardening), then a parametric model's normalised parameters
        (B, K); None when there are none."""
        parts = [b.h.reshape(-1, 1)] if self.spec.has_hardening else []
        if self.parameters is not None:
            parts.append(self.parameters.inputs(b.p))
        return torch.cat(parts, dim=1) if parts else None

    def loss(self, step: int, shards: int = 1, shard_range: tuple[int, int] | None = None) -> torch.Tensor:
        """Eq. 9 on batch `step` (the parts shard_range of its `shards`): samples and targets in float64
        (no grad), the network in config.precision."""
        key = (step, shards, shard_range)
        if key not in self._prepared:
            self._prepared = self._prepare(step, shards, shard_range)
        b = self._prepared.pop(key)
        self.loss_weight = float(len(b["F"]))  # the loss is a mean over these samples
        return energy_loss(
            self.net, b["F"], b["F0"], b["h"], b["P"], b["P0"], self.config.hessian_weight, b["v"], b["Sv"],
            self.loss_parts, self.config.energy_form, b["frame"],
        )

    def _prepare(self, step: int, shards: int, shard_range) -> dict:
        """The inputs of the loss for steps step .. step + prefetch_steps - 1: each step's batch drawn from its
        own streams as always, then the targets, the Hessian directions' targets and the principal frames
        computed for all of them at once (row by row, so a step's numbers do not depend on the grouping)."""
        cfg, d = self.config, self.config.dim
        steps = range(step, step + self.prefetch_steps)
        batches = [
            sample_batch(self.spec, cfg.batch, cfg.seed, s, device=self.device, shards=shards, shard_range=shard_range)
            for s in steps
        ]
        sizes = [len(b) for b in batches]
        b = DeformationBatch.cat(batches)
        with torch.no_grad():
            P = self.stress.from_factors(b.U, b.Sigma, b.V, b.h, b.p).to(self.dtype)
            P0 = self.stress.from_factors(b.U0, b.Sigma0, b.V0, b.h, b.p).to(self.dtype)
        bn = b.to(self.dtype)
        v = Sv = None
        if cfg.hessian_weight > 0.0:
            size, parts = shard_parts(cfg.batch, shards, shard_range)  # a direction stream per part
            v = torch.cat([
                torch.randn(size, d, d, dtype=torch.float64, device=self.device,
                            generator=generator_for(cfg.seed, s, "hessian", self.device, k))
                for s in steps for k in parts
            ])
            with torch.no_grad():
                Sv = stress_directional_derivative(self.stress, b.F, b.h, v, p=b.p if self.parameters else None)
                Sv = Sv.to(self.dtype)
            v = v.to(self.dtype)
        frame = (None,) * 3
        if self.net.representation == "principal":
            frame = principal_frame(network_reference(cfg.energy_form, bn.F0))
        fields = {"F": bn.F, "F0": bn.F0, "h": self._tail(bn), "P": P, "P0": P0,
                  "v": v, "Sv": Sv, "U": frame[0], "Sigma0": frame[1], "V": frame[2]}
        split = {k: (None,) * len(sizes) if t is None else t.split(sizes) for k, t in fields.items()}
        prepared = {}
        for i, s in enumerate(steps):
            one = {k: parts[i] for k, parts in split.items()}
            one["frame"] = None if one["U"] is None else (one.pop("U"), one.pop("Sigma0"), one.pop("V"))
            prepared[(s, shards, shard_range)] = one
        return prepared

    def curve_error(self) -> dict:
        """Relative RMS gradient error of the training net on CURVE_SAMPLES held-out samples, per sampling."""
        out = {}
        for s in SAMPLINGS:
            b = sample_batch(self.spec.with_(sampling=s), CURVE_SAMPLES, self.config.seed, CURVE_STEP, "eval")
            b = b.to(device=self.device)  # drawn on the CPU: the same held-out set on every device
            with torch.no_grad():
                P = self.stress.from_factors(b.U, b.Sigma, b.V, b.h, b.p).to(self.dtype)
                P0 = self.stress.from_factors(b.U0, b.Sigma0, b.V0, b.h, b.p).to(self.dtype)
            bn = b.to(self.dtype)
            g = psi_gradient(self.net, bn.F, bn.F0, self._tail(bn), P0, form=self.config.energy_form).detach()
            out[s] = float(((g - P) ** 2).sum() / (P**2).sum()) ** 0.5
        return out

    def metadata(self, recipe: dict, errors=None) -> dict:
        return energy_metadata(
            self.material, self.net, self.spec.has_hardening, recipe, errors, self.return_map_info,
            self.config.energy_form, self.parameters.to_metadata() if self.parameters else None,
        )

    def in_memory_model(self, metadata: dict):
        from ..model import LearnedEnergy

        return LearnedEnergy(script_network(self.scripted), metadata, return_map=self.return_map)


class ReturnMapTask:
    """The dgamma MLP of eq. 12, trained with the loss of eq. 13 (return_map_net.py)."""

    kind = "return_map"

    def __init__(self, config: TrainConfig, device: torch.device = torch.device("cpu")):
        self.config = config
        self.device = device
        self.material = nondimensional_material("metal_nh", config.dim)
        self.net = make_mlp(return_map_widths(config.dim, config.hidden), config.seed)
        self.dtype, self.scripted = _place(self.net, config, device)

    def loss(self, step: int, shards: int = 1, shard_range: tuple[int, int] | None = None) -> torch.Tensor:
        Sigma, h = sample_return_map_states(
            self.config.dim, self.config.batch, self.config.seed, step, device=self.device, shards=shards,
            shard_range=shard_range,
        )
        Sigma, h = Sigma.to(self.dtype), h.to(self.dtype)
        # Eq. 13 is a mean over the yielding samples: their number weighs this part's loss across processes.
        self.loss_weight = return_map_net.yielding(self.material, Sigma, h).sum()
        return return_map_net.return_map_loss(self.net, self.material, Sigma, h, self.config.rm_loss)

    def curve_error(self) -> dict:
        Sigma, h = sample_return_map_states(self.config.dim, CURVE_SAMPLES, self.config.seed, CURVE_STEP, "eval")
        Sigma, h = Sigma.to(self.device), h.to(self.device)
        with torch.no_grad():
            loss = return_map_net.return_map_loss(
                self.net, self.material, Sigma.to(self.dtype), h.to(self.dtype), self.config.rm_loss
            )
        return {"heldout_loss": float(loss)}

    def metadata(self, recipe: dict, errors=None) -> dict:
        return return_map_metadata(self.material, self.net, recipe, errors)

    def in_memory_model(self, metadata: dict):
        from ..model import LearnedReturnMap

        return LearnedReturnMap(script_network(self.scripted), metadata)


def make_task(config: TrainConfig, device: torch.device = torch.device("cpu")):
    task = ReturnMapTask if config.material == RETURN_MAP_MATERIAL else EnergyTask
    return task(config, device)


# --- files --------------------------------------------------------------------------------------------
def _atomic_torch_save(obj, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def _write_csv(path: Path, header, rows) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)
    os.replace(tmp, path)


LOG_HEADER = ("step", "loss", "lr", "wall_seconds")


def plot_curves(log_rows, eval_rows, eval_header, path: Path, title: str) -> None:
    """Loss against step (log y); with an error log, the held-out error against wall time beside it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = 2 if eval_rows else 1
    fig, axes = plt.subplots(1, panels, figsize=(6 * panels, 4), squeeze=False)
    ax = axes[0, 0]
    steps = [r[0] for r in log_rows]
    ax.plot(steps, [r[1] for r in log_rows], lw=0.6, color="#1f77b4")
    ax.set_yscale("log")
    ax.set_xlabel("step (epoch)")
    ax.set_ylabel("training loss")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    if eval_rows:
        ax = axes[0, 1]
        for j, name in enumerate(eval_header[3:], start=3):
            ax.plot([r[2] / 60 for r in eval_rows], [r[j] for r in eval_rows], marker=".", label=name)
        ax.set_yscale("log")
        ax.set_xlabel("training wall time (min)")
        ax.set_ylabel("held-out loss (eq. 13)" if eval_header[3] == "heldout_loss" else "held-out relative RMS error")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)


# --- the loop ------------------------------------------------------------------------------------------
@dataclass
class TrainResult:
    paths: dict
    steps: int
    final_loss: float
    wall_seconds: float
    errors: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    finished: bool = True


def initialise_from(task, path: str) -> dict:
    """Copies the weights of the trained energy at `path` into `task`'s network (fine-tuning: the run then
    trains them with a fresh optimizer and schedule). The model must be the same kind of network: material,
    dimension, input representation, energy form, parametric family and layer widths; ValueError naming the
    file and the field that differs. Returns {"file": its name, "sha256"} for the recipe."""
    from ..model import read_model_file

    if task.kind == "return_map":
        raise ValueError(f"init_from = {path!r}: fine-tuning applies to energies, not the return-map network")
    network, meta = read_model_file(path)
    cfg = task.config
    material = (meta.get("material") or {}).get("name")
    expected = {
        "kind": ("energy", meta.get("kind")),
        "material": (cfg.material, material),
        "dim": (cfg.dim, meta.get("dim")),
        "representation": (cfg.representation, meta.get("representation", "raw")),
        "energy_form": (cfg.energy_form, meta.get("energy_form", "eq8")),
        "parametric": (bool(cfg.parametric), bool(meta.get("parameters"))),
    }
    for field_name, (want, got) in expected.items():
        if want != got:
            raise ValueError(f"{path}: its {field_name} is {got!r}, this run trains {want!r}")
    ours = {k: tuple(v.shape) for k, v in task.net.state_dict().items()}
    theirs = {k: tuple(v.shape) for k, v in network.state_dict().items()}
    if ours != theirs:
        raise ValueError(
            f"{path}: its layer widths {meta.get('widths')} differ from this run's {task.net.widths} (--hidden)"
        )
    with torch.no_grad():
        task.net.load_state_dict({k: v.to(task.dtype) for k, v in network.state_dict().items()})
    return {"file": Path(path).name, "sha256": sha256_of(path)}


def make_scheduler(optimizer: torch.optim.Optimizer, config: TrainConfig):
    """The learning-rate schedule of `config` (SCHEDULES), stepped once per training step."""
    if config.schedule == "onecycle":
        return torch.optim.lr_scheduler.OneCycleLR(optimizer, max_lr=config.lr, total_steps=config.epochs)
    if config.schedule == "step" and config.warmup == 0:  # the paper's, as in every shipped model's checkpoint
        return torch.optim.lr_scheduler.StepLR(optimizer, step_size=config.decay_steps, gamma=config.lr_decay)
    warmup, total, floor = config.warmup, config.epochs, config.lr_min_fraction

    def factor(step: int) -> float:
        ramp = min(1.0, (step + 1) / warmup) if warmup else 1.0
        if config.schedule == "step":
            return ramp * config.lr_decay ** (step // config.decay_steps)
        t = min(1.0, max(0, step - warmup) / max(1, total - warmup))
        return ramp * (floor + (1.0 - floor) * 0.5 * (1.0 + math.cos(math.pi * t)))

    return torch.optim.lr_scheduler.LambdaLR(optimizer, factor)


class Trainer:
    def __init__(self, config: TrainConfig, parallel: Parallel | None = None):
        self.config = config
        self.parallel = parallel if parallel is not None else Parallel.from_environment()
        if config.threads:
            torch.set_num_threads(config.threads)
        self.device = resolve_device(config.device, self.parallel.local_rank)
        world = self.parallel.world
        shards = config.shards or world
        if shards % world or config.batch % shards:
            raise ValueError(
                f"shards = {shards}: must be a multiple of the {world} process(es) and divide the batch {config.batch}"
            )
        self.shards = shards
        per_rank = shards // world
        self.shard_range = (self.parallel.rank * per_rank, (self.parallel.rank + 1) * per_rank)
        if world > 1 and not dist.is_initialized():
            dist.init_process_group(backend="nccl" if self.device.type == "cuda" else "gloo")
            self._owns_process_group = True
        else:
            self._owns_process_group = False
        self.task = make_task(config, self.device)
        self.net: MLP = self.task.net
        self.init_from = None  # {"file", "sha256"} of the model the weights started from
        if config.init_from:
            self.init_from = initialise_from(self.task, config.init_from)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=config.lr)
        self.scheduler = make_scheduler(self.optimizer, config)
        self.step = 0  # number of completed steps
        self.trained_device_type = self.device.type  # a checkpoint's, when resumed
        self.wall = 0.0  # training seconds, summed over sessions
        self.log_rows: list[tuple] = []
        self.eval_rows: list[tuple] = []
        self.eval_header: tuple = ()
        if config.resume:
            self._load_checkpoint()

    def _resume_value(self, key: str):
        if key == "init_from":  # the starting weights, by content: the path may differ between machines
            return self.init_from["sha256"] if self.init_from else ""
        if key == "device_type":
            return self.device.type
        if key == "shards":
            return self.shards
        if key == "hidden":
            return list(self.config.hidden)
        if key == "schedule" and self.config.schedule != "step":  # its shape depends on the run's length
            return f"{self.config.schedule}:{self.config.epochs}:{self.config.lr_min_fraction}"
        return getattr(self.config, key)

    # checkpoints
    def _state(self) -> dict:
        return {
            "config": {k: self._resume_value(k) for k in _RESUME_FIELDS},
            "model": self.net.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "step": self.step,
            "wall_seconds": self.wall,
            "torch_rng_state": torch.get_rng_state(),
            "log_rows": self.log_rows,
            "eval_rows": self.eval_rows,
            "eval_header": self.eval_header,
        }

    def save_checkpoint(self) -> Path:
        path = self.config.paths["checkpoint"]
        _atomic_torch_save(self._state(), path)
        return path

    def _load_checkpoint(self) -> None:
        path = self.config.paths["checkpoint"]
        if not path.is_file():
            raise ValueError(f"{path}: no checkpoint to resume from")
        try:
            state = torch.load(path, map_location=self.device)
        except Exception as err:
            raise ValueError(f"{path}: unreadable checkpoint ({err})") from None
        # The device decides the random streams of the batches to come: a run that has none left (trained on a
        # GPU machine, say) may be finished -- exported and evaluated -- on another device.
        complete = int(state["step"]) >= self.config.epochs
        self.trained_device_type = state["config"].get("device_type", _LEGACY_FIELDS["device_type"])
        for key in _RESUME_FIELDS:
            saved = state["config"].get(key, _LEGACY_FIELDS.get(key))
            if key == "device_type" and complete:
                continue
            if saved != self._resume_value(key):
                raise ValueError(f"{path}: checkpoint has {key} = {saved!r}, this run {self._resume_value(key)!r}")
        self.net.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.scheduler.load_state_dict(state["scheduler"])
        self.step = int(state["step"])
        self.wall = float(state["wall_seconds"])
        torch.set_rng_state(state["torch_rng_state"].cpu())
        self.log_rows = [tuple(r) for r in state["log_rows"]]
        self.eval_rows = [tuple(r) for r in state["eval_rows"]]
        self.eval_header = tuple(state["eval_header"])

    def _average_across_processes(self, loss: torch.Tensor) -> torch.Tensor:
        """All-reduce the parameter gradients and the loss in one flat buffer, each process's weighted by
        the number of samples its mean is over (task.loss_weight: its part of the batch, or its yielding
        samples for eq. 13): the gradient of the global batch's loss. Returns the global loss."""
        params = [p for p in self.net.parameters() if p.grad is not None]
        dtype = params[0].grad.dtype
        w = torch.as_tensor(self.task.loss_weight, dtype=dtype, device=self.device).reshape(1)
        flat = torch.cat([p.grad.reshape(-1) * w for p in params] + [loss.detach().reshape(1).to(dtype) * w, w])
        dist.all_reduce(flat)
        total = flat[-1]
        flat = flat[:-1] / total if total > 0 else flat[:-1] * 0.0
        offset = 0
        for p in params:
            n = p.grad.numel()
            p.grad.copy_(flat[offset : offset + n].view_as(p.grad))
            offset += n
        return flat[-1]

    # training
    def _curve_point(self) -> None:
        errors = self.task.curve_error()
        if not self.eval_header:
            self.eval_header = ("step", "loss", "wall_seconds", *errors)
        loss = self.log_rows[-1][1] if self.log_rows else float("nan")
        self.eval_rows.append((self.step, loss, self.wall, *errors.values()))
        _write_csv(self.config.paths["eval_log"], self.eval_header, self.eval_rows)

    def run(self, stop_at: int | None = None) -> TrainResult:
        """Train up to config.epochs steps (or stop_at, as if interrupted there: checkpoint written, nothing
        exported), then export, evaluate and plot."""
        cfg = self.config
        paths = cfg.paths
        end = cfg.epochs if stop_at is None else min(stop_at, cfg.epochs)
        leader = self.parallel.leader
        log = writer = None
        if leader:
            _write_csv(paths["log"], LOG_HEADER, self.log_rows)  # (re)start the log at the checkpoint
            log = open(paths["log"], "a", newline="", buffering=1)  # line-buffered: the log can be watched live
            writer = csv.writer(log, lineterminator="\n")
        bar = None
        if cfg.progress and leader:
            from tqdm import tqdm

            bar = tqdm(total=cfg.epochs, initial=self.step, desc=f"{cfg.material} {cfg.dim}D", unit="step")
        try:
            self.net.train()
            while self.step < end:
                t0 = time.perf_counter()
                lr = self.optimizer.param_groups[0]["lr"]
                loss = self.task.loss(self.step, self.shards, self.shard_range)
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                if self.parallel.world > 1:
                    loss = self._average_across_processes(loss)
                self.optimizer.step()
                self.scheduler.step()
                self.step += 1
                self.wall += time.perf_counter() - t0
                value = float(loss.detach())
                if not math.isfinite(value):
                    raise FloatingPointError(f"loss is {value} at step {self.step}")
                row = (self.step, value, lr, round(self.wall, 3))
                self.log_rows.append(row)
                if writer is not None:
                    writer.writerow(row)
                if bar is not None:
                    bar.update(1)
                    if self.step % 10 == 0 or self.step == end:
                        bar.set_postfix(loss=f"{value:.3e}", lr=f"{lr:.2e}")
                if leader and cfg.eval_every and (self.step % cfg.eval_every == 0 or self.step == cfg.epochs):
                    self._curve_point()
                if leader and (self.step % cfg.checkpoint_every == 0 or self.step == end):
                    log.flush()
                    self.save_checkpoint()
        finally:
            if log is not None:
                log.close()
            if bar is not None:
                bar.close()
        final_loss = self.log_rows[-1][1] if self.log_rows else float("nan")
        if self.step < cfg.epochs or not leader:
            self._close_process_group()
            return TrainResult(paths, self.step, final_loss, self.wall, finished=self.step >= cfg.epochs)
        result = self.finish()
        self._close_process_group()
        return result

    def _close_process_group(self) -> None:
        if self._owns_process_group and dist.is_initialized():
            dist.destroy_process_group()
            self._owns_process_group = False

    def recipe(self) -> dict:
        cfg = self.config
        recipe = {
            "epochs": self.step,
            "batch": cfg.batch,
            "lr": cfg.lr,
            "decay": cfg.lr_decay,
            "decay_steps": cfg.decay_steps,
            "schedule": cfg.schedule,
            "warmup": cfg.warmup,
            "sampling": cfg.sampling,
            "seed": cfg.seed,
            "wall_seconds": round(self.wall, 1),
            "optimizer": "adam",
            "dtype": cfg.precision,
            "threads": torch.get_num_threads(),
            "device": str(self.device),
            "processes": self.parallel.world,
            "shards": self.shards,
            "final_loss": self.log_rows[-1][1] if self.log_rows else None,
        }
        if hasattr(self.task, "spec"):
            recipe["distribution"] = self.task.spec.to_dict()
            recipe["representation"] = cfg.representation
            recipe["hessian_weight"] = cfg.hessian_weight
            recipe["energy_form"] = cfg.energy_form
        else:  # the return-map net
            recipe["distribution"] = {"eps_range": [-1.0, 1.0], "h_range": [0.0, 1.0]}
            recipe["rm_loss"] = cfg.rm_loss
        if self.init_from:
            recipe["init_from"] = self.init_from
        if cfg.command:
            recipe["command"] = cfg.command
        if self.trained_device_type != self.device.type:  # trained elsewhere, finished here
            recipe["device"] = self.trained_device_type
            recipe["exported_on"] = str(self.device)
            if cfg.command:
                words = shlex.split(cfg.command)
                if "--device" in words:
                    words[words.index("--device") + 1] = self.trained_device_type
                else:
                    words += ["--device", self.trained_device_type]
                recipe["command"] = shlex.join(words)
        return recipe

    def finish(self) -> TrainResult:
        """Evaluate the float64 model, export it with its errors, plot the curves."""
        from .held_out import evaluate

        cfg = self.config
        paths = cfg.paths
        self.net.eval()
        self.net.to("cpu")  # the evaluation and the export run on the CPU (float64 TorchScript)
        if getattr(self.task, "return_map", None) is not None:
            self.task.return_map.network.to("cpu")
        recipe = self.recipe()
        errors = {}
        if cfg.eval_samples:
            errors = evaluate(self.task.in_memory_model(self.task.metadata(recipe)), cfg.eval_samples)
        metadata = self.task.metadata(recipe, errors)
        # The network compiled when training started (same parameters): a model that cannot be scripted
        # fails before training rather than after it, and editing the package's source during a long run
        # does not break its export (compiling reads the class's source file).
        export_model(paths["model"], self.task.scripted, metadata)
        plot_curves(self.log_rows, self.eval_rows, self.eval_header, paths["plot"], f"{cfg.material} {cfg.dim}D")
        final_loss = self.log_rows[-1][1] if self.log_rows else float("nan")
        return TrainResult(paths, self.step, final_loss, self.wall, errors, metadata, finished=True)


def train(config: TrainConfig, stop_at: int | None = None) -> TrainResult:
    return Trainer(config).run(stop_at)


__all__ = ["MATERIALS", "TrainConfig", "Trainer", "TrainResult", "train", "make_task", "plot_curves"]
