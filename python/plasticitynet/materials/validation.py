"""Input checks shared by the material functions: every bad input is a ValueError naming the
argument and the problem; NaN is never propagated silently."""

from __future__ import annotations

import torch


def check_finite(name: str, x: torch.Tensor) -> None:
    """ValueError naming `name` and the first batch index holding a NaN or inf."""
    bad = ~torch.isfinite(x)
    if bad.any():
        first = torch.nonzero(bad)[0].tolist()
        raise ValueError(f"{name}: non-finite value {x[tuple(first)].item()!r} at index {tuple(first)}")


def check_float(name: str, x: torch.Tensor) -> None:
    if x.dtype not in (torch.float32, torch.float64):
        raise ValueError(f"{name}: dtype {x.dtype} not supported (expected torch.float32 or torch.float64)")


def as_batch_F(F, dim: int) -> tuple[torch.Tensor, bool]:
    """F as a (B, dim, dim) float tensor and whether it was a single (dim, dim) matrix."""
    F = torch.as_tensor(F)
    check_float("F", F)
    if F.ndim not in (2, 3) or F.shape[-1] != dim or F.shape[-2] != dim:
        raise ValueError(
            f"F: wrong shape {tuple(F.shape)} (expected ({dim}, {dim}) or (B, {dim}, {dim}) for this {dim}D material)"
        )
    check_finite("F", F)
    single = F.ndim == 2
    return (F[None] if single else F), single


def as_batch_Sigma(Sigma, dim: int) -> tuple[torch.Tensor, bool]:
    """Sigma as a (B, dim) float tensor and whether it was a single (dim,) vector."""
    Sigma = torch.as_tensor(Sigma)
    check_float("Sigma", Sigma)
    if Sigma.ndim not in (1, 2) or Sigma.shape[-1] != dim:
        raise ValueError(f"Sigma: wrong shape {tuple(Sigma.shape)} (expected ({dim},) or (B, {dim}))")
    check_finite("Sigma", Sigma)
    single = Sigma.ndim == 1
    return (Sigma[None] if single else Sigma), single


def as_batch_hardening(h, batch: int, like: torch.Tensor) -> torch.Tensor:
    """Hardening state as a (batch,) tensor of the dtype of `like`; a scalar is broadcast."""
    h = torch.as_tensor(h, dtype=like.dtype, device=like.device)
    if h.ndim == 0:
        h = h.expand(batch)
    elif h.ndim != 1 or h.shape[0] != batch:
        raise ValueError(f"hardening: wrong shape {tuple(h.shape)} (expected a scalar or ({batch},))")
    check_finite("hardening", h)
    return h
