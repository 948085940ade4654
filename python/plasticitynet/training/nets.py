"""The multilayer perceptrons of PlasticityNet (paper appendix A.1, Table 2).

    N(x) = W_L silu(... silu(W_1 x + b_1) ...) + b_L,   silu(z) = z sigmoid(z)  ("Swish"),

SiLU on every hidden layer, none on the output. Widths: [in, 32, 32, 32, 1] in 2D and
[in, 64, 64, 64, 1] in 3D (Table 2), for the energy net (in = 2 d^2, + 1 with a hardening input)
and the return-mapping net (in = d + 1).

Energy input (row-major vec): x = [vec(F), vec(F0), h], i.e.
x[0 : d^2] = F_ij at i*d + j, x[d^2 : 2 d^2] = F0_ij at d^2 + i*d + j, x[2 d^2] = h.
An energy network (`EnergyNet`) always takes this x; its representation decides what the MLP sees:
  "raw"        (the paper's)  the MLP takes x itself, 2 d^2 (+1) inputs;
  "principal"  (frames.py)    the MLP takes [vec(U^T F V), Sigma0, h], d^2 + d (+1) inputs, with
                              F0 = U diag(Sigma0) V^T: frame-indifferent by construction.
In both, the inputs the simulator differentiates in (F, or G) come first. A parametric energy
(parameters.py) appends its K normalised material parameters u after h, in x and in the MLP's input.
"""

from __future__ import annotations

import torch
from torch import nn

from .frames import principal_frame, to_frame

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


#: Energy input representations (see the module docstring); "principal" is the default of training.
REPRESENTATIONS = ("raw", "principal")


def energy_input_width(dim: int, has_hardening: bool) -> int:
    """Width of an energy network's input x = [vec F, vec F0, h]: 2 d^2 (+ 1 for h), 8/9 in 2D, 18/19 in 3D."""
    return 2 * dim * dim + (1 if has_hardening else 0)


def mlp_input_width(dim: int, has_hardening: bool, representation: str = "raw", parameters: int = 0) -> int:
    """Width of the MLP's input: 2 d^2 (+1) raw; d^2 + d (+1) principal (6/7 in 2D, 12/13 in 3D); plus the
    number of material parameters of a parametric energy."""
    if representation not in REPRESENTATIONS:
        raise ValueError(f"representation = {representation!r}: expected one of {', '.join(REPRESENTATIONS)}")
    base = 2 * dim * dim if representation == "raw" else dim * dim + dim
    return base + (1 if has_hardening else 0) + int(parameters)


def hidden_widths(dim: int, hidden=None) -> tuple[int, ...]:
    """The hidden layers' widths: `hidden` (any number of layers) or Table 2's for `dim`."""
    if not hidden:
        return HIDDEN_WIDTHS[dim]
    hidden = tuple(int(w) for w in hidden)
    if any(w <= 0 for w in hidden):
        raise ValueError(f"hidden = {list(hidden)}: widths must be > 0")
    return hidden


def energy_widths(dim: int, has_hardening: bool, representation: str = "raw", hidden=None, parameters: int = 0) -> list[int]:
    return [mlp_input_width(dim, has_hardening, representation, parameters), *hidden_widths(dim, hidden), 1]


def return_map_widths(dim: int, hidden=None) -> list[int]:
    """[d + 1, hidden..., 1]: input [Sigma (d), h]."""
    return [dim + 1, *hidden_widths(dim, hidden), 1]


def make_mlp(widths, seed: int) -> MLP:
    """An MLP with PyTorch's default initialisation drawn from `seed` (the global RNG is left as it was)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return MLP(widths)


class EnergyNet(nn.Module):
    """An energy network: forward(x = [vec F, vec F0, h]) -> N (B, 1) whatever the representation, so that
    every model is called the same way from PyTorch, TorchScript and LibTorch. Parameters are the MLP's,
    named mlp.layers.{2k}.weight / .bias; `widths` are the MLP's. `parameters`: the number of material
    parameters a parametric energy takes after h (0 for a dedicated one)."""

    def __init__(self, mlp: MLP, dim: int, representation: str = "raw", parameters: int = 0):
        super().__init__()
        if representation not in REPRESENTATIONS:
            raise ValueError(f"representation = {representation!r}: expected one of {', '.join(REPRESENTATIONS)}")
        self.mlp = mlp
        self.dim = int(dim)
        self.representation = representation
        self.widths = list(mlp.widths)
        self.material_inputs = int(parameters)  # (nn.Module has parameters())
        self.has_hardening = self.widths[0] == mlp_input_width(dim, True, representation, parameters)
        if not self.has_hardening and self.widths[0] != mlp_input_width(dim, False, representation, parameters):
            raise ValueError(f"widths = {self.widths}: not a {dim}D {representation} energy network")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.representation == "raw":
            return self.mlp(x)
        d = self.dim
        m = d * d
        B = x.shape[0]
        U, Sigma0, V = principal_frame(x[:, m : 2 * m].reshape(B, d, d))
        return self.in_frame(x[:, :m].reshape(B, d, d), U, Sigma0, V, x[:, 2 * m :])

    def in_frame(
        self, F: torch.Tensor, U: torch.Tensor, Sigma0: torch.Tensor, V: torch.Tensor, rest: torch.Tensor
    ) -> torch.Tensor:
        """A principal network on F (B, d, d) given the frame (U, Sigma0, V) = principal_frame(F0) and the
        inputs after F0 (`rest`, (B, 0) or (B, 1) with h): forward(x) with the frame computed beforehand.
        Training computes the frames of many batches at once this way (the frame is a constant of F, and
        its batched polar SVD is most of a step's small kernels on a GPU)."""
        B = F.shape[0]
        G = to_frame(F, U, V).reshape(B, self.dim * self.dim)
        return self.mlp(torch.cat([G, Sigma0, rest], dim=1))


def make_energy_net(
    dim: int, has_hardening: bool, representation: str, seed: int, hidden=None, parameters: int = 0
) -> EnergyNet:
    """An energy network with PyTorch's default initialisation drawn from `seed` (hidden: hidden_widths;
    parameters: the number of material parameters of a parametric energy)."""
    widths = energy_widths(dim, has_hardening, representation, hidden, parameters)
    return EnergyNet(make_mlp(widths, seed), dim, representation, parameters)


def energy_input(F: torch.Tensor, F0: torch.Tensor, h: torch.Tensor | None) -> torch.Tensor:
    """x = [vec(F), vec(F0), h] (row-major vec; no h column when h is None), shape (B, 2 d^2 [+1])."""
    B = F.shape[0]
    parts = [F.reshape(B, -1), F0.reshape(B, -1)]
    if h is not None:  # h (B,), or the tail [h, u] (B, k) of a parametric model
        parts.append(h.reshape(B, -1).to(F.dtype))
    return torch.cat(parts, dim=1)
