"""Training and evaluation samples (F, F0, h) of PlasticityNet (paper sec. 5.1, appendix A.2;
docs/physics.md).

"paper" sampling (sec. 5.1), with Haar-random rotations R1..R4:
    F0 = R1 diag(e^eps) R2,   F = R3 diag(e^(eps + deps)) R4,
    eps ~ U[-1, 1]^d,  deps ~ U[-r, r]^d  (r = 0.1 sand and metal, 0.2 snow).
F shares only its singular values' neighbourhood with F0; as matrices they are far apart.

"near" sampling (docs/physics.md, beyond the paper): F close to F0 as a matrix, the regime the
simulator visits (within a step F differs from F0 by dt grad v):
    F0 = R1 diag(e^eps) R2,   F = R1 Qa diag(e^(eps + deps)) Qb R2,
with Qa, Qb small random rotations of angle <= 0.1 rad.

Hardening h ~ U[h_lo, h_hi] (appendix A.2): Cam-Clay (snow) h = min(a, 0) in [-0.5, 0] (2D) or
[-1, 0] (3D); von Mises (metal) h = tau_Y / (2 mu) in [0, 1]; Drucker-Prager (sand) has none.

A batch may draw a share `wide_fraction` of its samples with WIDE_SCALE times the deps range (beyond the
paper): the states a large step's Newton iterates pass through lie beyond the trained perturbation, and
a network trained only within it can extrapolate to stresses thousands of times too large there
(docs/physics.md, "Sampling").

A parametric model's batches also carry material parameters p (parameters.py): uniform in the family's
box, one vector per group of parameters.GROUP_SIZE consecutive samples (fewer, larger groups beyond
parameters.MAX_GROUPS per part), from a stream of their own.

Every draw comes from a torch.Generator seeded from (seed, step, stream), so that a batch is fully
determined by those three integers (resumed training sees the same batches; evaluation uses a
stream disjoint from training). Samples are drawn in float64 and cast at the end.

Because F = U diag(Sigma) V^T is built from its own rotations, the batch carries these factors:
the targets Ptilde = U diag(tau(Z(Sigma)) / Sigma) V^T then need no SVD (see targets.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from ..materials import Material
from .parameters import GROUP_SIZE, MAX_GROUPS, ParameterRange, bounds

SAMPLINGS = ("paper", "near")
#: Training may also draw "mixed" batches: half "paper", half "near" (beyond the paper: the states a
#: Newton solve visits, F close to F0, beside the paper's far-apart pairs).
TRAINING_SAMPLINGS = (*SAMPLINGS, "mixed")
#: Step offset of the "near" half of a mixed batch (its own stream of random numbers).
_MIXED_NEAR_STEP = 1 << 40
#: Step offset of a batch's wide share (SamplingSpec.wide_fraction), and how much wider its deps range is
#: (the "near 2x" held-out error's range).
_WIDE_STEP = 1 << 41
WIDE_SCALE = 2.0

#: Independent random streams: training batches never share a seed with evaluation samples.
STREAMS = {"train": 0, "eval": 1, "test": 2, "hessian": 3}
#: A parametric batch's parameters come from the stream of its samples offset by this (its own numbers, so
#: that adding parameters changes no other draw).
_PARAMETER_STREAM_OFFSET = 16

#: Log-singular values eps ~ U[-EPS_RANGE, EPS_RANGE]^d (sec. 5.1).
EPS_RANGE = 1.0
#: Largest rotation angle (rad) of Qa, Qb in "near" sampling (docs/physics.md).
NEAR_MAX_ANGLE = 0.1


@dataclass(frozen=True)
class SamplingSpec:
    """What to sample for one material: deps ~ U[-deps_scale deps, deps_scale deps]^d and h ~ U[h_range]
    (h_range None: the material has no hardening input); for a parametric model, the ranges of its
    material parameters (parameters.ParameterRange, in input order; empty otherwise)."""

    dim: int
    deps: float
    h_range: tuple[float, float] | None
    sampling: str = "paper"
    deps_scale: float = 1.0
    parameters: tuple[ParameterRange, ...] = ()
    wide_fraction: float = 0.0  # share of each batch drawn with WIDE_SCALE x the deps range

    def __post_init__(self):
        if self.sampling not in TRAINING_SAMPLINGS:
            raise ValueError(f"sampling = {self.sampling!r}: expected one of {', '.join(TRAINING_SAMPLINGS)}")
        if not (self.deps_scale > 0 and math.isfinite(self.deps_scale)):
            raise ValueError(f"deps_scale = {self.deps_scale!r}: must be finite and > 0")
        if not 0.0 <= self.wide_fraction < 1.0:
            raise ValueError(f"wide_fraction = {self.wide_fraction!r}: must be in [0, 1)")

    @property
    def has_hardening(self) -> bool:
        return self.h_range is not None

    def with_(self, **changes) -> "SamplingSpec":
        return replace(self, **changes)

    def to_dict(self) -> dict:
        return {
            "sampling": self.sampling,
            "eps_range": [-EPS_RANGE, EPS_RANGE],
            "deps_range": [-self.deps * self.deps_scale, self.deps * self.deps_scale],
            "h_range": None if self.h_range is None else list(self.h_range),
            "near_max_angle": NEAR_MAX_ANGLE if self.sampling in ("near", "mixed") else None,
            **({"wide_fraction": self.wide_fraction,
                "wide_deps_range": [-self.deps * self.deps_scale * WIDE_SCALE, self.deps * self.deps_scale * WIDE_SCALE]}
               if self.wide_fraction > 0.0 else {}),
            **({"parameters": [r.to_dict() for r in self.parameters], "parameter_group_size": GROUP_SIZE}
               if self.parameters else {}),
        }


def sampling_spec(material: Material, sampling: str = "paper", deps_scale: float = 1.0) -> SamplingSpec:
    """The sec. 5.1 / appendix A.2 ranges for `material`, chosen by its plasticity model."""
    plasticity = material.plasticity.name
    d = material.dim
    if plasticity == "cam_clay":  # snow: deps in [-0.2, 0.2], h = min(a, 0)
        return SamplingSpec(d, 0.2, (-0.5, 0.0) if d == 2 else (-1.0, 0.0), sampling, deps_scale)
    if plasticity == "von_mises":  # metal, metal_nh: h = tau_Y / (2 mu)
        return SamplingSpec(d, 0.1, (0.0, 1.0), sampling, deps_scale)
    if plasticity in ("drucker_prager", "none"):  # sand: no hardening
        return SamplingSpec(d, 0.1, None, sampling, deps_scale)
    raise ValueError(f"plasticity.model = {plasticity!r}: no training distribution defined")


def generator_for(
    seed: int, step: int, stream: str = "train", device: torch.device | str = "cpu", shard: int = 0,
    offset: int = 0,
) -> torch.Generator:
    """A generator on `device` whose state depends only on (seed, step, stream, shard) (numpy SeedSequence
    mixing, so that neighbouring seeds and steps give unrelated streams). Draws are reproducible per
    device type: a CUDA generator seeded alike yields other numbers than the CPU one. Shard 0 is the
    stream of an unsharded batch; shard k > 0 (a data-parallel rank's part, `sample_batch(shards=...)`)
    mixes k in as a fourth word."""
    if stream not in STREAMS:
        raise ValueError(f"stream = {stream!r}: expected one of {', '.join(STREAMS)}")
    if seed < 0 or step < 0 or shard < 0:
        raise ValueError(f"seed = {seed}, step = {step}, shard = {shard}: must be >= 0")
    words = [STREAMS[stream] + offset, int(seed), int(step)] + ([int(shard)] if shard else [])
    state = np.random.SeedSequence(words).generate_state(2, dtype=np.uint32)
    return torch.Generator(device=torch.device(device)).manual_seed((int(state[0]) << 31) ^ int(state[1]))


def uniform(n: int, lo: float, hi: float, generator: torch.Generator, cols: int | None = None) -> torch.Tensor:
    shape = (n,) if cols is None else (n, cols)
    return lo + (hi - lo) * torch.rand(shape, generator=generator, dtype=torch.float64, device=generator.device)


def random_rotations(n: int, d: int, generator: torch.Generator) -> torch.Tensor:
    """n Haar-random rotations, (n, d, d) float64: the QR factorisation of a Gaussian matrix A with
    diag(R) > 0 (Q is then Haar on O(d)), made proper (det +1, Haar on SO(d)).

    Done by hand because batched LAPACK QR and det cost ~80% of a batch for 2x2/3x3 matrices:
    Gram-Schmidt on the first d-1 columns of A (this is exactly Q of the QR with diag(R) > 0;
    projected twice for round-off), then the last column completing a right-handed frame
    (2D: q1 rotated by +90 deg; 3D: q1 x q2), i.e. Q's last column with its sign fixed so that det Q = +1."""
    A = torch.randn(n, d, d, generator=generator, dtype=torch.float64, device=generator.device)
    columns: list[torch.Tensor] = []
    for k in range(d - 1):
        q = A[:, :, k]
        for _ in range(2):
            for p in columns:
                q = q - (p * q).sum(-1, keepdim=True) * p
        columns.append(q / torch.linalg.vector_norm(q, dim=-1, keepdim=True))
    if d == 2:
        q1 = columns[0]
        columns.append(torch.stack([-q1[:, 1], q1[:, 0]], dim=-1))
    else:
        columns.append(torch.linalg.cross(columns[0], columns[1], dim=-1))
    return torch.stack(columns, dim=-1)


def small_rotations(n: int, d: int, max_angle: float, generator: torch.Generator) -> torch.Tensor:
    """n random rotations of angle theta ~ U[0, max_angle] (2D: either sense; 3D: about a uniformly
    random axis k, Rodrigues: R = I + sin(theta) [k]x + (1 - cos(theta)) [k]x^2), (n, d, d) float64."""
    if d == 2:
        theta = uniform(n, -max_angle, max_angle, generator)
        c, s = torch.cos(theta), torch.sin(theta)
        return torch.stack([torch.stack([c, -s], -1), torch.stack([s, c], -1)], -2)
    theta = uniform(n, 0.0, max_angle, generator)
    k = torch.randn(n, 3, generator=generator, dtype=torch.float64, device=generator.device)
    k = k / torch.linalg.vector_norm(k, dim=-1, keepdim=True)
    zero = torch.zeros_like(theta)
    K = torch.stack(
        [
            torch.stack([zero, -k[:, 2], k[:, 1]], -1),
            torch.stack([k[:, 2], zero, -k[:, 0]], -1),
            torch.stack([-k[:, 1], k[:, 0], zero], -1),
        ],
        -2,
    )
    eye = torch.eye(3, dtype=torch.float64, device=generator.device).expand(n, 3, 3)
    return eye + torch.sin(theta)[:, None, None] * K + (1.0 - torch.cos(theta))[:, None, None] * (K @ K)


@dataclass
class DeformationBatch:
    """A batch of (F, F0, h) with the factors F = U diag(Sigma) V^T, F0 = U0 diag(Sigma0) V0^T
    (U, V, U0, V0 rotations; Sigma, Sigma0 > 0, unsorted). h is (B,) (zeros, unused, without
    hardening); p (B, K) the material parameters of a parametric model (K = 0 otherwise)."""

    F: torch.Tensor
    F0: torch.Tensor
    h: torch.Tensor
    U: torch.Tensor
    Sigma: torch.Tensor
    V: torch.Tensor
    U0: torch.Tensor
    Sigma0: torch.Tensor
    V0: torch.Tensor
    p: torch.Tensor

    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None) -> "DeformationBatch":
        """The batch in another dtype and/or on another device."""
        return DeformationBatch(**{k: getattr(self, k).to(device=device, dtype=dtype) for k in self.__dataclass_fields__})

    @staticmethod
    def cat(parts: list["DeformationBatch"]) -> "DeformationBatch":
        if len(parts) == 1:
            return parts[0]
        return DeformationBatch(
            **{k: torch.cat([getattr(p, k) for p in parts]) for k in DeformationBatch.__dataclass_fields__}
        )

    def __len__(self) -> int:
        return self.F.shape[0]


def shard_parts(n: int, shards: int, shard_range: tuple[int, int] | None) -> tuple[int, range]:
    """(samples per part, the parts drawn) of a batch of n split into `shards` parts."""
    if n <= 0:
        raise ValueError(f"n = {n}: must be > 0")
    if shards < 1 or n % shards:
        raise ValueError(f"shards = {shards}: must be >= 1 and divide the batch size {n}")
    lo, hi = shard_range if shard_range is not None else (0, shards)
    if not 0 <= lo < hi <= shards:
        raise ValueError(f"shard_range = {shard_range}: expected 0 <= first < last <= shards = {shards}")
    return n // shards, range(lo, hi)


def sample_batch(
    spec: SamplingSpec,
    n: int,
    seed: int,
    step: int = 0,
    stream: str = "train",
    dtype=torch.float64,
    device: torch.device | str = "cpu",
    shards: int = 1,
    shard_range: tuple[int, int] | None = None,
) -> DeformationBatch:
    """n samples (F, F0, h) of `spec`, determined by (seed, step, stream) and the device type; built in
    float64 on `device` and cast.

    shards > 1 splits the batch into `shards` equal parts, part k drawn from its own stream (shard k):
    a data-parallel run of W processes draws parts [r S/W, (r + 1) S/W) on rank r, and the union over
    the ranks is the batch a single process draws with the same `shards`. shard_range selects those
    parts (default: all)."""
    size, parts = shard_parts(n, shards, shard_range)
    return DeformationBatch.cat([_sample_part(spec, size, seed, step, stream, dtype, device, k) for k in parts])


def _sample_part(spec, n, seed, step, stream, dtype, device, shard) -> DeformationBatch:
    if spec.wide_fraction > 0.0:
        # The first n - n_wide samples are the batch wide_fraction = 0 would draw with that size; the wide
        # share has a stream of its own.
        n_wide = int(round(n * spec.wide_fraction))
        base = _sample_part(spec.with_(wide_fraction=0.0), n - n_wide, seed, step, stream, dtype, device, shard)
        if n_wide == 0:
            return base
        wide = spec.with_(wide_fraction=0.0, deps_scale=spec.deps_scale * WIDE_SCALE)
        return DeformationBatch.cat([base, _sample_part(wide, n_wide, seed, step + _WIDE_STEP, stream, dtype, device, shard)])
    if spec.sampling == "mixed":
        paper = _sample_part(spec.with_(sampling="paper"), n - n // 2, seed, step, stream, dtype, device, shard)
        if n < 2:
            return paper
        near = _sample_part(
            spec.with_(sampling="near"), n // 2, seed, step + _MIXED_NEAR_STEP, stream, dtype, device, shard
        )
        return DeformationBatch.cat([paper, near])
    g = generator_for(seed, step, stream, device, shard)
    d = spec.dim
    r = spec.deps * spec.deps_scale
    # Fixed draw order: eps, deps, h, then the rotations.
    eps = uniform(n, -EPS_RANGE, EPS_RANGE, g, d)
    deps = uniform(n, -r, r, g, d)
    if spec.h_range is None:
        h = torch.zeros(n, dtype=torch.float64, device=g.device)
    else:
        h = uniform(n, spec.h_range[0], spec.h_range[1], g)
    Sigma0, Sigma = torch.exp(eps), torch.exp(eps + deps)
    R1, R2 = random_rotations(n, d, g), random_rotations(n, d, g)
    U0, V0 = R1, R2.transpose(-1, -2)
    if spec.sampling == "paper":
        # F = R3 diag(e^(eps+deps)) R4 with fresh R3, R4.
        U, V = random_rotations(n, d, g), random_rotations(n, d, g).transpose(-1, -2)
    else:
        # F = (R1 Qa) diag(e^(eps+deps)) (Qb R2).
        Qa, Qb = small_rotations(n, d, NEAR_MAX_ANGLE, g), small_rotations(n, d, NEAR_MAX_ANGLE, g)
        U, V = R1 @ Qa, (Qb @ R2).transpose(-1, -2)

    def compose(U_, S_, V_):
        return (U_ * S_[:, None, :]) @ V_.transpose(-1, -2)

    p = torch.zeros(n, 0, dtype=torch.float64, device=g.device)
    if spec.parameters:
        gp = generator_for(seed, step, stream, device, shard, offset=_PARAMETER_STREAM_OFFSET)
        lo, hi = bounds(spec.parameters, device=g.device)
        size = max(GROUP_SIZE, -(-n // MAX_GROUPS))  # samples per group
        groups = -(-n // size)
        values = lo + (hi - lo) * torch.rand((groups, len(lo)), generator=gp, dtype=torch.float64, device=g.device)
        p = values.repeat_interleave(size, dim=0)[:n]
    batch = DeformationBatch(compose(U, Sigma, V), compose(U0, Sigma0, V0), h, U, Sigma, V, U0, Sigma0, V0, p)
    return batch if dtype == torch.float64 else batch.to(dtype)


def sample_return_map_states(
    dim: int,
    n: int,
    seed: int,
    step: int = 0,
    stream: str = "train",
    dtype=torch.float64,
    device: torch.device | str = "cpu",
    shards: int = 1,
    shard_range: tuple[int, int] | None = None,
):
    """(Sigma, h) for the learned return mapping (paper sec. 4.3, appendix A.2.4):
    Sigma = e^eps, eps ~ U[-1, 1]^d, h ~ U[0, 1] (von Mises h = tau_Y / (2 mu)); shards as sample_batch."""
    size, parts = shard_parts(n, shards, shard_range)
    drawn = [_return_map_part(dim, size, seed, step, stream, dtype, device, k) for k in parts]
    return torch.cat([p[0] for p in drawn]), torch.cat([p[1] for p in drawn])


def _return_map_part(dim, n, seed, step, stream, dtype, device, shard):
    g = generator_for(seed, step, stream, device, shard)
    eps = uniform(n, -EPS_RANGE, EPS_RANGE, g, dim)
    h = uniform(n, 0.0, 1.0, g)
    return torch.exp(eps).to(dtype), h.to(dtype)
