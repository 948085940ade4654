"""The principal frame of F0: the network input of the frame-indifferent energy (docs/physics.md).

An isotropic material's Psi(F, F0, h) does not change when both deformations are rotated on the left
(Q F, Q F0) or on the right (F R, F0 R). With the polar SVD F0 = U diag(Sigma0) V^T, the pair is
therefore described by (G, Sigma0) with G = U^T F V (F in the principal frame of F0; G = diag(Sigma0)
at F = F0), and the "principal" representation feeds the MLP x = [vec G, Sigma0, h] (d^2 + d (+1)
numbers instead of 2 d^2 (+1)): the symmetry holds by construction, whatever the weights.

U and V depend on F0 only, which is constant within an optimization, so the energy is as smooth in F as
the MLP: grad_F N = U (grad_G N) V^T and Hess_F N = M^T (Hess_G N) M with vec G = M vec F.

The decomposition is the C++ simulator's `pnet::polar_svd` (cpp/pnet/math/svd.cpp) operation for
operation, batched and TorchScript-compatible, so that a model file gives the C++ fused kernel and
LibTorch/PyTorch the same frame, including where it is not unique (repeated singular values: F0 = I, the
most common state, gives U = V = I). Where singular values nearly coincide the frame turns quickly with
F0; the energy's exactness at F0 (eq. 8) does not depend on it, and the network, trained on frames from
this very function, is close to invariant under the turns the ambiguity allows (measured in the tests).
"""

from __future__ import annotations

from typing import Tuple

import torch


def _half_angle(c: torch.Tensor, s: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """(cos t/2, sin t/2) for the unit (c, s) = (cos t, sin t); the larger component from a root."""
    pos = c >= 0.0
    hc_pos = torch.sqrt(0.5 * (1.0 + c))
    hs_neg = torch.copysign(torch.sqrt(torch.clamp(0.5 * (1.0 - c), min=0.0)), s)
    safe_hc = torch.where(pos, hc_pos, torch.ones_like(c))
    safe_hs = torch.where(pos, torch.ones_like(c), hs_neg)
    hc = torch.where(pos, hc_pos, s / (2.0 * safe_hs))
    hs = torch.where(pos, s / (2.0 * safe_hc), hs_neg)
    return hc, hs


def _polar_svd_2d(F: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Closed-form 2x2 polar SVD (svd.cpp's: scaled rotation + scaled reflection, three roots)."""
    E = 0.5 * (F[:, 0, 0] + F[:, 1, 1])
    Fm = 0.5 * (F[:, 0, 0] - F[:, 1, 1])
    G = 0.5 * (F[:, 1, 0] + F[:, 0, 1])
    H = 0.5 * (F[:, 1, 0] - F[:, 0, 1])
    Q = torch.sqrt(E * E + H * H)
    R = torch.sqrt(Fm * Fm + G * G)
    one = torch.ones_like(E)
    zero = torch.zeros_like(E)
    r_pos = R > 0.0
    q_pos = Q > 0.0
    inv_r = 1.0 / torch.where(r_pos, R, one)
    inv_q = 1.0 / torch.where(q_pos, Q, one)
    c1 = torch.where(r_pos, Fm * inv_r, one)
    s1 = torch.where(r_pos, G * inv_r, zero)
    c2 = torch.where(q_pos, E * inv_q, one)
    s2 = torch.where(q_pos, H * inv_q, zero)
    c = c1 * c2 - s1 * s2
    s = s1 * c2 + c1 * s2
    uc, us = _half_angle(c, s)
    vc = uc * c2 + us * s2
    vs = us * c2 - uc * s2
    U = torch.stack([torch.stack([uc, -us], -1), torch.stack([us, uc], -1)], -2)
    V = torch.stack([torch.stack([vc, -vs], -1), torch.stack([vs, vc], -1)], -2)
    Sigma = torch.stack([Q + R, Q - R], -1)
    return U, Sigma, V


def _jacobi_rotate(A: torch.Tensor, V: torch.Tensor, p: int, q: int, active: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """svd.cpp's jacobi_rotate on the matrices where `active` (and A[p, q] != 0): zero A[p, q]."""
    r = 3 - p - q
    apq = A[:, p, q]
    on = active & (apq != 0.0)
    one = torch.ones_like(apq)
    safe_apq = torch.where(on, apq, one)
    theta = (A[:, q, q] - A[:, p, p]) / (2.0 * safe_apq)
    t = torch.copysign(one, theta) / (torch.abs(theta) + torch.sqrt(1.0 + theta * theta))
    c = 1.0 / torch.sqrt(1.0 + t * t)
    s = t * c
    arp = A[:, r, p]
    arq = A[:, r, q]
    App = A[:, p, p] - t * apq
    Aqq = A[:, q, q] + t * apq
    Arp = c * arp - s * arq
    Arq = s * arp + c * arq
    A2 = A.clone()
    A2[:, p, p] = App
    A2[:, q, q] = Aqq
    A2[:, p, q] = 0.0
    A2[:, q, p] = 0.0
    A2[:, r, p] = Arp
    A2[:, p, r] = Arp
    A2[:, r, q] = Arq
    A2[:, q, r] = Arq
    V2 = V.clone()
    vp = V[:, :, p]
    vq = V[:, :, q]
    V2[:, :, p] = c[:, None] * vp - s[:, None] * vq
    V2[:, :, q] = s[:, None] * vp + c[:, None] * vq
    on3 = on[:, None, None]
    return torch.where(on3, A2, A), torch.where(on3, V2, V)


def _swap_columns(A: torch.Tensor, V: torch.Tensor, i: int, j: int) -> Tuple[torch.Tensor, torch.Tensor]:
    """Where A[i, i] < A[j, j]: swap the eigenvalues and V's columns, negating the new column j."""
    swap = A[:, i, i] < A[:, j, j]
    A2 = A.clone()
    A2[:, i, i] = A[:, j, j]
    A2[:, j, j] = A[:, i, i]
    V2 = V.clone()
    V2[:, :, i] = V[:, :, j]
    V2[:, :, j] = -V[:, :, i]
    s3 = swap[:, None, None]
    return torch.where(s3, A2, A), torch.where(s3, V2, V)


def _givens_qr_step(B: torch.Tensor, U: torch.Tensor, p: int, q: int) -> Tuple[torch.Tensor, torch.Tensor]:
    """svd.cpp's givens_qr_step: rotate rows (p, q) of B to zero B[q, p]; U keeps U B constant."""
    a = B[:, p, p]
    b = B[:, q, p]
    r = torch.sqrt(a * a + b * b)
    on = r != 0.0
    safe_r = torch.where(on, r, torch.ones_like(r))
    c = (a / safe_r)[:, None]
    s = (b / safe_r)[:, None]
    B2 = B.clone()
    bp = B[:, p, :]
    bq = B[:, q, :]
    B2[:, p, :] = c * bp + s * bq
    B2[:, q, :] = -s * bp + c * bq
    U2 = U.clone()
    up = U[:, :, p]
    uq = U[:, :, q]
    U2[:, :, p] = c * up + s * uq
    U2[:, :, q] = -s * up + c * uq
    on3 = on[:, None, None]
    return torch.where(on3, B2, B), torch.where(on3, U2, U)


def _polar_svd_3d(F: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """svd.cpp's 3x3 polar SVD: cyclic Jacobi on F^T F (at most 8 sweeps, stopping per matrix at
    round-off), eigenvalues sorted with V's columns, Givens QR of F V for U and Sigma."""
    A = F.transpose(1, 2) @ F
    V = torch.eye(3, dtype=F.dtype, device=F.device).expand(F.shape[0], 3, 3).clone()
    active = torch.ones(F.shape[0], dtype=torch.bool, device=F.device)
    # Compiled into the model (TorchScript): materials.device.sync_interval written out.
    every = 1 if F.device.type == "cpu" else 8
    for it in range(8):
        off = A[:, 0, 1] * A[:, 0, 1] + A[:, 0, 2] * A[:, 0, 2] + A[:, 1, 2] * A[:, 1, 2]
        diagonal = A[:, 0, 0] * A[:, 0, 0] + A[:, 1, 1] * A[:, 1, 1] + A[:, 2, 2] * A[:, 2, 2]
        active = active & (off > 1e-34 * diagonal)
        if it % every == 0 and not bool(active.any()):  # sweep 0 always tests (often already diagonal)
            break
        A, V = _jacobi_rotate(A, V, 0, 1, active)
        A, V = _jacobi_rotate(A, V, 0, 2, active)
        A, V = _jacobi_rotate(A, V, 1, 2, active)
    A, V = _swap_columns(A, V, 0, 1)
    A, V = _swap_columns(A, V, 0, 2)
    A, V = _swap_columns(A, V, 1, 2)
    B = F @ V
    U = torch.eye(3, dtype=F.dtype, device=F.device).expand(F.shape[0], 3, 3).clone()
    B, U = _givens_qr_step(B, U, 0, 1)
    B, U = _givens_qr_step(B, U, 0, 2)
    B, U = _givens_qr_step(B, U, 1, 2)
    Sigma = torch.stack([B[:, 0, 0], B[:, 1, 1], B[:, 2, 2]], -1)
    return U, Sigma, V


def principal_frame(F0: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(U, Sigma0, V) of the batch F0 (B, d, d), d = 2 or 3: F0 = U diag(Sigma0) V^T, U and V
    rotations, Sigma0 descending with the sign of det F0 on the last entry. Computed in float64 without
    gradient (the frame is a constant of F) and returned in F0's dtype."""
    F64 = F0.detach().to(torch.float64)
    if F0.shape[-1] == 2:
        U, S, V = _polar_svd_2d(F64)
    else:
        U, S, V = _polar_svd_3d(F64)
    return U.to(F0.dtype), S.to(F0.dtype), V.to(F0.dtype)


def to_frame(F: torch.Tensor, U: torch.Tensor, V: torch.Tensor) -> torch.Tensor:
    """G = U^T F V (differentiable in F)."""
    return U.transpose(-1, -2) @ F @ V


__all__ = ["principal_frame", "to_frame"]
