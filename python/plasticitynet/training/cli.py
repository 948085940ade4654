"""Command line of the repository's train.py:

    python train.py --material {sand,snow,metal,metal_nh,metal_nh_rm} --dim {2,3}
                    [--epochs --batch --lr --lr-decay --decay-steps --seed --sampling --out --resume
                     --return-map FILE --checkpoint-every N --eval-every N --eval-samples N --threads N
                     --device cpu|cuda|cuda:N|auto --precision float32|float64 --hidden W.. --shards N
                     --parametric]

Several processes (data parallel, torch.distributed): torchrun --nproc-per-node W train.py ... (gloo on
the CPU, NCCL with --device cuda, one GPU per process); across machines, torchrun's --nnodes /
--rdzv-endpoint, with --out on a filesystem every machine sees.

Defaults are the paper's recipe (Adam, lr 0.01 x0.95 every 1000 steps, batch 2^16, 20000 epochs).
metal_nh_rm trains the learned return mapping of metal_nh; metal_nh trains the energy whose target
stress uses that learned mapping (--return-map, default models/metal_nh_rm_{dim}d.pt). Bad arguments
exit with code 2 and a message.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from pathlib import Path

from .energy import ENERGY_FORMS
from .held_out import format_errors
from .nets import REPRESENTATIONS
from .return_map_net import RESIDUALS
from .sampling import TRAINING_SAMPLINGS, WIDE_SCALE
from .trainer import MATERIALS, PRECISIONS, RETURN_MAP_MATERIAL, SCHEDULES, TrainConfig, Trainer


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{value} must be > 0")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} must be >= 0")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"{value} must be finite and > 0")
    return value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be finite and >= 0, got {text}")
    return value


def _decay(text: str) -> float:
    value = _positive_float(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"{value} must be in (0, 1]")
    return value


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be in [0, 1)")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="train.py",
        description="Train a PlasticityNet energy (or the learned metal_nh return mapping), export it as TorchScript.",
    )
    p.add_argument("--material", required=True, choices=MATERIALS, help="what to train")
    p.add_argument("--dim", required=True, type=int, choices=(2, 3), help="dimension")
    p.add_argument("--epochs", type=_positive_int, default=20000, help="training steps, one fresh batch each (20000)")
    p.add_argument("--batch", type=_positive_int, default=1 << 16, help="samples per step (65536)")
    p.add_argument("--lr", type=_positive_float, default=0.01, help="Adam learning rate (0.01)")
    p.add_argument("--lr-decay", type=_decay, default=0.95, help="learning-rate factor per decay period (0.95)")
    p.add_argument("--decay-steps", type=_positive_int, default=1000, help="steps per decay period (1000)")
    p.add_argument(
        "--wide-fraction", type=_fraction, default=0.0,
        help="share of each batch drawn with twice the perturbation range deps, where a large step's iterates go "
        "(energies; 0)",
    )
    p.add_argument(
        "--schedule",
        choices=SCHEDULES,
        default="step",
        help="learning-rate schedule: step (the paper's: x lr-decay every decay-steps), cosine (to 1%% of lr at the "
        "last step), onecycle (up to lr and down) (step)",
    )
    p.add_argument("--warmup", type=_non_negative_int, default=0, help="steps of linear lr warm-up (step, cosine) (0)")
    p.add_argument("--seed", type=_non_negative_int, default=0, help="seed of the initialisation and batches (0)")
    p.add_argument("--sampling", choices=TRAINING_SAMPLINGS, default="paper", help="(F, F0) distribution: paper, near, or mixed (half each) (paper)")
    p.add_argument(
        "--rm-loss",
        choices=RESIDUALS,
        default="radius",
        help="metal_nh_rm: the yield residual of eq. 13, radius = ||dev tau||/(2 mu) - h, or paper = y/(2 mu)^2 (radius)",
    )
    p.add_argument(
        "--representation",
        choices=REPRESENTATIONS,
        default="principal",
        help="energies: the MLP's input, principal = [U^T F V, Sigma0, h] in the frame of F0 = U Sigma0 V^T "
        "(frame-indifferent), raw = [F, F0, h] as in the paper (principal)",
    )
    p.add_argument(
        "--hessian-weight",
        type=_non_negative_float,
        default=0.0,
        help="energies: weight of the loss on Hess Psi against sym(d Ptilde/dF) beside eq. 9 (0: off)",
    )
    p.add_argument(
        "--energy-form",
        choices=ENERGY_FORMS,
        default="eq8",
        help="energies: eq8 (the paper's eq. 8) or a form the paper rejected in sec. 5.2 / Fig. 11, for that "
        "ablation: local_identity = N(F, F0) - grad N(I, F0) : F, global_identity = N(F) - grad N(I) : F, "
        "global = N(F) (eq8)",
    )
    p.add_argument("--out", default=None, help="model file (default models/{material}_{dim}d.pt)")
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint OUT.ckpt")
    p.add_argument(
        "--return-map", default=None, help="metal_nh: the learned return-map model (models/metal_nh_rm_{dim}d.pt)"
    )
    p.add_argument("--checkpoint-every", type=_positive_int, default=500, help="steps between checkpoints (500)")
    p.add_argument(
        "--eval-every", type=_non_negative_int, default=0, help="steps between held-out error points (0: off)"
    )
    p.add_argument(
        "--eval-samples", type=_non_negative_int, default=100_000, help="final held-out samples (1e5; 0: skip)"
    )
    p.add_argument("--threads", type=_non_negative_int, default=0, help="torch threads (0: torch's default)")
    p.add_argument(
        "--device",
        default="cpu",
        help="where to train: cpu, cuda (under torchrun: each process's own GPU), cuda:N, or auto (CUDA where "
        "available) (cpu)",
    )
    p.add_argument(
        "--hidden",
        type=_positive_int,
        nargs="+",
        default=[],
        metavar="W",
        help="the hidden layers' widths, e.g. 64 64 64 64 (default: Table 2's, 32 32 32 in 2D and 64 64 64 in 3D; "
        "the simulator's fused kernel has Table 2's and a few wider shapes compiled)",
    )
    p.add_argument(
        "--precision",
        choices=PRECISIONS,
        default="float32",
        help="the network's floating-point type in training (samples and targets are float64, the exported "
        "model float64 either way) (float32)",
    )
    p.add_argument(
        "--shards",
        type=_non_negative_int,
        default=0,
        help="parts of each batch with their own random stream, a multiple of the process count; a run with "
        "the same --shards draws the same batches on any number of processes (0: one per process)",
    )
    p.add_argument(
        "--parametric",
        action="store_true",
        help="a parametric energy: the material's parameters (sand: friction angle, nu; snow: friction angle, xi, "
        "beta, nu; metal: hardening coefficient, nu) as network inputs over the ranges of docs/physics.md, one "
        "model for the family (default out: models/<material>_param_<dim>d.pt)",
    )
    p.add_argument(
        "--init-from",
        default=None,
        metavar="MODEL",
        help="energies: start from this trained model's weights instead of a random initialisation (fine-tuning "
        "with a fresh optimizer and schedule); it must have the run's material, dimension, widths and inputs",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv=None, root: str | Path | None = None) -> int:
    """Parse, train, export, print. `root`: folder the default paths are relative to (the repository)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    base = Path(root) if root is not None else Path.cwd()
    stem = f"{args.material}_param" if args.parametric else args.material
    out = Path(args.out) if args.out else base / "models" / f"{stem}_{args.dim}d.pt"
    if out.suffix != ".pt":
        parser.error(f"--out {out}: the model file name must end in .pt")
    return_map = ""
    if args.material == "metal_nh":
        rm = Path(args.return_map) if args.return_map else base / "models" / f"metal_nh_rm_{args.dim}d.pt"
        if not rm.is_file():
            parser.error(
                f"--return-map {rm}: no such file "
                f"(train it first: python train.py --material metal_nh_rm --dim {args.dim})"
            )
        return_map = str(rm)
    elif args.return_map:
        parser.error(f"--return-map applies to --material metal_nh only, not {args.material}")
    if args.energy_form != "eq8" and args.material == RETURN_MAP_MATERIAL:
        parser.error(f"--energy-form applies to energies, not --material {RETURN_MAP_MATERIAL}")
    if args.warmup and args.schedule == "onecycle":
        parser.error("--warmup applies to the step and cosine schedules (onecycle warms up by itself)")
    if args.init_from is not None:
        if args.material == RETURN_MAP_MATERIAL:
            parser.error(f"--init-from applies to energies, not --material {RETURN_MAP_MATERIAL}")
        if not Path(args.init_from).is_file():
            parser.error(f"--init-from {args.init_from}: no such model file")
    if args.resume and not out.with_suffix(".ckpt").is_file():
        parser.error(f"--resume: no checkpoint {out.with_suffix('.ckpt')}")
    argv_list = sys.argv[1:] if argv is None else list(argv)
    try:
        config = TrainConfig(
            material=args.material,
            dim=args.dim,
            epochs=args.epochs,
            batch=args.batch,
            lr=args.lr,
            lr_decay=args.lr_decay,
            decay_steps=args.decay_steps,
            schedule=args.schedule,
            warmup=args.warmup,
            seed=args.seed,
            sampling=args.sampling,
            wide_fraction=args.wide_fraction,
            rm_loss=args.rm_loss,
            representation=args.representation,
            hessian_weight=args.hessian_weight,
            energy_form=args.energy_form,
            out=str(out),
            checkpoint_every=args.checkpoint_every,
            resume=args.resume,
            return_map=return_map,
            eval_every=args.eval_every,
            eval_samples=args.eval_samples,
            progress=not args.no_progress,
            threads=args.threads,
            device=args.device,
            precision=args.precision,
            hidden=tuple(args.hidden),
            shards=args.shards,
            parametric=args.parametric,
            init_from=args.init_from or "",
            command="python train.py " + shlex.join(argv_list),
        )
    except ValueError as err:  # a combination TrainConfig refuses (e.g. --parametric without a family)
        parser.error(str(err))
    try:
        trainer = Trainer(config)
    except ValueError as err:  # unreadable or mismatched checkpoint / return-map model, bad device
        parser.error(str(err))
    leader = trainer.parallel.leader
    kind = "return mapping" if args.material == RETURN_MAP_MATERIAL else "energy"
    where = f" on {trainer.device}" + (
        f", {trainer.parallel.world} processes ({trainer.shards} shards)" if trainer.parallel.world > 1 else ""
    )
    if not leader:  # the other ranks of a data-parallel run train silently
        trainer.run()
        return 0
    print(
        f"training the {args.dim}D {args.material} {kind}: {config.epochs} steps of batch {config.batch}, "
        + (f"lr {config.lr} x{config.lr_decay} every {config.decay_steps}" if config.schedule == "step"
           else f"lr {config.lr} {config.schedule}")
        + (f" after {config.warmup} warm-up steps" if config.warmup else "")
        + f", sampling {config.sampling}"
        + (f" ({config.wide_fraction:g} of it at {WIDE_SCALE:g}x the perturbation)" if config.wide_fraction else "")
        + f", seed {config.seed}"
        + (" (parametric: " + ", ".join(f"{r.field} in [{r.lo:g}, {r.hi:g}]" for r in trainer.task.parameters.ranges)
           + ")" if config.parametric else "")
        + (
            f", {config.representation} input, Hessian weight {config.hessian_weight}, energy form {config.energy_form}"
            if args.material != RETURN_MAP_MATERIAL
            else ""
        )
        + where
        + (f" (resuming at step {trainer.step})" if args.resume else "")
    )
    try:
        result = trainer.run()
    except KeyboardInterrupt:
        print(
            f"\ninterrupted; the last checkpoint is {config.paths['checkpoint']} "
            f"(continue with the same arguments and --resume)",
            file=sys.stderr,
        )
        return 130
    paths = result.paths
    print(f"trained {result.steps} steps in {result.wall_seconds:.1f} s, final loss {result.final_loss:.4e}")
    print(f"wrote model:      {paths['model']}")
    print(f"      loss log:   {paths['log']}")
    if config.eval_every:
        print(f"      error log:  {paths['eval_log']}")
    print(f"      loss curve: {paths['plot']}")
    print(f"      checkpoint: {paths['checkpoint']}")
    if result.errors:
        print(format_errors(result.errors, title="evaluation:"))
    return 0
