"""Export (TorchScript + metadata) and plasticitynet.load_model: round trip, the energy's derivatives,
the correction at F = F0, E scaling, learned return mappings, and clear errors for bad files."""

import json
import shutil
import subprocess
import sys
import zipfile

import pytest
import torch

import plasticitynet
from plasticitynet.materials import Material
from plasticitynet.model import LearnedEnergy, LearnedReturnMap
from plasticitynet.training import (
    ElastoplasticStress,
    energy_metadata,
    energy_widths,
    export_model,
    make_mlp,
    nondimensional_material,
    return_map_metadata,
    return_map_widths,
    sample_batch,
    sampling_spec,
    script_network,
)
from plasticitynet.training.held_out import evaluate, format_errors
from plasticitynet.training.export import sha256_of

RECIPE = {"epochs": 0, "batch": 1, "lr": 0.01, "decay": 0.95, "decay_steps": 1000, "sampling": "paper", "seed": 0,
          "wall_seconds": 0.0}


pytestmark = pytest.mark.usefixtures("one_thread")


def export_energy(folder, name, dim, seed=0, return_map=None):
    m = nondimensional_material(name, dim)
    spec = sampling_spec(m)
    net = make_mlp(energy_widths(dim, spec.has_hardening), seed)
    meta = energy_metadata(m, net, spec.has_hardening, RECIPE, {"note": "untrained"}, return_map)
    return export_model(folder / f"{name}_{dim}d.pt", net, meta), net, meta


def export_return_map(folder, dim, seed=0):
    m = nondimensional_material("metal_nh", dim)
    net = make_mlp(return_map_widths(dim), seed)
    meta = return_map_metadata(m, net, RECIPE, {})
    return export_model(folder / f"metal_nh_rm_{dim}d.pt", net, meta), net, meta


def samples(model, n=32, seed=0, scale=1.0):
    return sample_batch(sampling_spec(model.training_material, "near", scale), n, seed=seed, stream="test")


@pytest.mark.parametrize("dim", [2, 3])
def test_export_round_trip(tmp_path, dim):
    path, net, meta = export_energy(tmp_path, "snow", dim)
    extra = {"metadata.json": ""}
    loaded = torch.jit.load(str(path), _extra_files=extra)
    assert json.loads(extra["metadata.json"]) == meta
    x = torch.randn(257, 2 * dim * dim + 1, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    out = loaded(x)
    assert out.dtype == torch.float64 and out.shape == (257, 1)
    assert torch.equal(out, script_network(net)(x))  # bit-identical to the exported module
    assert torch.equal(out, net.double()(x))  # and to the float64 eager network
    assert [n for n, _ in loaded.named_parameters()] == [n for pair in meta["layer_parameters"] for n in pair]
    # The fields the C++ reader relies on.
    assert meta["format"] == "plasticitynet-model" and meta["format_version"] == 1 and meta["kind"] == "energy"
    assert meta["training_E"] == 1.0 and meta["material"]["elasticity"]["E"] == 1.0
    assert meta["material"] == Material.preset("snow", dim).to_dict() | {
        "elasticity": dict(Material.preset("snow", dim).to_dict()["elasticity"], E=1.0)
    }
    assert meta["dim"] == dim and meta["input_width"] == 2 * dim * dim + 1 == meta["widths"][0]
    assert meta["widths"] == energy_widths(dim, True) and meta["activation"] == "silu" and meta["output"] == "N(x)"
    assert meta["input_layout"] == [f"F (row-major, {dim * dim})", f"F0 (row-major, {dim * dim})", "h"]
    for key in ("rescale", "recipe", "errors", "torch_version", "created"):
        assert key in meta
    assert not list(tmp_path.glob("*.tmp"))  # atomic write left nothing behind


@pytest.mark.parametrize("name,dim", [("sand", 2), ("snow", 2), ("metal", 3), ("sand", 3)])
def test_gradient_at_F0_equals_Ptilde(tmp_path, name, dim):
    path, _, _ = export_energy(tmp_path, name, dim)
    E = Material.preset(name, dim).elasticity.params.E
    model = plasticitynet.load_model(path, E=E)
    assert isinstance(model, LearnedEnergy) and model.dim == dim and model.E == E
    assert model.material.elasticity.params.E == E and model.material.name == name
    b = samples(model, 500, scale=2.0)
    g = model.gradient(b.F0, b.F0, b.h)
    P0 = Material.preset(name, dim).elastoplastic_stress(b.F0, b.h)  # Pa, the library at the scene's E
    assert g.dtype == torch.float64 and g.shape == b.F0.shape
    rel = torch.linalg.matrix_norm(g - P0) / torch.clamp(torch.linalg.matrix_norm(P0), min=1e-3 * model.material.mu)
    assert float(rel.max()) < 1e-10
    # Single matrices work too.
    assert torch.allclose(model.gradient(b.F0[0], b.F0[0], b.h[0]), g[0], rtol=1e-12, atol=1e-12 * E)


def test_E_scaling_and_regularizer(tmp_path):
    path, _, _ = export_energy(tmp_path, "metal", 2)
    one, big = plasticitynet.load_model(path), plasticitynet.load_model(path, E=2.5e6)
    assert one.E == 1.0 and one.material.elasticity.params.E == 1.0
    b = samples(one, 20)
    for w in (0.0, 1.0):
        assert torch.allclose(big.psi(b.F, b.F0, b.h, w=w), 2.5e6 * one.psi(b.F, b.F0, b.h, w=w), rtol=1e-13)
        assert torch.allclose(big.gradient(b.F, b.F0, b.h, w=w), 2.5e6 * one.gradient(b.F, b.F0, b.h, w=w), rtol=1e-13)
    H0, H1 = one.hessian(b.F, b.F0, b.h), one.hessian(b.F, b.F0, b.h, w=1.0)
    assert torch.allclose(H1 - H0, one.mu * torch.eye(4, dtype=torch.float64).expand(20, 4, 4), atol=1e-12)
    # The regularizer does not move the gradient at F0.
    assert torch.allclose(one.gradient(b.F0, b.F0, b.h, w=1.0), one.gradient(b.F0, b.F0, b.h), atol=1e-15)


@pytest.mark.parametrize("name,dim", [("snow", 2), ("sand", 3)])
def test_derivatives_gradcheck(tmp_path, name, dim):
    """gradient = dPsi/dF and hessian = d(gradient)/dF, by torch.autograd.gradcheck / gradgradcheck in float64
    and against central differences of the gradient (PolyFEM's check, step 1e-6)."""
    path, _, _ = export_energy(tmp_path, name, dim, seed=1)
    model = plasticitynet.load_model(path)
    b = samples(model, 4, seed=1, scale=2.0)
    F = b.F.clone().requires_grad_(True)

    def psi(F_):
        return model.psi(F_, b.F0, b.h, w=0.5)

    assert torch.autograd.gradcheck(psi, (F,), eps=1e-6, atol=1e-8, rtol=1e-6)
    assert torch.autograd.gradgradcheck(psi, (F,), eps=1e-6, atol=1e-8, rtol=1e-6)
    # gradient() is the derivative of psi(), and differentiable itself.
    (g_auto,) = torch.autograd.grad(psi(F).sum(), F)
    g = model.gradient(b.F, b.F0, b.h, w=0.5)
    assert float(g.abs().max()) > 1e-3  # not two zero vectors
    assert torch.allclose(g, g_auto, rtol=1e-12, atol=1e-14)
    assert torch.autograd.gradcheck(lambda F_: model.gradient(F_, b.F0, b.h, w=0.5), (F,), eps=1e-6, atol=1e-8)
    # hessian() against central differences of gradient().
    H = model.hessian(b.F, b.F0, b.h, w=0.5)
    d2 = dim * dim
    assert H.shape == (4, d2, d2) and torch.allclose(H, H.transpose(-1, -2), atol=1e-12)
    step = 1e-6
    checks = 0
    for k in range(d2):
        dF = torch.zeros(d2, dtype=torch.float64)
        dF[k] = step
        dF = dF.reshape(dim, dim)
        fd = (model.gradient(b.F + dF, b.F0, b.h, w=0.5) - model.gradient(b.F - dF, b.F0, b.h, w=0.5)) / (2 * step)
        col = H[:, :, k].reshape(4, dim, dim)
        assert torch.all((fd - col).abs() <= 1e-4 * torch.clamp(torch.maximum(fd.abs(), col.abs()), min=1.0))
        checks += 1
    assert checks == d2


def test_learned_return_map_model(tmp_path):
    rm_path, rm_net, rm_meta = export_return_map(tmp_path, 2)
    rm = plasticitynet.load_model(rm_path)
    assert isinstance(rm, LearnedReturnMap) and rm.metadata == rm_meta and rm.metadata["kind"] == "return_map"
    assert rm_meta["input_width"] == 3 and rm_meta["widths"] == [3, 32, 32, 32, 1]
    Sigma = torch.tensor([[1.3, 0.8], [1.0, 1.0]], dtype=torch.float64)
    h = torch.tensor([0.05, 0.5], dtype=torch.float64)
    dg = rm.dgamma(Sigma, h)
    eps = torch.log(Sigma)
    L = torch.linalg.vector_norm(eps - eps.mean(-1, keepdim=True), dim=-1)
    assert torch.all(dg <= L)
    Z = rm.project(Sigma, h)
    assert torch.equal(Z[1], Sigma[1])  # on the diagonal: elastic
    assert torch.allclose(Z[0].prod(), Sigma[0].prod(), rtol=1e-14)  # volume preserving

    # An energy trained against it: the metadata names the file and its sha256.
    info = {"type": "learned", "file": rm_path.name, "sha256": sha256_of(rm_path)}
    path, _, meta = export_energy(tmp_path, "metal_nh", 2, return_map=info)
    model = plasticitynet.load_model(path)
    assert isinstance(model.return_map, LearnedReturnMap)
    b = samples(model, 200, scale=2.0)
    learned = ElastoplasticStress(model.training_material, model.return_map)(b.F0, b.h)
    exact = ElastoplasticStress(model.training_material)(b.F0, b.h)
    g = model.gradient(b.F0, b.F0, b.h)
    assert float((g - learned).abs().max()) < 1e-12 * float(learned.abs().max())
    assert float((learned - exact).abs().max()) > 1e-3 * float(exact.abs().max())  # untrained: really learned

    # A replaced return-map file is refused, a missing one named.
    shutil.copy(export_return_map(tmp_path / "other", 2, seed=5)[0], rm_path)
    with pytest.raises(ValueError, match="sha256"):
        plasticitynet.load_model(path)
    rm_path.unlink()
    with pytest.raises(ValueError, match="metal_nh_rm_2d.pt"):
        plasticitynet.load_model(path)
    # An explicit return map overrides the metadata's file.
    assert plasticitynet.load_model(path, return_map=rm).return_map is rm


def test_bad_files_are_named(tmp_path):
    missing = tmp_path / "missing.pt"
    with pytest.raises(ValueError, match="missing.pt: no such model file"):
        plasticitynet.load_model(missing)
    garbled = tmp_path / "garbled.pt"
    garbled.write_bytes(b"not a zip archive at all")
    with pytest.raises(ValueError, match="garbled.pt: not a readable TorchScript"):
        plasticitynet.load_model(garbled)
    plain = tmp_path / "plain.pt"
    torch.jit.save(torch.jit.script(make_mlp([3, 4, 1], 0)), str(plain))
    with pytest.raises(ValueError, match="plain.pt: no metadata.json"):
        plasticitynet.load_model(plain)
    path, net, meta = export_energy(tmp_path, "sand", 2)
    for change, message in (
        ({"format_version": 2}, "format_version"),
        ({"kind": "potential"}, "kind"),
        ({"input_width": 9}, "input_width"),
        ({"material": {"elasticity": {"model": "rubber", "E": 1, "nu": 0.3}}}, "elasticity.model"),
        ({"format": None}, "format"),
    ):
        bad = tmp_path / "bad.pt"
        torch.jit.save(script_network(net), str(bad), _extra_files={"metadata.json": json.dumps({**meta, **change})})
        with pytest.raises(ValueError, match=rf"bad.pt: bad metadata: .*{message}"):
            plasticitynet.load_model(bad)
    # Metadata that is not JSON.
    notjson = tmp_path / "notjson.pt"
    torch.jit.save(script_network(net), str(notjson), _extra_files={"metadata.json": "{oops"})
    with pytest.raises(ValueError, match="notjson.pt: metadata.json is not valid JSON"):
        plasticitynet.load_model(notjson)
    # A truncated archive.
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(path.read_bytes()[:200])
    with pytest.raises(ValueError, match="truncated.pt"):
        plasticitynet.load_model(truncated)
    assert zipfile.is_zipfile(path)


def test_evaluate_in_process_and_cli(tmp_path):
    path, _, _ = export_energy(tmp_path, "sand", 2)
    errors = evaluate(plasticitynet.load_model(path), samples=3000)
    assert set(errors["rel_rms"]) == {"paper", "near"}
    assert set(errors["rel_rms"]["paper"]) == {"0.5x", "1x", "2x"}
    assert errors["at_F0_max_rel"] < 1e-10
    assert all(0 < v < 1e3 for row in errors["rel_rms"].values() for v in row.values())
    assert "at F = F0" in format_errors(errors)
    rm_path, _, _ = export_return_map(tmp_path, 2)
    rm_errors = evaluate(plasticitynet.load_model(rm_path), samples=3000)
    assert 0 < rm_errors["yielding"] < 3000 and 0 <= rm_errors["frac_within_1e-3"] <= 1
    run = subprocess.run(
        [sys.executable, "-m", "plasticitynet.model_errors", str(path), "--samples", "2000"],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 0, run.stderr
    assert "relative RMS gradient error" in run.stdout and "deps x0.5" in run.stdout
    run = subprocess.run(
        [sys.executable, "-m", "plasticitynet.model_errors", str(tmp_path / "nope.pt")], capture_output=True, text=True,
        timeout=120,
    )
    assert run.returncode == 2 and "nope.pt: no such model file" in run.stderr
