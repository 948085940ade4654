#!/usr/bin/env python3
"""Training throughput of the PlasticityNet energy nets (issue 3 item 6): samples per second of one
training step (sampling + targets + loss of eq. 9 with its double backward + Adam), and of its parts,
for the 2D net ([9, 32, 32, 32, 1]) and the 3D net ([19, 64, 64, 64, 1]), float32.

    .venv/bin/python scripts/bench_training.py [--threads 2] [--batches 14 16] [--steps 5]
        [--materials metal snow] [--dims 2 3] [--device cpu|cuda|auto]

Timings are the median over --steps steps after one warm-up step (the whole step: the mean over whole
groups of the steps a GPU training prepares together). A benchmark, not a test: other
jobs on the machine slow it down (the load average is printed).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import torch

from plasticitynet.training import TrainConfig
from plasticitynet.training.energy import energy_loss
from plasticitynet.training.frames import principal_frame
from plasticitynet.training.sampling import sample_batch
from plasticitynet.training.trainer import make_task, resolve_device


def _median_time(fn, steps: int, device: torch.device) -> float:
    """Median wall time of fn(k), k = 1..steps, after fn(0); on CUDA each call ends with a synchronise, so
    the time is the kernels' and not their launch."""
    def timed(k):
        fn(k)
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    timed(0)  # warm-up
    times = []
    for k in range(1, steps + 1):
        t0 = time.perf_counter()
        timed(k)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _mean_time(fn, steps: int, device: torch.device) -> float:
    """Mean wall time of fn(k), k = 1..steps, after fn(0), synchronised once at the end: the time per call of
    a run of calls, which is what a training step costs when some calls prepare the following ones."""
    fn(0)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        fn(k)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return (time.perf_counter() - t0) / steps


def bench(material: str, dim: int, batch: int, steps: int, device: torch.device = torch.device("cpu"),
          profile: bool = False, hidden=None, hessian_weight: float = 0.0) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = TrainConfig(material=material, dim=dim, batch=batch, out=os.path.join(tmp, "m.pt"), progress=False,
                          hidden=tuple(hidden or ()), hessian_weight=hessian_weight)
        task = make_task(cfg, device)
    net, spec, stress = task.net, task.spec, task.stress
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)

    def sample(k):
        return sample_batch(spec, batch, 0, k, device=device)

    def targets(b):
        with torch.no_grad():
            return stress.from_factors(b.U, b.Sigma, b.V, b.h), stress.from_factors(b.U0, b.Sigma0, b.V0, b.h)

    b = sample(0)
    P, P0 = targets(b)
    b32, P, P0 = b.to(torch.float32), P.float(), P0.float()
    h = b32.h if spec.has_hardening else None
    frame = principal_frame(b32.F0) if net.representation == "principal" else None  # as training prepares it

    def network_step(k):
        opt.zero_grad(set_to_none=True)
        energy_loss(net, b32.F, b32.F0, h, P, P0, frame=frame).backward()
        opt.step()

    def full_step(k):
        opt.zero_grad(set_to_none=True)
        task.loss(k).backward()
        opt.step()

    t_sample = _median_time(sample, steps, device)
    t_targets = _median_time(lambda k: targets(b), steps, device)
    t_network = _median_time(network_step, steps, device)
    # whole prefetch groups (a GPU training prepares task.prefetch_steps steps' inputs at once)
    t_full = _mean_time(full_step, -(-steps // task.prefetch_steps) * task.prefetch_steps, device)
    if profile:
        from torch.profiler import ProfilerActivity
        from torch.profiler import profile as torch_profile

        activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
        with torch_profile(activities=activities) as prof:
            full_step(steps + 1)
            if device.type == "cuda":
                torch.cuda.synchronize(device)
        sort = "cuda_time_total" if device.type == "cuda" else "self_cpu_time_total"
        print(f"\n{material} {dim}D batch {batch}: one training step, top operators by {sort}")
        print(prof.key_averages().table(sort_by=sort, row_limit=15))
    return {
        "material": material, "dim": dim, "widths": net.widths, "batch": batch,
        "sample_s": t_sample, "targets_s": t_targets, "network_s": t_network, "step_s": t_full,
    }


def blas_library() -> str:
    """The BLAS shared object torch's GEMMs go to (Debian's torch uses the system libblas.so.3: the
    reference BLAS unless an optimised one such as libopenblas0-openmp is installed, ~4x slower here)."""
    torch.ones(2, 2) @ torch.ones(2, 2)
    try:
        with open("/proc/self/maps") as maps:
            libs = {line.split()[-1] for line in maps if "blas" in line.lower() and ".so" in line}
    except OSError:
        return "unknown"
    return ", ".join(sorted(os.path.realpath(lib) for lib in libs)) or "none found"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--batches", type=int, nargs="+", default=[14, 16], help="log2 of the batch sizes")
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--materials", nargs="+", default=["metal"], help="energy materials (hardening input: 9/19 wide)")
    p.add_argument("--dims", type=int, nargs="+", default=[2, 3])
    p.add_argument("--device", default="cpu", help="cpu, cuda, cuda:N or auto (cpu)")
    p.add_argument("--hidden", type=int, nargs="+", default=None, help="hidden widths (default: Table 2's)")
    p.add_argument("--hessian-weight", type=float, default=0.0, help="the Hessian term of the loss (0: off)")
    p.add_argument("--profile", action="store_true",
                   help="also print torch.profiler's top operators of one full training step per case")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    device = resolve_device(args.device)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"torch {torch.__version__}, {device}, {torch.get_num_threads()} threads, float32; load average {load}")
    print(f"BLAS: {blas_library()}")
    header = f"{'material':<9}{'dim':>4} {'widths':<20}{'batch':>7}{'step s':>9}{'steps/s':>9}{'samples/s':>11}" \
             f"{'net only':>11}{'sample s':>10}{'target s':>10}{'net s':>8}"
    print(header)
    print("-" * len(header))
    for material in args.materials:
        for dim in args.dims:
            for log2 in args.batches:
                r = bench(material, dim, 1 << log2, args.steps, device, args.profile, args.hidden, args.hessian_weight)
                print(
                    f"{material:<9}{dim:>4} {str(r['widths']):<20}{r['batch']:>7}{r['step_s']:>9.3f}{1 / r['step_s']:>9.2f}"
                    f"{r['batch'] / r['step_s']:>11.0f}{r['batch'] / r['network_s']:>11.0f}"
                    f"{r['sample_s']:>10.3f}{r['targets_s']:>10.3f}{r['network_s']:>8.3f}",
                    flush=True,
                )
    print("samples/s: whole training step (mean over whole prefetch groups); net only: loss (double backward) + Adam "
          "on a ready batch with its frame")


if __name__ == "__main__":
    main()
