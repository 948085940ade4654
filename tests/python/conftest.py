"""Shared fixtures of the material tests: materials by name and random states covering every branch."""

from __future__ import annotations

import copy

import pytest
import torch

from plasticitynet.materials import PRESETS, CamClay, DruckerPrager, Material, VonMises


def _variant(preset: str, name: str, **plasticity) -> dict:
    desc = copy.deepcopy(PRESETS[preset])
    desc["name"] = name
    desc["plasticity"].update(plasticity)
    return desc


#: Every plastic material the tests sweep: the presets, the paper Cam-Clay variant and von Mises
#: without hardening (hardening_coefficient 0), closed form (metal) and root find (metal_nh).
MATERIAL_DESCRIPTIONS = {
    "sand": PRESETS["sand"],
    "snow": PRESETS["snow"],
    "snow_paper": _variant("snow", "snow_paper", variant="paper"),
    "metal": PRESETS["metal"],
    "metal_perfect": _variant("metal", "metal_perfect", hardening_coefficient=0.0),
    "metal_nh": PRESETS["metal_nh"],
    "metal_nh_perfect": _variant("metal_nh", "metal_nh_perfect", hardening_coefficient=0.0),
}


def make_material(name: str, dim: int) -> Material:
    return Material.from_dict(copy.deepcopy(MATERIAL_DESCRIPTIONS[name]), dim)


def random_rotations(n: int, d: int, generator: torch.Generator, dtype=torch.float64) -> torch.Tensor:
    """n Haar-random rotations (det +1), (n, d, d)."""
    Q, R = torch.linalg.qr(torch.randn(n, d, d, generator=generator, dtype=torch.float64))
    Q = Q * torch.sign(torch.diagonal(R, dim1=1, dim2=2))[:, None, :]
    Q[:, :, 0] *= torch.sign(torch.linalg.det(Q))[:, None]
    return Q.to(dtype)


def sample_state(material: Material, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(Sigma, h) in float64, (n, d) and (n,), spread so that every branch of `material` occurs:
    eps = log(J)/d 1 + r n with n a random unit deviatoric direction."""
    g = torch.Generator().manual_seed(seed)
    d = material.dim
    p = material.plasticity

    def uniform(lo, hi):
        return lo + (hi - lo) * torch.rand(n, generator=g, dtype=torch.float64)

    if isinstance(p, DruckerPrager):
        log_J, r, h = uniform(-0.9, 0.3), uniform(0.0, 0.4), torch.zeros(n, dtype=torch.float64)
    elif isinstance(p, CamClay):
        log_J, r, h = uniform(-0.5, 0.2), uniform(0.0, 0.4), uniform(-0.8, -0.05)
    elif isinstance(p, VonMises):
        log_J, r, h = uniform(-0.6, 0.6), uniform(0.0, 0.6), uniform(0.005, 0.3)
    else:
        log_J, r, h = uniform(-0.6, 0.6), uniform(0.0, 0.5), torch.zeros(n, dtype=torch.float64)
    direction = torch.randn(n, d, generator=g, dtype=torch.float64)
    direction -= direction.mean(-1, keepdim=True)
    direction /= torch.linalg.vector_norm(direction, dim=-1, keepdim=True)
    eps = log_J[:, None] / d + r[:, None] * direction
    return torch.exp(eps), h


def sample_F(material: Material, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(F, h): F = R1 diag(Sigma) R2 with (Sigma, h) from sample_state."""
    Sigma, h = sample_state(material, n, seed)
    g = torch.Generator().manual_seed(seed + 1)
    d = material.dim
    return random_rotations(n, d, g) @ (Sigma[:, :, None] * random_rotations(n, d, g)), h


@pytest.fixture
def material_factory():
    return make_material


@pytest.fixture
def state_sampler():
    return sample_state


@pytest.fixture
def F_sampler():
    return sample_F


@pytest.fixture
def rotation_sampler():
    return random_rotations


@pytest.fixture
def one_thread():
    """Tiny training batches run faster on one thread, and do not stall when other jobs hold the cores."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
