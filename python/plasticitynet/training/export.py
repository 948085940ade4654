"""Export of a trained network as a TorchScript file for the C++ simulator (and `load_model`).

The file's forward(x: Tensor) -> Tensor is the network N(x), shape (B, 1), in float64 (for an energy,
x = [vec F, vec F0, h] whatever its representation: a "principal" energy maps x to the MLP's input inside
forward, see nets.EnergyNet; metadata.widths and input_width are the MLP's); the
consumer applies the rest: for kind "energy" the correction of eq. 8 (c = grad_F N(F0, F0, h) -
Ptilde(F0, h)), the regularizer of eq. 11 and the scale E; for kind "return_map" the clamp
dgamma = min(N, ||dev eps||) of eq. 12. A JSON metadata entry "metadata.json" in `_extra_files`
describes the model (FORMAT_VERSION 1; fields in `energy_metadata` / `return_map_metadata`).

Model files are executable code to LibTorch: load only trusted files (the shipped ones are pinned by
sha256 in models/MANIFEST).
"""

from __future__ import annotations

import copy
import datetime
import hashlib
import json
import os
from pathlib import Path

import torch
from torch import nn

from ..materials import Material
from .energy import check_form
from .nets import MLP
from .targets import TRAINING_E

FORMAT = "plasticitynet-model"
FORMAT_VERSION = 1
METADATA_KEY = "metadata.json"
KINDS = ("energy", "return_map")

#: The "energy" entry of the metadata per energy_form (energy.ENERGY_FORMS).
_TAIL = "; N, Ptilde and mu at E = 1; grad_F: derivative in the first d*d inputs"
ENERGY_DESCRIPTIONS = {
    "eq8": "Psi(F, F0, h) = E [N(F, F0, h) - (grad_F N(F0, F0, h) - Ptilde(F0, h)) : F + w mu/2 ||F - F0||^2] "
    "(paper eqs. 8, 11" + _TAIL + ")",
    "local_identity": "Psi(F, F0, h) = E [N(F, F0, h) - grad_F N(I, F0, h) : F + w mu/2 ||F - F0||^2] "
    "(a form the paper rejected, sec. 5.2" + _TAIL + ")",
    "global_identity": "Psi(F, F0, h) = E [N(F, I, h) - grad_F N(I, I, h) : F + w mu/2 ||F - F0||^2] "
    "(a form the paper rejected, sec. 5.2; the F0 slot is the identity" + _TAIL + ")",
    "global": "Psi(F, F0, h) = E [N(F, I, h) + w mu/2 ||F - F0||^2] "
    "(a form the paper rejected, sec. 5.2; the F0 slot is the identity" + _TAIL + ")",
}

ENERGY_RESCALE = (
    "multiply Psi, grad Psi and Hess Psi by the scene's Young's modulus E in Pa; "
    "the network input is dimensionless"
)
RETURN_MAP_RESCALE = "none: the return mapping is independent of E (Sigma and h = tau_Y / (2 mu) are dimensionless)"


def sha256_of(path: str | os.PathLike) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def script_network(net: MLP | torch.jit.ScriptModule) -> torch.jit.ScriptModule:
    """A float64 TorchScript copy of `net` (forward(x) -> N(x), (B, 1)), in eval mode. `net` may be a
    ScriptModule already (the trainer scripts its network when training starts, sharing its parameters:
    compiling reads the class's source file, which may have changed by the end of a long run)."""
    with torch.no_grad():  # a ScriptModule's copy clones its tensors: under no_grad they are leaves again
        net64 = copy.deepcopy(net).to(torch.float64).eval()
    for p in net64.parameters():
        p.requires_grad_(True)
    return net64 if isinstance(net64, torch.jit.ScriptModule) else torch.jit.script(net64)


def _layer_parameters(net: nn.Module) -> list[list[str]]:
    """[[weight name, bias name], ...] per linear layer, in order (for a C++ reader of the weights)."""
    names = [name for name, _ in net.named_parameters()]
    return [[w, b] for w, b in zip(names[0::2], names[1::2])]


def _common(kind: str, material: Material, net: MLP, recipe: dict, errors: dict | None) -> dict:
    if material.elasticity.params.E != TRAINING_E:
        raise ValueError(f"material E = {material.elasticity.params.E}: models are trained and exported with E = 1")
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "material": material.to_dict(),
        "training_E": TRAINING_E,
        "dim": material.dim,
        "widths": list(net.widths),
        "input_width": net.widths[0],
        "activation": "silu",
        "output": "N(x)",
        "layer_parameters": _layer_parameters(net),
        "recipe": dict(recipe),
        "errors": dict(errors or {}),
        "torch_version": torch.__version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def energy_metadata(
    material: Material,
    net: MLP,
    has_hardening: bool,
    recipe: dict,
    errors: dict | None = None,
    return_map: dict | None = None,
    energy_form: str = "eq8",
    parameters: list[dict] | None = None,
) -> dict:
    """Metadata of an energy model. `return_map`: {"type": "analytic"} (default) or
    {"type": "learned", "file": path relative to the model's folder, "sha256": ...}. `energy_form`: eq. 8 or
    one of the rejected forms of the paper's Fig. 11 (energy.ENERGY_FORMS), recorded as "energy_form".
    `parameters`: a parametric model's ranges (parameters.ParameterSpace.to_metadata), recorded as
    "parameters" with `material` the family's reference; absent for a dedicated model."""
    d = material.dim
    representation = getattr(net, "representation", "raw")
    tail = (["h"] if has_hardening else []) + [
        f"u({p['field']}) = 2 (value - {p['min']:g}) / ({p['max']:g} - {p['min']:g}) - 1" for p in parameters or []
    ]
    forward_layout = [f"F (row-major, {d * d})", f"F0 (row-major, {d * d})"] + tail
    if representation == "raw":
        layout = forward_layout
    else:
        layout = [f"G = U^T F V (row-major, {d * d})", f"Sigma0 ({d})"] + tail
    meta = _common("energy", material, net, recipe, errors)
    meta.update(
        rescale=ENERGY_RESCALE,
        representation=representation,
        input_layout=layout,
        forward_input_layout=forward_layout,
        frame=(
            "F0 = U diag(Sigma0) V^T, the polar SVD of pnet::polar_svd (plasticitynet.training.frames); "
            "forward(x) computes the frame itself"
            if representation == "principal"
            else "none: the MLP takes forward's input"
        ),
        has_hardening=has_hardening,
        energy_form=check_form(energy_form),
        energy=ENERGY_DESCRIPTIONS[energy_form],
        return_map=dict(return_map or {"type": "analytic"}),
    )
    if parameters:
        meta["parameters"] = [dict(p) for p in parameters]
    return meta


def return_map_metadata(material: Material, net: MLP, recipe: dict, errors: dict | None = None) -> dict:
    d = material.dim
    meta = _common("return_map", material, net, recipe, errors)
    meta.update(
        rescale=RETURN_MAP_RESCALE,
        input_layout=[f"Sigma (singular values clamped to >= 1e-4, {d})", "h"],
        dgamma=(
            "dgamma = min(N(x), ||dev eps||), eps = log(Sigma_c); where y(Sigma_c, h) > 0: "
            "Z = exp(eps - dgamma dev(eps) / ||dev eps||), else Z = Sigma_c (paper eq. 12)"
        ),
    )
    return meta


def export_model(path: str | os.PathLike, net: MLP, metadata: dict) -> Path:
    """Write the float64 TorchScript of `net` with `metadata` to `path` atomically (a temporary file in the
    same folder, then rename): a reader never sees a half-written model. Returns the path."""
    if metadata.get("kind") not in KINDS:
        raise ValueError(f"metadata.kind = {metadata.get('kind')!r}: expected one of {', '.join(KINDS)}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    scripted = script_network(net)
    text = json.dumps(metadata, indent=2, sort_keys=False)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    try:
        torch.jit.save(scripted, str(tmp), _extra_files={METADATA_KEY: text})
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path
