"""Reading a PlasticityNet model file (TorchScript + metadata, see training/export.py) back into torch.

    model = plasticitynet.load_model("models/snow_2d.pt", E=1.4e5)
    model.psi(F, F0, h)        # Psi(F, F0, h), J/m^3 (scaled by E), (B,)
    model.gradient(F, F0, h)   # dPsi/dF, Pa, (B, d, d)
    model.hessian(F, F0, h)    # d^2 Psi/dF^2, (B, d*d, d*d), entry (i*d+j, k*d+l) (row-major vec)

Everything is float64. The energy is that of the paper's eqs. 8 and 11:
    Psi(F, F0, h) = E [N(F, F0, h) - c : F + w mu/2 ||F - F0||^2],  c = grad_F N(F0, F0, h) - Ptilde(F0, h),
with N the network, Ptilde and mu those of the E = 1 material (Ptilde from the library's return
mapping, or the learned one the model was trained with), so that grad Psi(F0, F0, h) = E Ptilde(F0, h).
A return-mapping model (kind "return_map") offers dgamma(Sigma, h) and project(Sigma, h) instead.

A parametric energy (metadata "parameters"; training/parameters.py) is bound to one material of its
family: load_model(path, material=...) or model.at(material), checked against the trained ranges; without
one, the family's reference material (the dedicated model's).

Model files are executable code to LibTorch: load only trusted files.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from .materials import Material
from .materials.validation import as_batch_F, as_batch_hardening, as_batch_Sigma
from .training import energy, return_map_net
from .training.export import FORMAT, FORMAT_VERSION, KINDS, METADATA_KEY, sha256_of
from .training.nets import REPRESENTATIONS, energy_input, mlp_input_width
from .training.parameters import ParameterSpace
from .training.targets import TRAINING_E, ElastoplasticStress, with_young_modulus

_REQUIRED = ("format", "format_version", "kind", "material", "dim", "widths", "input_width", "activation", "output")


def _check_metadata(meta, where: str) -> dict:
    def bad(msg):
        return ValueError(f"{where}: bad metadata: {msg}")

    if not isinstance(meta, dict):
        raise bad(f"expected a JSON object, got {type(meta).__name__}")
    for key in _REQUIRED:
        if key not in meta:
            raise bad(f"missing field {key!r}")
    if meta["format"] != FORMAT:
        raise bad(f"format = {meta['format']!r}, expected {FORMAT!r}")
    if meta["format_version"] != FORMAT_VERSION:
        raise bad(f"format_version = {meta['format_version']!r}, this reader knows {FORMAT_VERSION}")
    if meta["kind"] not in KINDS:
        raise bad(f"kind = {meta['kind']!r}, expected one of {', '.join(KINDS)}")
    d = meta["dim"]
    if d not in (2, 3):
        raise bad(f"dim = {d!r}, expected 2 or 3")
    widths = meta["widths"]
    if not (isinstance(widths, list) and len(widths) >= 2 and all(isinstance(w, int) and w > 0 for w in widths)):
        raise bad(f"widths = {widths!r}, expected a list of positive integers")
    if widths[-1] != 1 or widths[0] != meta["input_width"]:
        raise bad(f"widths = {widths} do not match input_width = {meta['input_width']} and one output")
    if meta["kind"] == "energy":
        representation = meta.get("representation", "raw")
        if representation not in REPRESENTATIONS:
            raise bad(f"representation = {representation!r}, expected one of {', '.join(REPRESENTATIONS)}")
        k = len(meta.get("parameters", [])) if isinstance(meta.get("parameters", []), list) else 0
        allowed = (mlp_input_width(d, False, representation, k), mlp_input_width(d, True, representation, k))
        form = meta.get("energy_form", "eq8")  # files written before it existed are eq. 8
        if form not in energy.ENERGY_FORMS:
            raise bad(f"energy_form = {form!r}, expected one of {', '.join(energy.ENERGY_FORMS)}")
    else:
        allowed = (d + 1,)
    if meta["input_width"] not in allowed:
        raise bad(f"input_width = {meta['input_width']} for a {d}D {meta['kind']} model (expected one of {allowed})")
    if meta["activation"] != "silu":
        raise bad(f"activation = {meta['activation']!r}, expected 'silu'")
    try:
        material = Material.from_dict(meta["material"], d)
    except ValueError as err:
        raise bad(f"material: {err}") from None
    if "parameters" in meta:
        if meta["kind"] != "energy":
            raise bad("parameters: only an energy can be parametric")
        ParameterSpace.from_metadata(meta["parameters"], material, f"{where}: bad metadata")
    return meta


def read_model_file(path: str | os.PathLike) -> tuple[torch.jit.ScriptModule, dict]:
    """(network in float64, metadata) of a model file; ValueError naming the file for a missing or
    unreadable file or bad metadata."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such model file")
    extra = {METADATA_KEY: ""}
    try:
        network = torch.jit.load(str(path), map_location="cpu", _extra_files=extra)
    except Exception as err:  # torch raises RuntimeError (and others) for garbled archives
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ValueError(f"{path}: not a readable TorchScript model file ({first})") from None
    text = extra[METADATA_KEY]
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    if not text:
        raise ValueError(f"{path}: no {METADATA_KEY} in the file's extra files (not a PlasticityNet model)")
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: {METADATA_KEY} is not valid JSON ({err})") from None
    return network.double().eval(), _check_metadata(meta, str(path))


def _as_F(F, dim: int) -> tuple[torch.Tensor, bool]:
    return as_batch_F(torch.as_tensor(F, dtype=torch.float64) if not torch.is_tensor(F) else F.to(torch.float64), dim)


class LearnedReturnMap:
    """A learned von Mises return mapping (paper eq. 12) of kind "return_map"; float64."""

    def __init__(self, network: torch.nn.Module, metadata: dict, path: str | None = None):
        self.network = network
        self.metadata = metadata
        self.path = path
        self.dim = metadata["dim"]
        # E-invariant; y is evaluated with the E = 1 material.
        self.material = Material.from_dict(metadata["material"], self.dim)

    def _inputs(self, Sigma, h):
        Sigma, single = as_batch_Sigma(torch.as_tensor(Sigma).to(torch.float64), self.dim)
        h = as_batch_hardening(self.material.initial_hardening if h is None else h, Sigma.shape[0], Sigma)
        return Sigma, h, single

    def dgamma(self, Sigma, h=None) -> torch.Tensor:
        """dgamma_theta = min(N(Sigma_c, h), ||dev eps||), (B,) (or a scalar for one Sigma)."""
        Sigma, h, single = self._inputs(Sigma, h)
        with torch.no_grad():
            dg = return_map_net.dgamma(self.network, Sigma, h)
        return dg[0] if single else dg

    def project(self, Sigma, h=None) -> torch.Tensor:
        """Z_theta(Sigma, h): the projection where y(Sigma_c, h) > 0, Sigma_c elsewhere, (B, d)."""
        Sigma, h, single = self._inputs(Sigma, h)
        with torch.no_grad():
            Z = return_map_net.project(self.network, self.material, Sigma, h)
        return Z[0] if single else Z

    def __call__(self, Sigma: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """The ReturnMap callable of targets.ElastoplasticStress (batched; evaluated in float64, the
        result cast back to Sigma's dtype)."""
        with torch.no_grad():
            Z = return_map_net.project(self.network, self.material, Sigma.to(torch.float64), h.to(torch.float64))
        return Z.to(Sigma.dtype)


class LearnedEnergy:
    """A PlasticityNet energy (kind "energy"): Psi, its gradient and Hessian in F (see the module docstring)."""

    def __init__(
        self,
        network: torch.nn.Module,
        metadata: dict,
        E: float | None = None,
        return_map: LearnedReturnMap | None = None,
        path: str | None = None,
        material: Material | dict | None = None,
    ):
        self.network = network
        self.metadata = metadata
        self.path = path
        self.dim = metadata["dim"]
        where = path or "model"
        #: "raw" (the paper's [F, F0, h]) or "principal" (frame-indifferent; nets.EnergyNet).
        self.representation = metadata.get("representation", "raw")
        #: "eq8" (the paper's) or a form it rejected in sec. 5.2 (training.energy.ENERGY_FORMS).
        self.energy_form = metadata.get("energy_form", "eq8")
        reference = Material.from_dict(metadata["material"], self.dim)
        #: A parametric model's family (None for a dedicated model) and the bound material's values.
        self.parameters = (
            ParameterSpace.from_metadata(metadata["parameters"], reference, where) if "parameters" in metadata else None
        )
        k = len(self.parameters) if self.parameters else 0
        self.has_hardening = metadata["input_width"] == mlp_input_width(self.dim, True, self.representation, k)
        if self.parameters is not None:
            self.parameter_values = self.parameters.values_of(reference if material is None else material, where)
            self.training_material = self.parameters.material_at(self.parameter_values)
            values = torch.tensor([self.parameter_values], dtype=torch.float64)
            self._parameter_inputs = self.parameters.inputs(values)  # (1, K)
        else:
            if material is not None:
                raise ValueError(f"{where}: material= binds a parametric model; this model was trained for one material")
            self.parameter_values = []
            self.training_material = reference
        self.E = float(metadata.get("training_E", TRAINING_E) if E is None else E)
        #: The material at the requested E (Pa).
        self.material = with_young_modulus(self.training_material, E=self.E)
        self.return_map = return_map
        self.stress_nd = ElastoplasticStress(self.training_material, return_map)

    # --- inputs ---------------------------------------------------------------------------------
    def _inputs(self, F, F0, h):
        F, single = _as_F(F, self.dim)
        F0, single0 = _as_F(F0, self.dim)
        if F0.shape != F.shape:
            raise ValueError(f"F0: shape {tuple(F0.shape)} does not match F {tuple(F.shape)}")
        h = as_batch_hardening(self.training_material.initial_hardening if h is None else h, F.shape[0], F)
        return F, F0, h, single and single0

    @property
    def hardening_range(self) -> tuple[float, float] | None:
        """The range of the network's hardening input in training (recipe.distribution.h_range; for
        files that do not record it, docs/physics.md's: Cam-Clay [-0.5, 0] in 2D and [-1, 0] in 3D, von
        Mises [0, 1]); None for a model without hardening input."""
        if not self.has_hardening:
            return None
        rng = self.metadata.get("recipe", {}).get("distribution", {}).get("h_range")
        if rng is not None:
            return float(rng[0]), float(rng[1])
        if self.training_material.plasticity.name == "cam_clay":
            return (-0.5 if self.dim == 2 else -1.0), 0.0
        return 0.0, 1.0

    def network_hardening(self, h: torch.Tensor) -> torch.Tensor:
        """The network's input for hardening states h (docs/physics.md, as the C++ simulator): Cam-Clay
        h = min(a, 0), von Mises h itself, clamped to hardening_range."""
        lo, hi = self.hardening_range
        if self.training_material.plasticity.name == "cam_clay":
            h = torch.clamp(h, max=0.0)
        return torch.clamp(h, lo, hi)

    def _net_h(self, h):
        """The network's inputs after F0 for hardening states h (B,): h, then a parametric model's parameters."""
        if self.parameters is None:
            return self.network_hardening(h) if self.has_hardening else None
        parts = [self.network_hardening(h).reshape(-1, 1)] if self.has_hardening else []
        parts.append(self._parameter_inputs.expand(h.shape[0], -1))
        return torch.cat(parts, dim=1)

    def at(self, material: Material | dict) -> "LearnedEnergy":
        """A parametric model bound to another material of its family (ValueError outside the ranges)."""
        return LearnedEnergy(self.network, self.metadata, E=self.E, return_map=self.return_map, path=self.path,
                             material=material)

    @property
    def mu(self) -> float:
        """Shear modulus at E = 1 (the regularizer w mu/2 ||F - F0||^2 is scaled by E with the rest)."""
        return self.training_material.mu

    # --- stress ------------------------------------------------------------------------------------
    def Ptilde(self, F, h=None) -> torch.Tensor:
        """E Ptilde(F, h), with the model's return mapping (analytic or learned), (B, d, d)."""
        F, _, h, single = self._inputs(F, F, h)
        P = self.E * self.stress_nd(F, h)
        return P[0] if single else P

    def correction(self, F0, h=None) -> torch.Tensor:
        """E c = E (grad_F N(F0, F0, h) - Ptilde(F0, h)), (B, d, d) (eq. 8; the other forms' c otherwise)."""
        F0, _, h, single = self._inputs(F0, F0, h)
        c = self._c(F0, h)
        return self.E * (c[0] if single else c)

    def _c(self, F0, h):
        with torch.no_grad():
            P0 = self.stress_nd(F0, h)
        return energy.correction(self.network, F0, self._net_h(h), P0, form=self.energy_form).detach()

    def _slot(self, F0):
        """The network's F0 input: F0, or the identity for a global energy form."""
        return energy.network_reference(self.energy_form, F0)

    # --- energy ----------------------------------------------------------------------------------
    def psi(self, F, F0, h=None, w: float = 0.0) -> torch.Tensor:
        """Psi(F, F0, h) scaled by E, (B,); differentiable in F."""
        F, F0, h, single = self._inputs(F, F0, h)
        c = self._c(F0, h)
        value = self.network(energy_input(F, self._slot(F0), self._net_h(h)))[:, 0] - (c * F).sum((-2, -1))
        if w != 0.0:
            D = F - F0
            value = value + 0.5 * w * self.mu * (D * D).sum((-2, -1))
        value = self.E * value
        return value[0] if single else value

    def _gradient(self, F, F0, h, w, c, create_graph):
        _, dN = energy.network_gradient(self.network, F, self._slot(F0), self._net_h(h), create_graph=create_graph)
        g = dN - c
        if w != 0.0:
            g = g + w * self.mu * (F - F0)
        return self.E * g

    def gradient(self, F, F0, h=None, w: float = 0.0) -> torch.Tensor:
        """dPsi/dF = E (grad_F N(F, F0, h) - c + w mu (F - F0)), (B, d, d). Differentiable in F when F
        requires grad (the graph is then kept)."""
        F, F0, h, single = self._inputs(F, F0, h)
        g = self._gradient(F, F0, h, w, self._c(F0, h), create_graph=F.requires_grad)
        if not F.requires_grad:
            g = g.detach()
        return g[0] if single else g

    def hessian(self, F, F0, h=None, w: float = 0.0) -> torch.Tensor:
        """d^2 Psi/dF^2 = E (Hess_F N + w mu I), (B, d*d, d*d), row-major vec: entry (i*d+j, k*d+l) =
        d^2 Psi / dF_ij dF_kl. Not projected to PSD (the simulator does that)."""
        F, F0, h, single = self._inputs(F, F0, h)
        c = self._c(F0, h)
        B, d = F.shape[0], self.dim
        with torch.enable_grad():
            Fg = F.detach().requires_grad_(True)
            g = self._gradient(Fg, F0, h, w, c, create_graph=True).reshape(B, d * d)
            rows = [
                torch.autograd.grad(g[:, k].sum(), Fg, retain_graph=k < d * d - 1)[0].reshape(B, d * d)
                for k in range(d * d)
            ]
        H = torch.stack(rows, dim=1)
        return H[0] if single else H


def load_model(path, E: float | None = None, return_map=None, material=None):
    """Load a PlasticityNet model file: a LearnedEnergy (kind "energy") or a LearnedReturnMap (kind
    "return_map"). E: Young's modulus (Pa) the energy is scaled by (default: the training E = 1).
    return_map: for an energy trained with a learned return mapping, the return-map model (a path or a
    LearnedReturnMap) to use instead of the file named in its metadata (default: that file, resolved
    beside the model and checked against its sha256). material: for a parametric energy, the material (a
    Material or a description dict) it is bound to (default: its family's reference). ValueError, naming
    the file, on any problem."""
    path = Path(path)
    network, meta = read_model_file(path)
    if meta["kind"] == "return_map":
        return LearnedReturnMap(network, meta, path=str(path))
    rm_info = meta.get("return_map", {"type": "analytic"})
    rm = None
    if isinstance(rm_info, dict) and rm_info.get("type") == "learned":
        if return_map is None:
            rm_path = path.parent / str(rm_info.get("file", ""))
            if not rm_path.is_file():
                raise ValueError(
                    f"{path}: trained with the learned return mapping {rm_info.get('file')!r}, not found at {rm_path}"
                )
            if rm_info.get("sha256") and sha256_of(rm_path) != rm_info["sha256"]:
                raise ValueError(
                    f"{path}: the return-map model {rm_path} does not match the sha256 the energy was trained with"
                )
            return_map = rm_path
        rm = return_map if isinstance(return_map, LearnedReturnMap) else load_model(return_map)
        if not isinstance(rm, LearnedReturnMap) or rm.dim != meta["dim"]:
            raise ValueError(f"{path}: {return_map} is not a {meta['dim']}D return-map model")
    elif not (isinstance(rm_info, dict) and rm_info.get("type") == "analytic"):
        raise ValueError(f"{path}: bad metadata: return_map = {rm_info!r}")
    return LearnedEnergy(network, meta, E=E, return_map=rm, path=str(path), material=material)


__all__ = ["load_model", "read_model_file", "LearnedEnergy", "LearnedReturnMap"]
