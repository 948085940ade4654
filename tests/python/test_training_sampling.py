"""Training samples (F, F0, h) (paper sec. 5.1, docs/physics.md) and the stress targets built from them."""

import math

import pytest
import torch

from plasticitynet.materials import Material
from plasticitynet.training import (
    ElastoplasticStress,
    generator_for,
    nondimensional_material,
    random_rotations,
    sample_batch,
    sample_return_map_states,
    sampling_spec,
    small_rotations,
    with_young_modulus,
)

NAMES = ["sand", "snow", "metal", "metal_nh"]
#: deps half-width and hardening range per material (sec. 5.1, appendix A.2).
EXPECTED = {
    ("sand", 2): (0.1, None), ("sand", 3): (0.1, None),
    ("snow", 2): (0.2, (-0.5, 0.0)), ("snow", 3): (0.2, (-1.0, 0.0)),
    ("metal", 2): (0.1, (0.0, 1.0)), ("metal", 3): (0.1, (0.0, 1.0)),
    ("metal_nh", 2): (0.1, (0.0, 1.0)), ("metal_nh", 3): (0.1, (0.0, 1.0)),
}


def _is_rotation(R: torch.Tensor) -> bool:
    d = R.shape[-1]
    eye = torch.eye(d, dtype=R.dtype)
    return bool(
        torch.allclose(R.transpose(-1, -2) @ R, eye.expand_as(R), atol=1e-12)
        and torch.allclose(torch.linalg.det(R), torch.ones(R.shape[0], dtype=R.dtype), atol=1e-12)
    )


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("sampling", ["paper", "near"])
@pytest.mark.parametrize("name", NAMES)
def test_batch_ranges_and_factors(name, dim, sampling):
    m = nondimensional_material(name, dim)
    spec = sampling_spec(m, sampling)
    deps, h_range = EXPECTED[(name, dim)]
    assert spec.deps == deps and spec.h_range == h_range and spec.has_hardening == (h_range is not None)
    b = sample_batch(spec, 4000, seed=1, step=2)
    assert b.F.dtype == torch.float64 and b.F.shape == (4000, dim, dim) and len(b) == 4000
    # The factors reproduce F and F0, with proper rotations.
    for U, S, V, F in ((b.U, b.Sigma, b.V, b.F), (b.U0, b.Sigma0, b.V0, b.F0)):
        assert _is_rotation(U) and _is_rotation(V)
        assert torch.allclose((U * S[:, None, :]) @ V.transpose(-1, -2), F, atol=1e-13)
    eps, d_eps = torch.log(b.Sigma0), torch.log(b.Sigma / b.Sigma0)
    assert eps.min() >= -1 and eps.max() <= 1 and eps.min() < -0.95 and eps.max() > 0.95
    assert d_eps.abs().max() <= deps * (1 + 1e-12) and d_eps.abs().max() > 0.95 * deps
    # Singular values of F from an SVD agree with the sampled ones (as sets).
    svd = torch.linalg.svdvals(b.F)
    assert torch.allclose(svd, torch.sort(b.Sigma, dim=-1, descending=True).values, rtol=1e-12)
    if h_range is None:
        assert torch.all(b.h == 0)
    else:
        assert b.h.min() >= h_range[0] and b.h.max() <= h_range[1]
        assert b.h.max() - b.h.min() > 0.95 * (h_range[1] - h_range[0])


@pytest.mark.parametrize("dim", [2, 3])
def test_near_is_near_and_paper_is_not(dim):
    m = nondimensional_material("sand", dim)
    rel = {}
    for s in ("paper", "near"):
        b = sample_batch(sampling_spec(m, s), 4000, seed=0)
        rel[s] = torch.linalg.matrix_norm(b.F - b.F0) / torch.linalg.matrix_norm(b.F0)
    # near: F = R1 Qa S Qb R2 vs F0 = R1 S0 R2 with angles <= 0.1 rad and |deps| <= 0.1.
    assert rel["near"].max() < 0.45 and rel["near"].mean() < 0.15
    assert rel["paper"].mean() > 1.0  # independent rotations: F is far from F0 as a matrix
    # near keeps the frames: R1^T F R2^T = Qa diag(Sigma) Qb, within ||Qa - I||_2 + ||Qb - I||_2 <= 2 (2 sin 0.05)
    # (relative, Frobenius) of diag(Sigma).
    b = sample_batch(sampling_spec(m, "near"), 1000, seed=0)
    inner = b.U0.transpose(-1, -2) @ b.F @ b.V0
    dist = torch.linalg.matrix_norm(inner - torch.diag_embed(b.Sigma)) / torch.linalg.vector_norm(b.Sigma, dim=-1)
    assert float(dist.max()) <= 4 * math.sin(0.05) * (1 + 1e-12)


def test_reproducible_and_streams_disjoint():
    spec = sampling_spec(nondimensional_material("snow", 3), "paper")
    a, b = sample_batch(spec, 64, seed=5, step=3), sample_batch(spec, 64, seed=5, step=3)
    for key in ("F", "F0", "h", "U", "Sigma", "V"):
        assert torch.equal(getattr(a, key), getattr(b, key))
    assert not torch.equal(a.F, sample_batch(spec, 64, seed=5, step=4).F)
    assert not torch.equal(a.F, sample_batch(spec, 64, seed=6, step=3).F)
    assert not torch.equal(a.F, sample_batch(spec, 64, seed=5, step=3, stream="eval").F)
    # Independent of the global RNG.
    torch.manual_seed(123)
    c = sample_batch(spec, 64, seed=5, step=3)
    assert torch.equal(a.F, c.F)
    # float32 is the cast of the float64 batch.
    f32 = sample_batch(spec, 64, seed=5, step=3, dtype=torch.float32)
    assert f32.F.dtype == torch.float32 and torch.equal(f32.F, a.F.float())
    S1, h1 = sample_return_map_states(2, 100, seed=1, step=0)
    S2, h2 = sample_return_map_states(2, 100, seed=1, step=0)
    assert torch.equal(S1, S2) and torch.equal(h1, h2)
    assert torch.log(S1).abs().max() <= 1 and h1.min() >= 0 and h1.max() <= 1


@pytest.mark.parametrize("dim", [2, 3])
def test_rotations_haar_and_small(dim):
    g = generator_for(0, 0)
    R = random_rotations(20000, dim, g)
    assert _is_rotation(R)
    # Haar: E[R] = 0 and E[R_ij^2] = 1/d.
    assert float(R.mean(0).abs().max()) < 0.03
    assert torch.allclose((R * R).mean(0), torch.full((dim, dim), 1.0 / dim, dtype=R.dtype), atol=0.02)
    Q = small_rotations(5000, dim, 0.1, g)
    assert _is_rotation(Q)
    angle = torch.acos(torch.clamp((torch.diagonal(Q, dim1=-2, dim2=-1).sum(-1) - (dim - 2)) / 2, -1, 1))
    assert float(angle.max()) <= 0.1 + 1e-12 and float(angle.max()) > 0.09


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", NAMES)
def test_targets_without_svd_match_the_library(name, dim):
    """Ptilde from the sampled factors (training path) equals the library's elastoplastic_stress."""
    m = nondimensional_material(name, dim)
    assert m.elasticity.params.E == 1.0 and m.to_dict()["name"] == name
    b = sample_batch(sampling_spec(m, "paper", deps_scale=2.0), 3000, seed=2)
    stress = ElastoplasticStress(m)
    P = stress.from_factors(b.U, b.Sigma, b.V, b.h)
    ref = m.elastoplastic_stress(b.F, b.h)
    assert float((P - ref).abs().max()) <= 1e-12 * float(ref.abs().max())
    assert torch.equal(stress(b.F, b.h), ref)


@pytest.mark.parametrize("name", NAMES)
def test_stress_is_linear_in_E(name):
    """The nondimensional training premise: Ptilde(F, h; E) = E Ptilde(F, h; 1)."""
    m1 = nondimensional_material(name, 3)
    mE = Material.preset(name, 3)
    E = mE.elasticity.params.E
    assert with_young_modulus(mE).to_dict() == m1.to_dict()
    b = sample_batch(sampling_spec(m1, "paper", deps_scale=2.0), 2000, seed=4)
    P1, PE = m1.elastoplastic_stress(b.F, b.h), mE.elastoplastic_stress(b.F, b.h)
    assert float((PE - E * P1).abs().max()) <= 1e-11 * float(PE.abs().max())


def test_bad_arguments():
    m = nondimensional_material("sand", 2)
    with pytest.raises(ValueError, match="sampling"):
        sampling_spec(m, "far")
    with pytest.raises(ValueError, match="deps_scale"):
        sampling_spec(m, "paper", deps_scale=0.0)
    with pytest.raises(ValueError, match="n = 0"):
        sample_batch(sampling_spec(m), 0, seed=0)
    with pytest.raises(ValueError, match="stream"):
        generator_for(0, 0, "validation")


def test_mixed_batches_are_half_paper_half_near():
    """A "mixed" batch is a paper batch of n - n//2 followed by a near batch of n//2 drawn from their own
    streams: reproducible by (seed, step), and its near half has F close to F0."""
    from plasticitynet.training import nondimensional_material, sample_batch, sampling_spec

    m = nondimensional_material("sand", 3)
    spec = sampling_spec(m, "mixed")
    b = sample_batch(spec, 101, seed=4, step=7)
    again = sample_batch(spec, 101, seed=4, step=7)
    assert len(b) == 101 and torch.equal(b.F, again.F) and torch.equal(b.F0, again.F0)
    paper = sample_batch(spec.with_(sampling="paper"), 51, seed=4, step=7)
    assert torch.equal(b.F[:51], paper.F) and torch.equal(b.F0[:51], paper.F0)
    gap = torch.linalg.matrix_norm(b.F - b.F0) / torch.linalg.matrix_norm(b.F0)
    assert float(gap[51:].max()) < 0.5 < float(gap[:51].median())
    assert sampling_spec(m, "mixed").to_dict()["near_max_angle"] is not None
    with pytest.raises(ValueError, match="sampling"):
        sampling_spec(m, "fancy")


def test_a_wide_share_draws_twice_the_perturbation_from_its_own_stream():
    """wide_fraction f: the first n - round(f n) samples are the batch f = 0 draws with that size, the rest
    have deps in WIDE_SCALE x the range (and reach beyond 1x); the model file's distribution records it."""
    from plasticitynet.training import nondimensional_material, sample_batch, sampling_spec
    from plasticitynet.training.sampling import WIDE_SCALE

    m = nondimensional_material("snow", 3)
    spec = sampling_spec(m, "mixed")
    wide = spec.with_(wide_fraction=0.25)
    b = sample_batch(wide, 400, seed=3, step=5)
    base = sample_batch(spec, 300, seed=3, step=5)
    assert len(b) == 400 and torch.equal(b.F[:300], base.F) and torch.equal(b.F0[:300], base.F0)
    assert torch.equal(b.F, sample_batch(wide, 400, seed=3, step=5).F)
    deps = (torch.log(b.Sigma) - torch.log(b.Sigma0)).abs().amax(dim=1)
    r = spec.deps
    assert float(deps[:300].max()) <= r
    assert float(deps[300:].max()) <= WIDE_SCALE * r and float((deps[300:] > r).float().mean()) > 0.5
    d = wide.to_dict()
    assert d["wide_fraction"] == 0.25 and d["wide_deps_range"] == [-WIDE_SCALE * r, WIDE_SCALE * r]
    assert "wide_fraction" not in spec.to_dict()
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match="wide_fraction"):
            spec.with_(wide_fraction=bad)
