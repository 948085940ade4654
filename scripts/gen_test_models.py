#!/usr/bin/env python3
"""Writes the small model files of the model-loader tests (tests/data/models/).

Each file is a TorchScript archive in the layout of plasticitynet.training.export (a float64 MLP
layers.{0,2,4,6}.{weight,bias} with SiLU between the linear layers, forward(x) -> (B, 1), and a JSON
"metadata.json" extra file), either valid or broken in exactly one deliberate way, so that a loader
test can check that each problem is rejected with a clear message. See tests/data/models/README.md.

Small networks ([9, 8, 8, 8, 1] energy for snow 2D, [3, 8, 8, 8, 1] return map for metal_nh 2D),
random weights from fixed seeds; the metadata comes from the export helpers (energy_metadata /
return_map_metadata at E = 1, script_network) with a fixed "created" time, and the archives are
written through a buffer (root folder "archive") by a process with PYTHONHASHSEED=0 (the script
re-executes itself so), so the files are byte-identical from run to run for a given torch version
(the "torch_version" field records it).

Usage: .venv/bin/python scripts/gen_test_models.py [--out DIR] [--no-check]
After writing, every file is loaded back with torch.jit.load and checked to be broken exactly as
intended (and the valid ones to load with plasticitynet.load_model); --no-check skips that.
"""

from __future__ import annotations

import argparse
import copy
import io
import json
import math
import os
import sys
from pathlib import Path

import torch
from torch import nn

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from plasticitynet.training.export import (  # noqa: E402
    KINDS,
    METADATA_KEY,
    energy_metadata,
    return_map_metadata,
    script_network,
)
from plasticitynet.training.nets import MLP, energy_input, make_energy_net, make_mlp  # noqa: E402
from plasticitynet.training.targets import nondimensional_material  # noqa: E402

DEFAULT_OUT = ROOT / "tests" / "data" / "models"
DIM = 2
ENERGY_WIDTHS = [9, 8, 8, 8, 1]  # snow 2D: [vec F (4), vec F0 (4), h] -> 8 -> 8 -> 8 -> 1
RETURN_MAP_WIDTHS = [3, 8, 8, 8, 1]  # metal_nh 2D: [Sigma (2), h] -> ... -> 1
CREATED = "2000-01-01T00:00:00+00:00"  # fixed instead of the export time: deterministic content
GENERATOR = "scripts/gen_test_models.py"

#: file name -> one line: what is special about it (the README's table, and the report of --check).
DESCRIPTIONS = {
    "valid_energy_2d.pt": "valid: random energy MLP [9,8,8,8,1] for snow 2D (has_hardening, analytic return map)",
    "valid_return_map_2d.pt": "valid: random return-map MLP [3,8,8,8,1] for metal_nh 2D",
    "no_metadata.pt": "valid float64 MLP [9,8,8,8,1] saved without the metadata.json extra file",
    "bad_json.pt": "metadata.json is not valid JSON (the valid text with its closing brace cut off)",
    "wrong_format_version.pt": "metadata format_version 99 (this format is version 1)",
    "not_an_mlp.pt": "parameters named and shaped exactly like the [9,8,8,8,1] MLP, valid metadata, "
    "but forward() uses tanh instead of SiLU",
    "wrong_activation.pt": "metadata activation \"relu\" (the network itself is a valid SiLU MLP)",
    "shape_mismatch.pt": "metadata widths [9,8,8,8,1], but layers.2.weight is (8, 7): the layers do not chain",
    "nonfinite_weights.pt": "valid metadata, but layers.2.weight[3, 5] is NaN",
    "float32.pt": "valid metadata and MLP, but every parameter is float32 instead of float64",
    "wrong_input_width.pt": "energy metadata input_width 9 for dim 2, but widths [7,8,8,8,1] and "
    "layers.0.weight (8, 7) use 7 inputs",
    "bad_material.pt": "metadata material.elasticity.E = -1 (negative Young's modulus); the network is valid",
    "valid_principal_energy_2d.pt": "valid: random principal-input energy (EnergyNet, MLP [7,32,32,32,1]) for snow "
    "2D, forward takes [F, F0, h] (9)",
    "valid_principal_energy_3d.pt": "valid: random principal-input energy (EnergyNet, MLP [13,64,64,64,1]) for snow "
    "3D, forward takes [F, F0, h] (19)",
    "wrong_representation.pt": "metadata representation \"fancy\" (the principal network itself is valid)",
}

#: The principal-input files: an EnergyNet (parameters mlp.layers.*), MLP widths per dimension.
PRINCIPAL = {
    "valid_principal_energy_2d.pt": (2, 13),
    "valid_principal_energy_3d.pt": (3, 14),
    "wrong_representation.pt": (2, 15),
}


# --- building blocks ------------------------------------------------------------------------------
def snow():
    return nondimensional_material("snow", DIM)


def metal_nh():
    return nondimensional_material("metal_nh", DIM)


def recipe(seed: int, note: str) -> dict:
    return {"generator": GENERATOR, "seed": seed, "note": note}


def energy_meta(net: MLP, seed: int, note: str) -> dict:
    meta = energy_metadata(snow(), net, True, recipe(seed, note))
    meta["created"] = CREATED
    return meta


def dumps(meta: dict) -> str:
    return json.dumps(meta, indent=2, sort_keys=False)  # as export_model writes it


def save_raw(path: Path, module: torch.jit.ScriptModule, metadata_text: str | None) -> None:
    """torch.jit.save of a scripted module with `metadata_text` verbatim (None: no extra file).

    Saved through a buffer, so the archive's root folder is torch's "archive" (export_model saves to a
    temporary file whose name, with the process id, becomes the root folder: not reproducible)."""
    extra = {} if metadata_text is None else {METADATA_KEY: metadata_text}
    buffer = io.BytesIO()
    torch.jit.save(module, buffer, _extra_files=extra)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    try:
        tmp.write_bytes(buffer.getvalue())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def export(path: Path, net: nn.Module, meta: dict) -> None:
    """What export_model writes (script_network: a float64 TorchScript in eval mode, the metadata as
    indented JSON), but byte-reproducible (see save_raw)."""
    if meta.get("kind") not in KINDS:
        raise ValueError(f"metadata.kind = {meta.get('kind')!r}")
    save_raw(path, script_network(net), dumps(meta))


# --- the files --------------------------------------------------------------------------------------
def valid_energy_2d(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=1)
    export(path, net, energy_meta(net, 1, "valid small random energy model for loader tests"))


def valid_return_map_2d(path: Path) -> None:
    net = make_mlp(RETURN_MAP_WIDTHS, seed=2)
    meta = return_map_metadata(metal_nh(), net, recipe(2, "valid small random return-map model for loader tests"))
    meta["created"] = CREATED
    export(path, net, meta)


def no_metadata(path: Path) -> None:
    save_raw(path, script_network(make_mlp(ENERGY_WIDTHS, seed=3)), None)


def bad_json(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=4)
    text = dumps(energy_meta(net, 4, "metadata.json is not valid JSON")).rstrip()
    assert text.endswith("}")
    save_raw(path, script_network(net), text[:-1])


def wrong_format_version(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=5)
    meta = energy_meta(net, 5, "format_version 99")
    meta["format_version"] = 99
    export(path, net, meta)


class TanhMLP(MLP):
    """Same parameters (names and shapes) as MLP, different function: tanh in place of SiLU."""

    def __init__(self, widths):
        super().__init__(widths)
        for k in range(1, len(self.layers), 2):
            assert isinstance(self.layers[k], nn.SiLU)
            self.layers[k] = nn.Tanh()


def not_an_mlp(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=6)
    impostor = TanhMLP(ENERGY_WIDTHS)
    impostor.load_state_dict(net.state_dict())
    export(path, impostor, energy_meta(net, 6, "forward uses tanh, not SiLU"))


def wrong_activation(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=7)
    meta = energy_meta(net, 7, "activation relu")
    meta["activation"] = "relu"
    export(path, net, meta)


def shape_mismatch(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=8)
    meta = energy_meta(net, 8, "layers.2.weight is (8, 7): layers do not chain")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(8)
        net.layers[2] = nn.Linear(7, 8)  # takes 7 inputs, layer 0 gives 8
    export(path, net, meta)


def nonfinite_weights(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=9)
    with torch.no_grad():
        net.layers[2].weight[3, 5] = float("nan")
    export(path, net, energy_meta(net, 9, "layers.2.weight[3, 5] is NaN"))


def float32(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=10)
    meta = energy_meta(net, 10, "float32 parameters")
    net32 = copy.deepcopy(net).to(torch.float32).eval()
    save_raw(path, torch.jit.script(net32), dumps(meta))


def wrong_input_width(path: Path) -> None:
    net = make_mlp([7, *ENERGY_WIDTHS[1:]], seed=11)
    meta = energy_meta(net, 11, "input_width 9, network takes 7")
    meta["input_width"] = 9
    export(path, net, meta)


def bad_material(path: Path) -> None:
    net = make_mlp(ENERGY_WIDTHS, seed=12)
    meta = energy_meta(net, 12, "negative Young's modulus")
    meta["material"]["elasticity"]["E"] = -1.0
    export(path, net, meta)


def principal_energy(path: Path) -> None:
    dim, seed = PRINCIPAL[path.name]
    net = make_energy_net(dim, True, "principal", seed)
    meta = energy_metadata(nondimensional_material("snow", dim), net, True, recipe(seed, DESCRIPTIONS[path.name]))
    meta["created"] = CREATED
    if path.name == "wrong_representation.pt":
        meta["representation"] = "fancy"
    export(path, net, meta)


BUILDERS = {
    "valid_energy_2d.pt": valid_energy_2d,
    "valid_return_map_2d.pt": valid_return_map_2d,
    "no_metadata.pt": no_metadata,
    "bad_json.pt": bad_json,
    "wrong_format_version.pt": wrong_format_version,
    "not_an_mlp.pt": not_an_mlp,
    "wrong_activation.pt": wrong_activation,
    "shape_mismatch.pt": shape_mismatch,
    "nonfinite_weights.pt": nonfinite_weights,
    "float32.pt": float32,
    "wrong_input_width.pt": wrong_input_width,
    "bad_material.pt": bad_material,
    **{name: principal_energy for name in PRINCIPAL},
}
assert BUILDERS.keys() == DESCRIPTIONS.keys()


# --- check ------------------------------------------------------------------------------------------
def _reference_forward(state: dict, x: torch.Tensor) -> torch.Tensor:
    """The MLP of nets.py evaluated from the parameters alone (what a loader computes itself)."""
    k = 0
    while f"layers.{2 * (k + 1)}.weight" in state:
        k += 1
    for i in range(k + 1):
        x = x @ state[f"layers.{2 * i}.weight"].T + state[f"layers.{2 * i}.bias"]
        if i < k:
            x = torch.nn.functional.silu(x)
    return x


def _inspect(path: Path) -> dict:
    """Everything the checks below need: metadata (text / parsed / error), parameters, forward vs reference."""
    extra = {METADATA_KEY: ""}
    module = torch.jit.load(str(path), map_location="cpu", _extra_files=extra)
    text = extra[METADATA_KEY]
    text = text.decode() if isinstance(text, bytes) else text
    info = {"text": text, "meta": None, "json_error": None}
    if text:
        try:
            info["meta"] = json.loads(text)
        except json.JSONDecodeError as err:
            info["json_error"] = str(err)
    state = {n: p.detach() for n, p in module.named_parameters()}
    info["names"] = list(state)
    info["shapes"] = {n: tuple(p.shape) for n, p in state.items()}
    info["dtypes"] = {str(p.dtype) for p in state.values()}
    info["finite"] = all(bool(torch.isfinite(p).all()) for p in state.values())
    w0 = info["shapes"]["layers.0.weight"][1]
    x = torch.randn(16, w0, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    state64 = {n: p.double() for n, p in state.items()}
    try:
        ref = _reference_forward(state64, x)
        info["ref_error"] = None
    except RuntimeError as err:
        ref, info["ref_error"] = None, str(err).splitlines()[0]
    try:
        out = module.double()(x)
        info["forward_error"] = None
        info["max_diff"] = float((out - ref).abs().max()) if ref is not None else math.nan
        info["out_shape"] = tuple(out.shape)
    except Exception as err:  # noqa: BLE001  (TorchScript raises torch.jit.Error)
        info["forward_error"] = str(err).strip().splitlines()[-1]
    return info


def _check_principal(path: Path) -> bool:
    """A principal file: forward([F, F0, h]) is the MLP of its parameters at [U^T F V, Sigma0, h]; the
    valid ones load, the other is refused for its representation only."""
    from plasticitynet.model import load_model
    from plasticitynet.training.frames import principal_frame, to_frame

    dim, _ = PRINCIPAL[path.name]
    extra = {METADATA_KEY: ""}
    module = torch.jit.load(str(path), map_location="cpu", _extra_files=extra).double()
    meta = json.loads(extra[METADATA_KEY])
    state = {n.removeprefix("mlp."): p.detach().double() for n, p in module.named_parameters()}
    g = torch.Generator().manual_seed(0)
    F0 = torch.randn(16, dim, dim, dtype=torch.float64, generator=g)
    F = F0 + 0.1 * torch.randn(16, dim, dim, dtype=torch.float64, generator=g)
    h = torch.rand(16, dtype=torch.float64, generator=g)
    U, S, V = principal_frame(F0)
    x = torch.cat([to_frame(F, U, V).reshape(16, -1), S, h[:, None]], 1)
    diff = float((module(energy_input(F, F0, h)) - _reference_forward(state, x)).abs().max())
    try:
        load_model(path)
        accepted, why = True, "accepted"
    except ValueError as err:
        accepted, why = False, f"rejected ({str(err).replace(str(path), '<file>')})"
    valid = path.name.startswith("valid_")
    good = diff < 1e-12 and accepted == valid and (valid or meta["representation"] == "fancy")
    print(f"{'ok' if good else 'UNEXPECTED':10s} {path.name:24s} {path.stat().st_size:6d} B  "
          f"|forward - MLP(frame)| = {diff:.2e}; load_model: {why}")
    print(f"{'':10s} {DESCRIPTIONS[path.name]}")
    return good


def check(out: Path) -> bool:
    from plasticitynet.model import load_model

    mlp_names = [f"layers.{2 * i}.{s}" for i in range(4) for s in ("weight", "bias")]
    ok = True
    for name in BUILDERS:
        path = out / name
        if name in PRINCIPAL:
            ok = _check_principal(path) and ok
            continue
        info = _inspect(path)  # every file is a loadable TorchScript archive
        meta = info["meta"]
        try:
            load_model(path)
            py_loader = "load_model: accepted"
        except ValueError as err:
            py_loader = f"load_model: rejected ({str(err).replace(str(path), '<file>')})"
        # the one property each file is meant to have
        same = info.get("max_diff", math.nan) < 1e-12  # forward() is the MLP of its parameters
        expected = {
            "valid_energy_2d.pt": meta is not None and meta["kind"] == "energy" and same,
            "valid_return_map_2d.pt": meta is not None and meta["kind"] == "return_map" and same,
            "no_metadata.pt": info["text"] == "" and same,
            "bad_json.pt": info["json_error"] is not None,
            "wrong_format_version.pt": meta is not None and meta["format_version"] == 99,
            "not_an_mlp.pt": info["names"] == mlp_names and info.get("max_diff", math.nan) > 1e-3,
            "wrong_activation.pt": meta is not None and meta["activation"] == "relu",
            "shape_mismatch.pt": info["shapes"]["layers.2.weight"] == (8, 7) and info["forward_error"] is not None,
            "nonfinite_weights.pt": not info["finite"],
            "float32.pt": info["dtypes"] == {"torch.float32"},
            "wrong_input_width.pt": meta is not None and meta["input_width"] == 9
            and info["shapes"]["layers.0.weight"] == (8, 7),
            "bad_material.pt": meta is not None and meta["material"]["elasticity"]["E"] < 0,
        }[name]
        # and nothing else wrong: metadata valid except where intended, parameters named like the MLP
        if name not in ("no_metadata.pt", "bad_json.pt"):
            expected = expected and meta is not None and meta["widths"][0] in (3, 7, 9)
        expected = expected and info["names"] == mlp_names
        must_accept = name.startswith("valid_")
        py_ok = py_loader.startswith("load_model: accepted") == must_accept or name in (
            "not_an_mlp.pt", "shape_mismatch.pt", "nonfinite_weights.pt", "float32.pt")  # no such checks in Python
        status = "ok" if expected and py_ok else "UNEXPECTED"
        ok = ok and status == "ok"
        diff = info.get("max_diff")
        fwd = f"forward error: {info['forward_error']}" if info["forward_error"] else f"|forward - MLP| = {diff:.2e}"
        print(f"{status:10s} {name:24s} {path.stat().st_size:6d} B  {fwd}; {py_loader}")
        print(f"{'':10s} {DESCRIPTIONS[name]}")
    return ok


def main() -> int:
    if os.environ.get("PYTHONHASHSEED") != "0":
        # TorchScript writes a module's constants (e.g. Linear's in_features / out_features) in the order
        # of a Python set of strings, which follows the per-process string hash: fix it for identical files.
        os.execve(sys.executable, [sys.executable, *sys.argv], {**os.environ, "PYTHONHASHSEED": "0"})
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    parser.add_argument("--no-check", action="store_true", help="skip loading the files back")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, build in BUILDERS.items():
        build(args.out / name)
    print(f"wrote {len(BUILDERS)} files to {args.out}")
    if args.no_check:
        return 0
    return 0 if check(args.out) else 1


if __name__ == "__main__":
    sys.exit(main())
