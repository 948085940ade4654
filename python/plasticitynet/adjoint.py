"""Gradients of simulated outcomes for torch (docs/adjoint.md).

`fem_positions(scene, youngs_modulus, v0, steps, dt, states)` runs an implicit FEM rollout of elastic
or von Mises bodies (plasticitynet_sim.FemRollout: backward Euler, the return mapping after each
step, IPC contact without friction) and returns the nodes' positions at the chosen states as a tensor
that torch can differentiate with respect to Young's modulus, the start's velocities and the initial
hardening (the yield stress): its backward pass is the rollout's adjoint, not a tape of torch
operations, so a torch optimizer can fit E or v0 to observed frames.

    E = torch.tensor(1e5, dtype=torch.float64, requires_grad=True)
    x = fem_positions(scene, E, None, steps=50, dt=2e-3, states=[10, 20, 50])   # (3, nodes, dim)
    loss = ((x - observed) ** 2).sum(); loss.backward(); E.grad

`mpm_positions(scene, youngs_modulus, v0, steps, dt, states)` does the same for an implicit MPM rollout of
elastic particle bodies (plasticitynet_sim.MpmRollout): the particles' positions.
"""
from __future__ import annotations

import copy
from typing import Sequence

import numpy as np
import torch


def _sim():
    import plasticitynet_sim  # the simulator; imported on first use

    return plasticitynet_sim


def with_youngs_modulus(scene: dict, youngs_modulus: float, initial_hardening: float | None = None) -> dict:
    """A copy of a scene dict whose meshes' and particle objects' materials have Young's modulus E (Pa) and, when given, the
    initial hardening h0 (von Mises: tau_Y = 2 mu h0). The material must be written out in the scene (a
    dict with an "elasticity" block), not a preset's name."""
    out = copy.deepcopy(scene)
    for field in ("meshes", "objects"):
        for k, body in enumerate(out.get(field, [])):
            if body.get("kinematic"):
                continue
            material = body.get("material")
            if not isinstance(material, dict) or "elasticity" not in material:
                raise ValueError(f"{field}[{k}].material: write the material out (a dict with an \"elasticity\" "
                                 "block) to set its parameters")
            material["elasticity"]["E"] = float(youngs_modulus)
            if initial_hardening is not None:
                material["initial_hardening"] = float(initial_hardening)
    return out


def _state_cotangents(grad: torch.Tensor, states: Sequence[int]) -> dict[int, np.ndarray]:
    """The positions' gradient (len(states), points, dim) as {state: array} for a rollout's backward; a state
    asked for twice sums its cotangents."""
    g = grad.detach().cpu().numpy().astype(np.float64)
    dL_dx: dict[int, np.ndarray] = {}
    for i, k in enumerate(states):
        dL_dx[k] = dL_dx.get(k, 0.0) + g[i]
    return dL_dx


class _FemPositions(torch.autograd.Function):
    @staticmethod
    def forward(ctx, youngs_modulus, v0, initial_hardening, scene, steps, dt, states, newton_tolerance, integrator):
        h0 = None if initial_hardening is None else float(initial_hardening)
        rollout = _sim().FemRollout(with_youngs_modulus(scene, float(youngs_modulus), h0), newton_tolerance,
                                    integrator)
        v = None if v0 is None else v0.detach().cpu().numpy().astype(np.float64)
        x = rollout.forward(int(steps), float(dt), v0=v, states=sorted(set(states)))["x"]
        ctx.rollout, ctx.states, ctx.has_v0, ctx.has_h0 = rollout, list(states), v0 is not None, h0 is not None
        return torch.from_numpy(np.stack([x[k] for k in states]))

    @staticmethod
    def backward(ctx, grad):
        out = ctx.rollout.backward(_state_cotangents(grad, ctx.states))
        dE = torch.tensor(out["youngs_modulus"], dtype=torch.float64)
        dv0 = torch.from_numpy(out["v0"]) if ctx.has_v0 else None
        dh0 = torch.tensor(out["initial_hardening"], dtype=torch.float64) if ctx.has_h0 else None
        return dE, dv0, dh0, None, None, None, None, None, None


def fem_positions(scene: dict, youngs_modulus: torch.Tensor, v0: torch.Tensor | None, steps: int, dt: float,
                  states: Sequence[int], newton_tolerance: float = 1e-10,
                  initial_hardening: torch.Tensor | None = None, integrator: str = "lagged") -> torch.Tensor:
    """The nodes' positions (len(states), nodes, dim) at the kept states `states` (0: the start; k: after
    step k) of `steps` steps of dt from the scene's start (v0: the start's velocities instead of the
    scene's), differentiable in youngs_modulus (a 0-d tensor, Pa), v0 and, for von Mises metal,
    initial_hardening (a 0-d tensor: h0 = tau_Y / (2 mu) of every element at the start). integrator: the
    steps' integrator, "lagged" or "return_map" (FemRollout)."""
    for k in states:
        if not 0 <= int(k) <= steps:
            raise ValueError(f"states: {k} is not a state of a {steps}-step rollout (0..{steps})")
    return _FemPositions.apply(youngs_modulus, v0, initial_hardening, scene, steps, dt, [int(k) for k in states],
                               newton_tolerance, integrator)


def with_friction_angle(scene: dict, friction_angle: float) -> dict:
    """A copy of a scene dict whose Drucker-Prager objects have the friction angle phi (degrees); their
    material must be written out (a dict with a "plasticity" block)."""
    out = copy.deepcopy(scene)
    for k, body in enumerate(out.get("objects", [])):
        material = body.get("material")
        if not isinstance(material, dict) or "plasticity" not in material:
            raise ValueError(f"objects[{k}].material: write the material out (a dict with a \"plasticity\" "
                             "block) to set its friction angle")
        if material["plasticity"].get("model") == "drucker_prager":
            material["plasticity"]["friction_angle_deg"] = float(friction_angle)
    return out


class _MpmPositions(torch.autograd.Function):
    @staticmethod
    def forward(ctx, youngs_modulus, v0, friction_angle, scene, steps, dt, states, newton_tolerance, integrator):
        s = with_youngs_modulus(scene, float(youngs_modulus))
        if friction_angle is not None:
            s = with_friction_angle(s, float(friction_angle))
        rollout = _sim().MpmRollout(s, newton_tolerance, integrator)
        v = None if v0 is None else v0.detach().cpu().numpy().astype(np.float64)
        x = rollout.forward(int(steps), float(dt), v0=v, states=sorted(set(states)))["x"]
        ctx.rollout, ctx.states = rollout, list(states)
        ctx.has_v0, ctx.has_phi = v0 is not None, friction_angle is not None
        return torch.from_numpy(np.stack([x[k] for k in states]))

    @staticmethod
    def backward(ctx, grad):
        out = ctx.rollout.backward(_state_cotangents(grad, ctx.states))
        dE = torch.tensor(out["youngs_modulus"], dtype=torch.float64)
        dv0 = torch.from_numpy(out["v0"]) if ctx.has_v0 else None
        dphi = torch.tensor(out["friction_angle"], dtype=torch.float64) if ctx.has_phi else None
        return dE, dv0, dphi, None, None, None, None, None, None


def mpm_positions(scene: dict, youngs_modulus: torch.Tensor, v0: torch.Tensor | None, steps: int, dt: float,
                  states: Sequence[int], newton_tolerance: float = 1e-10, friction_angle: torch.Tensor | None = None,
                  integrator: str = "lagged") -> torch.Tensor:
    """The particles' positions (len(states), particles, dim) at the kept states of `steps` implicit MPM
    steps of dt from the scene's particles (v0: their start velocities instead), differentiable in
    youngs_modulus (a 0-d tensor, Pa), v0 and, for Drucker-Prager sand, friction_angle (a 0-d tensor,
    degrees): plasticitynet_sim.MpmRollout, elastic and sand bodies with APIC transfers and slip walls, the
    steps "lagged" or "return_map" (docs/adjoint.md)."""
    for k in states:
        if not 0 <= int(k) <= steps:
            raise ValueError(f"states: {k} is not a state of a {steps}-step rollout (0..{steps})")
    return _MpmPositions.apply(youngs_modulus, v0, friction_angle, scene, steps, dt, [int(k) for k in states],
                               newton_tolerance, integrator)
