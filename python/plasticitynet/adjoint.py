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
elastic, sand, snow and metal particle bodies (plasticitynet_sim.MpmRollout): the particles' positions,
differentiable in E, v0, the friction angle, Cam-Clay's xi and beta and the initial hardening.

`coupled_positions(scene, E, mesh_E, v0, mesh_v0, steps, dt, states)` does it for an implicit MPM-FEM coupled
rollout (plasticitynet_sim.CoupledRollout): the particles' and the mesh nodes' positions, differentiable in both
Young's moduli, both start velocities and the particles' friction angle.

Losses that need no particle correspondence: `grid_mass(x, mass, scene)` is the particles' mass on the
scene's grid (Simulation.grid_mass(), the quadratic B-spline), differentiable in the positions, and
`height_profile(x, mass, scene, density)` the deposit's height over each grid column (the mass above a
node of the floor's line or plane over density dx^(dim-1)); observed frames of another run, another
resolution or another particle count compare through them.
"""
from __future__ import annotations

import copy
import math
import warnings
from typing import Sequence

import numpy as np
import torch


def _sim():
    import plasticitynet_sim  # the simulator; imported on first use

    return plasticitynet_sim


def with_youngs_modulus(scene: dict, youngs_modulus: float, initial_hardening: float | None = None,
                        fields: Sequence[str] = ("meshes", "objects")) -> dict:
    """A copy of a scene dict whose meshes' and particle objects' materials (those of `fields`) have Young's modulus E
    (Pa) and, when given, the initial hardening h0 (von Mises: tau_Y = 2 mu h0). The material must be written out in
    the scene (a dict with an "elasticity" block), not a preset's name."""
    out = copy.deepcopy(scene)
    for field in fields:
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


def _rollout_gradients(ctx, grad, parameters: Sequence[str]):
    """dL/dE, dL/dv0 (None where v0 was not given) and dL/d of each named parameter (None where ctx.given says it
    was not given), by the adjoint of the rollout ctx.rollout kept."""
    out = ctx.rollout.backward(_state_cotangents(grad, ctx.states))
    dE = torch.tensor(out["youngs_modulus"], dtype=torch.float64)
    dv0 = torch.from_numpy(out["v0"]) if ctx.has_v0 else None
    return dE, dv0, [torch.tensor(out[name], dtype=torch.float64) if given else None
                     for name, given in zip(parameters, ctx.given)]


class _FemPositions(torch.autograd.Function):
    @staticmethod
    def forward(ctx, youngs_modulus, v0, initial_hardening, scene, steps, dt, states, newton_tolerance, integrator):
        h0 = None if initial_hardening is None else float(initial_hardening)
        rollout = _sim().FemRollout(with_youngs_modulus(scene, float(youngs_modulus), h0), newton_tolerance,
                                    integrator)
        v = None if v0 is None else v0.detach().cpu().numpy().astype(np.float64)
        x = rollout.forward(int(steps), float(dt), v0=v, states=sorted(set(states)))["x"]
        ctx.rollout, ctx.states, ctx.has_v0, ctx.given = rollout, list(states), v0 is not None, [h0 is not None]
        return torch.from_numpy(np.stack([x[k] for k in states]))

    @staticmethod
    def backward(ctx, grad):
        dE, dv0, (dh0,) = _rollout_gradients(ctx, grad, ["initial_hardening"])
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


# The plasticity parameters mpm_positions differentiates: (its keyword, the scene's field, the models that have it).
_PLASTICITY_PARAMETERS = (
    ("friction_angle", "friction_angle_deg", ("drucker_prager", "cam_clay")),
    ("xi", "xi", ("cam_clay",)),
    ("beta", "beta", ("cam_clay",)),
)


def with_plasticity(scene: dict, field: str, value: float, models: Sequence[str]) -> dict:
    """A copy of a scene dict whose particle objects of the plasticity models `models` have the plasticity field
    `field` (e.g. "friction_angle_deg", "xi") set to value; their material must be written out (a dict with a
    "plasticity" block), and one object at least must have one of the models (ValueError naming the field)."""
    out = copy.deepcopy(scene)
    found = False
    for k, body in enumerate(out.get("objects", [])):
        material = body.get("material")
        if not isinstance(material, dict) or "plasticity" not in material:
            raise ValueError(f"objects[{k}].material: write the material out (a dict with a \"plasticity\" "
                             f"block) to set plasticity.{field}")
        if material["plasticity"].get("model") in models:
            material["plasticity"][field] = float(value)
            found = True
    if not found:
        raise ValueError(f"no object's material has plasticity.{field} (model {' or '.join(models)}): the scene's "
                         "gradient in it would be 0")
    return out


class _MpmPositions(torch.autograd.Function):
    @staticmethod
    def forward(ctx, youngs_modulus, v0, scene, steps, dt, states, newton_tolerance, integrator, initial_hardening,
                *plasticity):
        h0 = None if initial_hardening is None else float(initial_hardening)
        s = with_youngs_modulus(scene, float(youngs_modulus), h0)
        for (name, field, models), value in zip(_PLASTICITY_PARAMETERS, plasticity):
            if value is not None:
                try:
                    s = with_plasticity(s, field, float(value), models)
                except ValueError as e:
                    raise ValueError(f"{name}: {e}") from None
        rollout = _sim().MpmRollout(s, newton_tolerance, integrator)
        v = None if v0 is None else v0.detach().cpu().numpy().astype(np.float64)
        x = rollout.forward(int(steps), float(dt), v0=v, states=sorted(set(states)))["x"]
        if rollout.unconverged_steps:
            warnings.warn(f"{rollout.unconverged_steps} of {steps} steps stopped short of newton_tolerance "
                          f"({newton_tolerance:g} m/s): the gradient is that of the path taken, not of converged "
                          "steps (docs/adjoint.md)", RuntimeWarning, stacklevel=2)
        ctx.rollout, ctx.states, ctx.has_v0 = rollout, list(states), v0 is not None
        ctx.given = [initial_hardening is not None] + [value is not None for value in plasticity]
        return torch.from_numpy(np.stack([x[k] for k in states]))

    @staticmethod
    def backward(ctx, grad):
        names = ["initial_hardening"] + [name for name, _, _ in _PLASTICITY_PARAMETERS]
        dE, dv0, parameters = _rollout_gradients(ctx, grad, names)
        return (dE, dv0, None, None, None, None, None, None, *parameters)


def mpm_positions(scene: dict, youngs_modulus: torch.Tensor, v0: torch.Tensor | None, steps: int, dt: float,
                  states: Sequence[int], newton_tolerance: float = 1e-10, friction_angle: torch.Tensor | None = None,
                  integrator: str = "lagged", xi: torch.Tensor | None = None, beta: torch.Tensor | None = None,
                  initial_hardening: torch.Tensor | None = None) -> torch.Tensor:
    """The particles' positions (len(states), particles, dim) at the kept states of `steps` implicit MPM
    steps of dt from the scene's particles (v0: their start velocities instead), differentiable in
    youngs_modulus (a 0-d tensor, Pa), v0 and, where given (0-d tensors that set every object's value):
    friction_angle (degrees; Drucker-Prager sand and Cam-Clay snow), Cam-Clay's xi and beta, and
    initial_hardening (Cam-Clay's a; von Mises' h0 = tau_Y / (2 mu)): plasticitynet_sim.MpmRollout, elastic,
    sand, snow and metal bodies with APIC or AFLIP transfers, slip walls and a sticky or Coulomb floor (the latter
    under "return_map"), the steps "lagged" or "return_map"
    (docs/adjoint.md)."""
    for k in states:
        if not 0 <= int(k) <= steps:
            raise ValueError(f"states: {k} is not a state of a {steps}-step rollout (0..{steps})")
    return _MpmPositions.apply(youngs_modulus, v0, scene, steps, dt, [int(k) for k in states], newton_tolerance,
                               integrator, initial_hardening, friction_angle, xi, beta)


class _CoupledPositions(torch.autograd.Function):
    @staticmethod
    def forward(ctx, youngs_modulus, mesh_youngs_modulus, v0, mesh_v0, friction_angle, scene, steps, dt, states,
                newton_tolerance, integrator):
        s = with_youngs_modulus(scene, float(youngs_modulus), fields=("objects",))
        s = with_youngs_modulus(s, float(mesh_youngs_modulus), fields=("meshes",))
        if friction_angle is not None:
            name, field, models = _PLASTICITY_PARAMETERS[0]
            try:
                s = with_plasticity(s, field, float(friction_angle), models)
            except ValueError as e:
                raise ValueError(f"{name}: {e}") from None
        rollout = _sim().CoupledRollout(s, newton_tolerance, integrator)
        as_array = (lambda t: None if t is None else t.detach().cpu().numpy().astype(np.float64))
        out = rollout.forward(int(steps), float(dt), v0=as_array(v0), mesh_v0=as_array(mesh_v0),
                              states=sorted(set(states)))
        if rollout.unconverged_steps:
            warnings.warn(f"{rollout.unconverged_steps} of {steps} steps stopped short of newton_tolerance "
                          f"({newton_tolerance:g} m/s): the gradient is that of the path taken, not of converged "
                          "steps (docs/adjoint.md)", RuntimeWarning, stacklevel=2)
        ctx.rollout, ctx.states = rollout, list(states)
        ctx.given = (v0 is not None, mesh_v0 is not None, friction_angle is not None)
        return (torch.from_numpy(np.stack([out["x"][k] for k in states])),
                torch.from_numpy(np.stack([out["mesh_x"][k] for k in states])))

    @staticmethod
    def backward(ctx, grad_x, grad_mesh_x):
        out = ctx.rollout.backward(_state_cotangents(grad_x, ctx.states), None,
                                   _state_cotangents(grad_mesh_x, ctx.states), None)
        has_v0, has_mesh_v0, has_angle = ctx.given
        scalar = (lambda name: torch.tensor(out[name], dtype=torch.float64))
        return (scalar("youngs_modulus"), scalar("mesh_youngs_modulus"),
                torch.from_numpy(out["v0"]) if has_v0 else None,
                torch.from_numpy(out["mesh_v0"]) if has_mesh_v0 else None,
                scalar("friction_angle") if has_angle else None,
                None, None, None, None, None, None)


def coupled_positions(scene: dict, youngs_modulus: torch.Tensor, mesh_youngs_modulus: torch.Tensor,
                      v0: torch.Tensor | None, mesh_v0: torch.Tensor | None, steps: int, dt: float,
                      states: Sequence[int], newton_tolerance: float = 1e-10,
                      friction_angle: torch.Tensor | None = None,
                      integrator: str = "lagged") -> tuple[torch.Tensor, torch.Tensor]:
    """The particles' and the mesh nodes' positions ((len(states), particles, dim), (len(states), nodes, dim)) at the
    kept states of `steps` implicit MPM-FEM coupled steps of dt from the scene's start (v0, mesh_v0: the particles'
    and the nodes' start velocities instead), differentiable in youngs_modulus (the particles' E, a 0-d tensor, Pa),
    mesh_youngs_modulus (the mesh's), v0, mesh_v0 and, where given, friction_angle (degrees; every Drucker-Prager and
    Cam-Clay object's): plasticitynet_sim.CoupledRollout, elastic meshes of one material meeting the particles through
    the barrier and the scene's lagged friction (held at its lagged values in the gradient), the particles' steps
    "lagged" or "return_map" (docs/adjoint.md)."""
    for k in states:
        if not 0 <= int(k) <= steps:
            raise ValueError(f"states: {k} is not a state of a {steps}-step rollout (0..{steps})")
    return _CoupledPositions.apply(youngs_modulus, mesh_youngs_modulus, v0, mesh_v0, friction_angle, scene, steps, dt,
                                   [int(k) for k in states], newton_tolerance, integrator)


def _grid_of(scene: dict) -> tuple[np.ndarray, list[int], float]:
    """The origin, node counts and dx of the grid Simulation.grid_mass() rasterizes on (metrics/iou.cpp)."""
    try:
        lo = np.asarray(scene["domain"]["min"], dtype=np.float64)
        hi = np.asarray(scene["domain"]["max"], dtype=np.float64)
        dx = float(scene["dx"])
    except (KeyError, TypeError) as e:
        raise ValueError(f"scene: a grid needs domain.min, domain.max and dx ({e})") from None
    if not dx > 0.0:
        raise ValueError(f"scene.dx: expected a positive number, got {dx}")
    nodes = []
    for axis, extent in enumerate(hi - lo):
        r = extent / dx
        if not r >= 2.0:
            raise ValueError(f"scene.domain: axis {axis} spans {r:g} cells; need at least 2")
        nodes.append(int(math.ceil(r - 1e-9 * r)) + 1)
    return lo, nodes, dx


def grid_mass(x: torch.Tensor, mass, scene: dict) -> torch.Tensor:
    """The particles' mass on the scene's grid, kg (per metre of depth in 2D): shape (..., nodes_x, nodes_y[,
    nodes_z]) for positions x of shape (..., particles, dim), node [i, j(, k)] at domain.min + (i, j, k) dx,
    what plasticitynet_sim.Simulation.grid_mass() gives for the same particles (the quadratic B-spline;
    positions within a cell of the domain's edge are moved onto it, as there). Differentiable in x (torch
    autograd: the weights' derivative), so a loss of it pulls back through mpm_positions."""
    origin, nodes, dx = _grid_of(scene)
    dim = len(nodes)
    if x.shape[-1] != dim:
        raise ValueError(f"x: expected positions of shape (..., particles, {dim}), got {tuple(x.shape)}")
    m = torch.as_tensor(mass, dtype=x.dtype, device=x.device)
    if m.shape != x.shape[-2:-1]:
        raise ValueError(f"mass: expected {x.shape[-2]} masses, got shape {tuple(m.shape)}")
    batch = x.shape[:-2]
    flat = x.reshape(-1, x.shape[-2], dim)
    s = (flat - torch.as_tensor(origin, dtype=x.dtype, device=x.device)) / dx
    upper = torch.tensor([n - 2 for n in nodes], dtype=x.dtype, device=x.device)
    s = torch.minimum(torch.clamp(s, min=1.0), upper)
    base = torch.floor(s.detach() - 0.5)
    f = s - base
    w = torch.stack([0.5 * (1.5 - f) ** 2, 0.75 - (f - 1.0) ** 2, 0.5 * (f - 0.5) ** 2], dim=-1)  # (B, n, dim, 3)
    base = base.long()
    strides = [int(np.prod(nodes[a + 1:])) for a in range(dim)]
    size = int(np.prod(nodes))
    out = x.new_zeros(flat.shape[0], size)
    for offsets in np.ndindex(*([3] * dim)):
        index = sum((base[..., a] + int(offsets[a])) * strides[a] for a in range(dim))
        weight = m * torch.prod(torch.stack([w[..., a, offsets[a]] for a in range(dim)], dim=-1), dim=-1)
        out = out.scatter_add(1, index, weight)
    return out.reshape(*batch, *nodes)


def height_profile(x: torch.Tensor, mass, scene: dict, density: float) -> torch.Tensor:
    """The deposit's height over each node of the floor's line (2D: shape (..., nodes_x)) or plane (3D:
    (..., nodes_x, nodes_z)), m: the grid mass above it (grid_mass, summed along y, gravity's axis) over
    density dx^(dim-1), the height of material at that density. A loss of it needs no particle
    correspondence: an observed run's profile is taken from its own particles."""
    if not density > 0.0:
        raise ValueError(f"density: expected a positive number (kg/m^3), got {density}")
    g = grid_mass(x, mass, scene)
    dim = x.shape[-1]
    dx = float(scene["dx"])
    return g.sum(dim=g.dim() - dim + 1) / (density * dx ** (dim - 1))
