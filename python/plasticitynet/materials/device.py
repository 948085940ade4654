"""How often a batched iteration may test for convergence on the host.

Reading a device tensor on the host (`bool(active.any())`) waits for every queued kernel: on a GPU a
test per iteration serialises the loop. The loops of this package (Cam-Clay's unimodular shift, the
von Mises path bisection, the 3x3 Jacobi SVD) freeze converged rows with `torch.where`, so extra
iterations leave them unchanged and the result does not depend on how often the test runs: every
iteration on the CPU, where the test is free, every `ACCELERATOR_SYNC_INTERVAL` elsewhere.
"""

from __future__ import annotations

import torch

ACCELERATOR_SYNC_INTERVAL = 8


def sync_interval(device: torch.device | str) -> int:
    """Iterations between host-side convergence tests on `device`."""
    return 1 if torch.device(device).type == "cpu" else ACCELERATOR_SYNC_INTERVAL


def should_test(iteration: int, interval: int) -> bool:
    """Whether iteration `iteration` (0-based) ends with a host-side convergence test."""
    return (iteration + 1) % interval == 0
