"""The multilayer perceptrons of PlasticityNet (paper appendix A.1, Table 2).

    N(x) = W_L silu(... silu(W_1 x + b_1) ...) + b_L,   silu(z) = z sigmoid(z)  ("Swish"),

SiLU on every hidden layer, none on the output. Widths: [in, 32, 32, 32, 1] in 2D and
[in, 64, 64, 64, 1] in 3D (Table 2), for the energy net (in = 2 d^2, + 1 with a hardening input)
and the return-mapping net (in = d + 1).

Energy input (row-major vec): x = [vec(F), vec(F0), h], i.e.
x[0 : d^2] = F_ij at i*d + j, x[d^2 : 2 d^2] = F0_ij at d^2 + i*d + j, x[2 d^2] = h.
"""

from __future__ import annotations

import torch
from torch import nn

#: Hidden widths per dimension (Table 2).
HIDDEN_WIDTHS = {2: (32, 32, 32), 3: (64, 64, 64)}


class MLP(nn.Module):
    """Linear layers with SiLU between them; forward(x: (B, in)) -> (B, 1).
    Parameters are named layers.{2k}.weight / layers.{2k}.bias for the k-th linear layer."""

    def __init__(self, widths: list[int] | tuple[int, ...]):
        super().__init__()
        widths = [int(w) for w in widths]
        if len(widths) < 2 or any(w <= 0 for w in widths):
            raise ValueError(f"widths = {widths}: expected at least two positive widths")
        layers: list[nn.Module] = []
        for k in range(len(widths) - 1):
            layers.append(nn.Linear(widths[k], widths[k + 1]))
            if k < len(widths) - 2:
                layers.append(nn.SiLU())
        self.layers = nn.Sequential(*layers)
        self.widths = widths

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.layers(x)


def energy_input_width(dim: int, has_hardening: bool) -> int:
    """2 d^2 (+ 1 for h): 8/9 in 2D, 18/19 in 3D."""
    return 2 * dim * dim + (1 if has_hardening else 0)


def energy_widths(dim: int, has_hardening: bool) -> list[int]:
    return [energy_input_width(dim, has_hardening), *HIDDEN_WIDTHS[dim], 1]


def return_map_widths(dim: int) -> list[int]:
    """[d + 1, hidden..., 1]: input [Sigma (d), h]."""
    return [dim + 1, *HIDDEN_WIDTHS[dim], 1]


def make_mlp(widths, seed: int) -> MLP:
    """An MLP with PyTorch's default initialisation drawn from `seed` (the global RNG is left as it was)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return MLP(widths)


def energy_input(F: torch.Tensor, F0: torch.Tensor, h: torch.Tensor | None) -> torch.Tensor:
    """x = [vec(F), vec(F0), h] (row-major vec; no h column when h is None), shape (B, 2 d^2 [+1])."""
    B = F.shape[0]
    parts = [F.reshape(B, -1), F0.reshape(B, -1)]
    if h is not None:
        parts.append(h.reshape(B, 1).to(F.dtype))
    return torch.cat(parts, dim=1)
