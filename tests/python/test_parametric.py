"""Parametric energies (issue 36): material parameters as network inputs. The family's ranges and their
checks, the sampled parameters, the per-group targets, training end to end, the model bound to a material
(load_model(material=), LearnedEnergy.at), eq. 8's exactness at F = F0 for any bound material, resuming."""

import copy
import json
import math
from pathlib import Path

import pytest
import torch

import plasticitynet
from plasticitynet.materials import PRESETS, Material
from plasticitynet.training import (
    ElastoplasticStress,
    TrainConfig,
    Trainer,
    energy_input,
    energy_metadata,
    energy_widths,
    export_model,
    make_mlp,
    nondimensional_material,
    sample_batch,
    sampling_spec,
    script_network,
)
from plasticitynet.training.cli import main as cli_main
from plasticitynet.training.held_out import (
    EVAL_SEED, MAP_BINS, format_errors, parameter_error_map, relative_rms_error,
)
from plasticitynet.training.nets import make_energy_net, mlp_input_width
from plasticitynet.training.parameters import FAMILIES, GROUP_SIZE, MAX_GROUPS, ParameterRange, ParameterSpace, runs

RECIPE = {"epochs": 0, "batch": 1, "lr": 0.01, "decay": 0.95, "decay_steps": 1000, "sampling": "paper", "seed": 0,
          "wall_seconds": 0.0}

pytestmark = pytest.mark.usefixtures("one_thread")


def space_of(name, dim=2):
    return ParameterSpace.family(name, nondimensional_material(name, dim))


def description(name, **fields):
    """The preset `name`'s description (its own E) with fields "section.key" = value changed."""
    desc = copy.deepcopy(PRESETS[name])
    for field, value in fields.items():
        section, _, key = field.partition("__")
        desc[section][key] = value
    return desc


def parametric_spec(name, dim=2, sampling="paper"):
    material = nondimensional_material(name, dim)
    return sampling_spec(material, sampling).with_(parameters=ParameterSpace.family(name, material).ranges)


def rel_max(a, b, floor):
    return float((torch.linalg.matrix_norm(a - b) / torch.clamp(torch.linalg.matrix_norm(b), min=floor)).max())


# --- the family and its checks ---------------------------------------------------------------------------


def test_values_of_in_range_and_refusals():
    space = space_of("sand")
    assert space.fields == ("plasticity.friction_angle_deg", "elasticity.nu") and len(space) == 2
    # The preset (its own E: E is a scale, never a parameter) is the reference point.
    assert space.values_of(Material.preset("sand", 2), "scene") == [30.0, 0.3] == space.reference_values()
    desc = description("sand", plasticity__friction_angle_deg=40.0, elasticity__nu=0.25)
    assert space.values_of(desc, "scene") == [40.0, 0.25]
    assert space.values_of(Material.from_dict(desc, 2), "scene") == [40.0, 0.25]
    # The ranges are closed.
    assert space.values_of(description("sand", plasticity__friction_angle_deg=20.0, elasticity__nu=0.45), "s") == [20.0, 0.45]
    assert space.values_of(description("sand", plasticity__friction_angle_deg=45.0, elasticity__nu=0.2), "s") == [45.0, 0.2]
    with pytest.raises(ValueError, match=r"^scene: material\.plasticity\.friction_angle_deg = 50 is outside the range \[20, 45\]"):
        space.values_of(description("sand", plasticity__friction_angle_deg=50.0), "scene")
    with pytest.raises(ValueError, match=r"^scene: material\.elasticity\.nu = 0\.48 is outside the range \[0\.2, 0\.45\]"):
        space.values_of(description("sand", elasticity__nu=0.48), "scene")
    with pytest.raises(ValueError, match=r"material\.plasticity\.friction_angle_deg = 19\.9 is outside"):
        space.values_of(description("sand", plasticity__friction_angle_deg=19.9), "scene")
    # A field the family does not vary must equal the reference's: snow's Cam-Clay variant, metal's elasticity.
    snow = space_of("snow")
    assert snow.values_of(Material.preset("snow", 2), "scene") == [45.0, 0.5, 0.3, 0.2]
    with pytest.raises(ValueError, match=r"^scene: material\.plasticity\.variant = 'paper', but .*'exact'.*only "
                       r"plasticity\.friction_angle_deg, plasticity\.xi, plasticity\.beta, elasticity\.nu vary"):
        snow.values_of(description("snow", plasticity__variant="paper"), "scene")
    metal = space_of("metal")
    with pytest.raises(ValueError, match=r"^scene: material\.elasticity\.model = 'neo_hookean_metal', but .*'stvk_hencky'"):
        metal.values_of(Material.preset("metal_nh", 2), "scene")
    # Another plasticity model lacks the family's fields.
    with pytest.raises(ValueError, match=r"material\.plasticity\.friction_angle_deg: missing"):
        space.values_of(Material.preset("metal", 2), "scene")


def test_ranges_inputs_and_metadata():
    space = space_of("sand")
    p = torch.tensor([[20.0, 0.2], [45.0, 0.45], [32.5, 0.325], [30.0, 0.3]], dtype=torch.float64)
    u = space.inputs(p)
    assert u.shape == (4, 2) and u.dtype == torch.float64
    assert torch.equal(u[0], torch.tensor([-1.0, -1.0], dtype=torch.float64))
    assert torch.equal(u[1], torch.tensor([1.0, 1.0], dtype=torch.float64))
    assert torch.allclose(u[2], torch.zeros(2, dtype=torch.float64), atol=1e-15)
    assert torch.allclose(u[3], torch.tensor([-0.2, -0.2], dtype=torch.float64), atol=1e-15)
    for k, r in enumerate(space.ranges):  # the per-range and the batched normalisations agree
        assert [r.normalise(float(v)) for v in p[:, k]] == pytest.approx(u[:, k].tolist(), abs=1e-15)
    assert space.inputs(p.float()).dtype == torch.float32
    with pytest.raises(ValueError, match=r"range \[1.0, 1.0\]"):
        ParameterRange("elasticity.nu", 1.0, 1.0)
    with pytest.raises(ValueError, match="must be finite"):
        ParameterRange("elasticity.nu", 0.0, math.inf)
    # The metadata round trip, and malformed metadata named.
    meta = space.to_metadata()
    assert meta == [{"field": "plasticity.friction_angle_deg", "min": 20.0, "max": 45.0},
                    {"field": "elasticity.nu", "min": 0.2, "max": 0.45}]
    assert ParameterSpace.from_metadata(meta, space.material, "f.pt").ranges == FAMILIES["sand"]
    for bad, message in (
        ({"field": "elasticity.nu", "min": 0.4, "max": 0.3}, r"f\.pt: parameters\[0\]: parameter elasticity\.nu: range"),
        ({"field": "elasticity.nu", "min": "0", "max": 0.3}, r"f\.pt: parameters\[0\]: expected"),
        ({"field": "plasticity.xi", "min": 0.1, "max": 0.3}, r"f\.pt: parameters: material\.plasticity\.xi: missing"),
    ):
        with pytest.raises(ValueError, match=message):
            ParameterSpace.from_metadata([bad], space.material, "f.pt")
    with pytest.raises(ValueError, match="listed twice"):
        ParameterSpace(space.material, [FAMILIES["sand"][1], FAMILIES["sand"][1]])
    with pytest.raises(ValueError, match="no parametric family 'metal_nh'"):
        ParameterSpace.family("metal_nh", nondimensional_material("metal_nh", 2))
    # material_at sets the fields and keeps E = 1.
    m = space.material_at([40.0, 0.25])
    d = m.to_dict()
    assert d["plasticity"]["friction_angle_deg"] == 40.0 and d["elasticity"]["nu"] == 0.25 and d["elasticity"]["E"] == 1.0
    # runs(): maximal runs of equal rows.
    q = torch.tensor([[1.0], [1.0], [2.0], [2.0], [2.0], [1.0]])
    assert runs(q) == [(0, 2), (2, 5), (5, 6)] and runs(q[:1]) == [(0, 1)] and runs(q[:0]) == []


# --- sampling ------------------------------------------------------------------------------------------


def test_sampled_parameters():
    spec = parametric_spec("sand")
    n = 3 * GROUP_SIZE + 7  # a last, partial group
    b = sample_batch(spec, n, seed=3, step=5)
    lo = torch.tensor([r.lo for r in spec.parameters], dtype=torch.float64)
    hi = torch.tensor([r.hi for r in spec.parameters], dtype=torch.float64)
    assert b.p.shape == (n, 2) and b.p.dtype == torch.float64
    assert bool(((b.p >= lo) & (b.p <= hi)).all())
    starts = list(range(0, n, GROUP_SIZE))
    for s in starts:
        assert torch.equal(b.p[s : s + GROUP_SIZE], b.p[s].expand_as(b.p[s : s + GROUP_SIZE]))
    assert runs(b.p) == [(s, min(s + GROUP_SIZE, n)) for s in starts]  # consecutive groups differ
    # Reproducible for (seed, step, stream), other for another step, seed or stream.
    assert torch.equal(sample_batch(spec, n, seed=3, step=5).p, b.p)
    for other in (dict(seed=3, step=6), dict(seed=4, step=5), dict(seed=3, step=5, stream="eval")):
        assert not torch.equal(sample_batch(spec, n, **other).p, b.p)
    # A large part has at most MAX_GROUPS groups (larger ones), and they spread over the box.
    big = sample_batch(spec, 200 * GROUP_SIZE, seed=0).p
    groups = runs(big)
    assert len(groups) == MAX_GROUPS and groups[0] == (0, -(-200 * GROUP_SIZE // MAX_GROUPS))
    wide = big[[start for start, _ in groups]]
    assert bool(((wide.min(0).values - lo) < 0.05 * (hi - lo)).all() and ((hi - wide.max(0).values) < 0.05 * (hi - lo)).all())
    # A cast batch carries p too.
    assert torch.equal(sample_batch(spec, n, seed=3, step=5, dtype=torch.float32).p, b.p.float())
    # Without parameters: p is (B, 0).
    assert sample_batch(spec.with_(parameters=()), 5, seed=0).p.shape == (5, 0)
    assert spec.to_dict()["parameters"] == space_of("sand").to_metadata()
    assert spec.to_dict()["parameter_group_size"] == GROUP_SIZE and "parameters" not in spec.with_(parameters=()).to_dict()


@pytest.mark.parametrize(
    "name,sampling,shards", [("sand", "paper", 1), ("snow", "mixed", 1), ("metal", "near", 2), ("snow", "paper", 4)]
)
def test_parameters_change_no_other_draw(name, sampling, shards):
    """Adding parameters to a spec changes no other draw: F, F0, h and the factors are bitwise those of the
    dedicated spec (the parameters come from a stream of their own)."""
    spec = parametric_spec(name, 2, sampling)
    n = 4 * GROUP_SIZE
    with_p = sample_batch(spec, n, seed=1, step=2, shards=shards)
    without = sample_batch(spec.with_(parameters=()), n, seed=1, step=2, shards=shards)
    for field in ("F", "F0", "h", "U", "Sigma", "V", "U0", "Sigma0", "V0"):
        assert torch.equal(getattr(with_p, field), getattr(without, field)), field
    assert with_p.p.shape == (n, len(spec.parameters)) and without.p.shape == (n, 0)
    # Shards: the union of the ranks' parts is the whole batch, p included.
    if shards > 1:
        parts = [sample_batch(spec, n, seed=1, step=2, shards=shards, shard_range=(k, k + 1)) for k in range(shards)]
        assert torch.equal(torch.cat([q.p for q in parts]), with_p.p)


# --- targets -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["sand", "snow", "metal"])
def test_stress_per_group_equals_the_dedicated_material(name):
    space = space_of(name)
    stress = ElastoplasticStress(space.material, parameters=space)
    spec = sampling_spec(space.material).with_(parameters=space.ranges)
    b = sample_batch(spec, 3 * GROUP_SIZE, seed=0, step=1)
    P = stress.from_factors(b.U, b.Sigma, b.V, b.h, b.p)
    P_svd = stress(b.F, b.h, b.p)
    assert P.shape == b.F.shape
    for s in range(0, len(b), GROUP_SIZE):
        rows = slice(s, s + GROUP_SIZE)
        m = space.material_at(b.p[s].tolist())
        one = ElastoplasticStress(m)
        assert torch.equal(P[rows], one.from_factors(b.U[rows], b.Sigma[rows], b.V[rows], b.h[rows]))
        assert torch.equal(P_svd[rows], m.elastoplastic_stress(b.F[rows], b.h[rows]))
    assert torch.allclose(P, P_svd, rtol=1e-10, atol=1e-12)
    # Not the reference material's stress (the parameters matter).
    assert not torch.allclose(P, ElastoplasticStress(space.material).from_factors(b.U, b.Sigma, b.V, b.h), rtol=1e-6)


def test_stress_of_a_batch_mixing_groups():
    """Rows A A A B B A: each run uses its own material, the returning A too."""
    space = space_of("sand")
    stress = ElastoplasticStress(space.material, parameters=space)
    b = sample_batch(sampling_spec(space.material), 6, seed=2)
    A, B = [22.0, 0.42], [44.0, 0.21]
    p = torch.tensor([A, A, A, B, B, A], dtype=torch.float64)
    P = stress(b.F, b.h, p)
    for k in range(6):
        m = space.material_at(p[k].tolist())
        assert torch.equal(P[k : k + 1], m.elastoplastic_stress(b.F[k : k + 1], b.h[k : k + 1])), k
    # The two materials give other stresses on the same F.
    PA = space.material_at(A).elastoplastic_stress(b.F, b.h)
    PB = space.material_at(B).elastoplastic_stress(b.F, b.h)
    assert not torch.allclose(PA, PB, rtol=1e-6)
    # p is required, of shape (B, K); a learned return mapping is refused.
    with pytest.raises(ValueError, match=r"needs the parameters p of the 6 rows, \(B, 2\)"):
        stress(b.F, b.h)
    with pytest.raises(ValueError, match="needs the parameters p"):
        stress(b.F, b.h, p[:, :1])
    with pytest.raises(ValueError, match="analytic return mapping"):
        ElastoplasticStress(space.material, return_map=lambda S, h: S, parameters=space)
    # An empty family is a dedicated stress.
    assert ElastoplasticStress(space.material, parameters=ParameterSpace(space.material, ())).parameters is None


# --- the trainer ------------------------------------------------------------------------------------------


def _config(folder, **kw):
    base = dict(material="sand", dim=2, epochs=6, batch=64, seed=0, out=str(folder / "model.pt"), checkpoint_every=1000,
                eval_samples=0, progress=False, parametric=True)
    base.update(kw)
    return TrainConfig(**base)


def test_config_and_task(tmp_path):
    assert TrainConfig(material="sand", dim=2, parametric=True).out == "models/sand_param_2d.pt"
    assert TrainConfig(material="snow", dim=3).out == "models/snow_3d.pt"
    for material, extra in (("metal_nh", {"return_map": "rm.pt"}), ("metal_nh_rm", {})):
        with pytest.raises(ValueError, match=f"material = '{material}': no parametric family"):
            TrainConfig(material=material, dim=2, parametric=True, **extra)
    # Snow: the network's tail after F0 is [h, u_1..u_4], and its MLP is 4 inputs wider.
    task = Trainer(_config(tmp_path, material="snow", representation="raw")).task
    assert task.net.material_inputs == 4 and task.net.widths[0] == mlp_input_width(2, True, "raw", 4) == 13
    b = sample_batch(task.spec, 40, seed=0)
    tail = task._tail(b)
    assert tail.shape == (40, 5)
    assert torch.equal(tail[:, 0], b.h) and torch.equal(tail[:, 1:], task.parameters.inputs(b.p))
    # Sand, principal: no hardening, the tail is u only.
    task = Trainer(_config(tmp_path / "sand")).task
    assert task.net.widths[0] == mlp_input_width(2, False, "principal", 2) == 8
    b = sample_batch(task.spec, 8, seed=0)
    assert torch.equal(task._tail(b), task.parameters.inputs(b.p))


def test_cli_refuses_a_family_less_material(capsys):
    """--parametric for a material without a family exits 2 with a message (it once raised a traceback)."""
    with pytest.raises(SystemExit) as exit_info:
        cli_main(["--material", "metal_nh_rm", "--dim", "2", "--parametric"])
    assert exit_info.value.code == 2
    assert "no parametric family" in capsys.readouterr().err


def test_resume_equals_uninterrupted(tmp_path):
    """A parametric run (mixed sampling, Hessian term) stopped at step 3 and resumed equals the uninterrupted
    run bit for bit; a resume without --parametric is refused."""
    kw = dict(epochs=6, checkpoint_every=2, sampling="mixed", hessian_weight=0.1)
    full = Trainer(_config(tmp_path / "a", **kw))
    full.run()
    part = Trainer(_config(tmp_path / "b", **kw))
    assert not part.run(stop_at=3).finished
    resumed = Trainer(_config(tmp_path / "b", resume=True, **kw))
    assert resumed.step == 3
    resumed.run()
    for (name, a), b in zip(full.net.state_dict().items(), resumed.net.state_dict().values()):
        assert torch.equal(a, b), name
    assert [r[:3] for r in full.log_rows] == [r[:3] for r in resumed.log_rows]
    x = torch.randn(20, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    x[:, 8:] = x[:, 8:].clamp(-1, 1)
    out_a = torch.jit.load(str(full.config.paths["model"]))(x)
    out_b = torch.jit.load(str(resumed.config.paths["model"]))(x)
    assert torch.equal(out_a, out_b)
    with pytest.raises(ValueError, match="parametric"):
        Trainer(_config(tmp_path / "b", resume=True, **{**kw, "epochs": 8, "parametric": False}))


# --- a trained model, end to end -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A tiny parametric sand model trained through train.py's main (20 steps of 64)."""
    threads = torch.get_num_threads()
    path = tmp_path_factory.mktemp("parametric") / "m.pt"
    try:
        code = cli_main(["--material", "sand", "--dim", "2", "--parametric", "--epochs", "20", "--batch", "64",
                         "--eval-samples", "512", "--out", str(path), "--threads", "1", "--no-progress"])
    finally:
        torch.set_num_threads(threads)
    assert code == 0
    return path


def test_trained_model_metadata(trained, capsys):
    model = plasticitynet.load_model(trained)
    meta = model.metadata
    assert meta["parameters"] == space_of("sand").to_metadata()
    assert meta["material"]["elasticity"]["E"] == 1.0 and meta["material"]["plasticity"]["friction_angle_deg"] == 30.0
    assert meta["input_width"] == meta["widths"][0] == 8
    assert meta["input_layout"][-2:] == [
        "u(plasticity.friction_angle_deg) = 2 (value - 20) / (45 - 20) - 1",
        "u(elasticity.nu) = 2 (value - 0.2) / (0.45 - 0.2) - 1",
    ]
    assert meta["recipe"]["distribution"]["parameters"] == meta["parameters"]
    assert meta["recipe"]["command"].startswith("python train.py --material sand --dim 2 --parametric")
    assert json.loads(json.dumps(meta)) == meta
    # Bound by default to the family's reference (the dedicated model's point).
    assert model.parameters is not None and model.parameter_values == [30.0, 0.3]
    assert model.training_material.to_dict() == nondimensional_material("sand", 2).to_dict()
    errors = meta["errors"]
    assert errors["parameter_values"] == [30.0, 0.3] and errors["at_F0_max_rel"] < 1e-10
    pmap = errors["parameter_map"]
    bins = MAP_BINS[2]
    assert pmap["fields"] == list(model.parameters.fields) and pmap["bins"] == bins
    assert len(pmap["points"]) == bins**2
    centres = [[r.lo + (r.hi - r.lo) * (k + 0.5) / bins for k in range(bins)] for r in model.parameters.ranges]
    assert [p["values"] for p in pmap["points"]] == [[round(a, 6), round(b, 6)] for a in centres[0] for b in centres[1]]
    values = [p["paper_1x"] for p in pmap["points"]]
    assert all(math.isfinite(v) and v > 0 for v in values)
    assert pmap["mean"] == pytest.approx(sum(values) / len(values)) and pmap["max"] == max(values)
    assert pmap["max_over_mean"] == pytest.approx(max(values) / pmap["mean"])
    text = format_errors(errors)
    assert "at the reference material (plasticity.friction_angle_deg = 30, elasticity.nu = 0.3)" in text
    assert f"({bins} bins per parameter, {bins**2} points, paper 1x)" in text


def test_bound_models(trained):
    default = plasticitynet.load_model(trained)
    desc40 = description("sand", plasticity__friction_angle_deg=40.0)
    bound = plasticitynet.load_model(trained, material=desc40)
    assert bound.parameter_values == [40.0, 0.3] and bound.training_material.to_dict()["plasticity"]["friction_angle_deg"] == 40.0
    b = sample_batch(sampling_spec(default.training_material, "near"), 64, seed=0, stream="test")
    g_default, g_bound = default.gradient(b.F, b.F0), bound.gradient(b.F, b.F0)
    assert not torch.allclose(g_default, g_bound, rtol=1e-6)
    # Binding with a Material, or with at(), is the same model (to round-off: TorchScript's first, profiling
    # call of a loaded network may differ from later ones in the last bit).
    def same(a, b):
        return torch.allclose(a, b, rtol=1e-13, atol=1e-14)

    for other in (plasticitynet.load_model(trained, material=Material.from_dict(desc40, 2)), default.at(desc40)):
        assert other.parameter_values == [40.0, 0.3]
        assert torch.equal(other._parameter_inputs, bound._parameter_inputs)
        assert same(other.gradient(b.F, b.F0), g_bound)
        assert same(other.psi(b.F, b.F0, w=1.0), bound.psi(b.F, b.F0, w=1.0))
        assert same(other.hessian(b.F[:4], b.F0[:4]), bound.hessian(b.F[:4], b.F0[:4]))
    # Binding keeps E; the bound model at the reference is the default one.
    big = plasticitynet.load_model(trained, E=2.0e5)
    assert big.at(desc40).E == 2.0e5
    assert same(default.at(PRESETS["sand"]).gradient(b.F, b.F0), g_default)
    # Outside the ranges, or another material: refused with the file and the field named.
    with pytest.raises(ValueError, match=rf"{trained.name}: material\.plasticity\.friction_angle_deg = 50 is outside "
                       r"the range \[20, 45\]"):
        plasticitynet.load_model(trained, material=description("sand", plasticity__friction_angle_deg=50.0))
    with pytest.raises(ValueError, match=r"material\.elasticity\.nu = 0\.1 is outside the range \[0\.2, 0\.45\]"):
        default.at(description("sand", elasticity__nu=0.1))
    with pytest.raises(ValueError, match=r"friction_angle_deg: missing"):
        default.at(Material.preset("metal", 2))


@pytest.mark.parametrize("values", [[20.0, 0.2], [41.5, 0.37], [45.0, 0.45]])
def test_gradient_at_F0_is_exact_for_every_bound_material(trained, values):
    """Eq. 8: grad Psi(F0, F0) = E Ptilde(F0) of the bound material, at the scene's E, wherever in the box."""
    desc = description("sand", plasticity__friction_angle_deg=values[0], elasticity__nu=values[1])
    scene = Material.from_dict(desc, 2)
    E = scene.elasticity.params.E
    model = plasticitynet.load_model(trained, E=E, material=desc)
    assert model.material.to_dict() == scene.to_dict()
    b = sample_batch(sampling_spec(model.training_material, "paper", 2.0), 300, seed=1, stream="test")
    g = model.gradient(b.F0, b.F0)
    P0 = scene.elastoplastic_stress(b.F0, b.h)
    assert rel_max(g, P0, 1e-3 * scene.mu) < 1e-10
    assert torch.allclose(model.Ptilde(b.F0), P0, rtol=1e-13, atol=1e-13 * E)
    # The reference material's stress differs (the check is not vacuous).
    assert rel_max(Material.preset("sand", 2).elastoplastic_stress(b.F0, b.h), P0, 1e-3 * scene.mu) > 1e-3


def test_psi_is_the_network_with_the_normalised_parameters(trained):
    """The file's forward(x) with x = [vec F, vec F0, u]: Psi = N(x) - c : F, c = grad_F N(F0, F0, u) - Ptilde(F0)."""
    desc = description("sand", plasticity__friction_angle_deg=25.0, elasticity__nu=0.4)
    model = plasticitynet.load_model(trained, material=desc)
    net = torch.jit.load(str(trained))
    b = sample_batch(sampling_spec(model.training_material, "near"), 16, seed=3, stream="test")
    u = torch.tensor([[2 * (25.0 - 20) / 25 - 1, 2 * (0.4 - 0.2) / 0.25 - 1]], dtype=torch.float64).expand(16, 2)
    F0 = b.F0.clone().requires_grad_(True)
    N0 = net(torch.cat([F0.reshape(16, 4), b.F0.reshape(16, 4), u], dim=1))[:, 0]
    (dN0,) = torch.autograd.grad(N0.sum(), F0)
    c = dN0 - model.training_material.elastoplastic_stress(b.F0, b.h)
    expected = net(energy_input(b.F, b.F0, u))[:, 0].detach() - (c * b.F).sum((-2, -1))
    assert torch.allclose(model.psi(b.F, b.F0), expected, rtol=1e-12, atol=1e-12)


def test_gradient_matches_finite_differences(trained):
    model = plasticitynet.load_model(trained, material=description("sand", plasticity__friction_angle_deg=37.0,
                                                                      elasticity__nu=0.22))
    b = sample_batch(sampling_spec(model.training_material, "paper"), 4, seed=5, stream="test")
    g = model.gradient(b.F, b.F0, w=0.5)
    assert float(g.abs().max()) > 1e-3
    step = 1e-6
    for k in range(4):
        dF = torch.zeros(4, dtype=torch.float64)
        dF[k] = step
        dF = dF.reshape(2, 2)
        fd = (model.psi(b.F + dF, b.F0, w=0.5) - model.psi(b.F - dF, b.F0, w=0.5)) / (2 * step)
        col = g.reshape(4, 4)[:, k]
        assert torch.allclose(fd, col, rtol=1e-6, atol=1e-8), (k, fd, col)
    F = b.F.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda F_: model.psi(F_, b.F0, w=0.5), (F,), eps=1e-6, atol=1e-8, rtol=1e-6)
    # The principal representation stays frame-indifferent with the parameters: g(R F, R F0) = R g(F, F0).
    theta = torch.tensor(0.7, dtype=torch.float64)
    R = torch.stack([torch.stack([theta.cos(), -theta.sin()]), torch.stack([theta.sin(), theta.cos()])])
    assert torch.allclose(model.gradient(R @ b.F, R @ b.F0, w=0.5), R @ g, rtol=1e-10, atol=1e-12)


def test_parameter_error_map_of_a_bound_model(trained):
    """The map binds the model at each bin centre: a point's error is the bound model's own."""
    model = plasticitynet.load_model(trained)
    pmap = parameter_error_map(model, samples=256, bins=2)
    assert len(pmap["points"]) == 4 and pmap["samples"] == 256
    first = pmap["points"][0]
    assert first["values"] == [26.25, 0.2625]
    bound = model.at(model.parameters.description_at(first["values"]))
    assert first["paper_1x"] == relative_rms_error(bound, "paper", 1.0, 256, EVAL_SEED)


# --- hand-built parametric files --------------------------------------------------------------------------


def export_parametric(folder, name, dim, representation="raw", seed=0):
    m = nondimensional_material(name, dim)
    space = ParameterSpace.family(name, m)
    spec = sampling_spec(m)
    net = make_energy_net(dim, spec.has_hardening, representation, seed, None, len(space))
    meta = energy_metadata(m, net, spec.has_hardening, RECIPE, {}, None, "eq8", space.to_metadata())
    return export_model(folder / f"{name}_param_{dim}d.pt", net, meta), net, meta


@pytest.mark.parametrize("name,dim,representation", [("snow", 2, "raw"), ("metal", 3, "principal")])
def test_hardening_and_parameters(tmp_path, name, dim, representation):
    """With a hardening input the tail is [h, u]: Psi is the network on [F, F0, h_net, u] and eq. 8 holds at
    F = F0 for any bound material."""
    path, _, meta = export_parametric(tmp_path, name, dim, representation)
    space = space_of(name, dim)
    K = len(space)
    assert meta["input_layout"][-K - 1] == "h" and meta["input_width"] == mlp_input_width(dim, True, representation, K)
    lo_hi = [(r.lo, r.hi) for r in space.ranges]
    values = [lo + 0.3 * (hi - lo) for lo, hi in lo_hi]
    desc = space.description_at(values)
    model = plasticitynet.load_model(path, material=desc)
    assert model.has_hardening and model.parameter_values == pytest.approx(values)
    b = sample_batch(sampling_spec(model.training_material, "near"), 32, seed=0, stream="test")
    u = space.inputs(torch.tensor([values], dtype=torch.float64)).expand(32, K)
    net = torch.jit.load(str(path))
    x = torch.cat([b.F.reshape(32, -1), b.F0.reshape(32, -1), model.network_hardening(b.h)[:, None], u], dim=1)
    c = model.correction(b.F0, b.h)
    assert torch.allclose(model.psi(b.F, b.F0, b.h), net(x)[:, 0].detach() - (c * b.F).sum((-2, -1)), rtol=1e-12, atol=1e-12)
    g = model.gradient(b.F0, b.F0, b.h)
    P0 = model.training_material.elastoplastic_stress(b.F0, b.h)
    assert rel_max(g, P0, 1e-3 * model.training_material.mu) < 1e-10
    assert not torch.allclose(model.gradient(b.F, b.F0, b.h), plasticitynet.load_model(path).gradient(b.F, b.F0, b.h))


def test_dedicated_model_refuses_a_material(tmp_path):
    m = nondimensional_material("sand", 2)
    net = make_mlp(energy_widths(2, False), 0)
    path = export_model(tmp_path / "sand_2d.pt", net, energy_metadata(m, net, False, RECIPE, {}))
    model = plasticitynet.load_model(path)
    assert model.parameters is None and model.parameter_values == []
    with pytest.raises(ValueError, match=r"sand_2d\.pt: material= binds a parametric model"):
        plasticitynet.load_model(path, material=PRESETS["sand"])
    with pytest.raises(ValueError, match="binds a parametric model"):
        model.at(PRESETS["sand"])


def test_bad_parametric_metadata_is_named(tmp_path):
    path, net, meta = export_parametric(tmp_path, "sand", 2)

    for change, message in (
        ({"parameters": [{"field": "elasticity.nu", "min": 0.5, "max": 0.2}]}, r"parameters\[0\]"),
        ({"parameters": ["nu", "E"]}, r"parameters\[0\]: expected"),
        ({"parameters": meta["parameters"] + meta["parameters"][:1]}, "input_width"),  # one parameter too many
        ({"parameters": [{"field": "plasticity.xi", "min": 0.1, "max": 0.5}] * 2}, "xi"),
    ):
        bad = tmp_path / "bad.pt"
        torch.jit.save(script_network(net), str(bad), _extra_files={"metadata.json": json.dumps({**meta, **change})})
        with pytest.raises(ValueError, match=rf"bad\.pt: bad metadata: .*{message}"):
            plasticitynet.load_model(bad)
    # A dedicated file's metadata without the parameters does not fit the parametric network's width.
    bad = tmp_path / "bad.pt"
    torch.jit.save(script_network(net), str(bad),
                   _extra_files={"metadata.json": json.dumps({k: v for k, v in meta.items() if k != "parameters"})})
    with pytest.raises(ValueError, match=r"bad\.pt: bad metadata: .*input_width"):
        plasticitynet.load_model(bad)


def test_granular_collapse_sweep_end_to_end(tmp_path):
    """scripts/granular_collapse.py at one angle and aspect ratio, 2 coarse frames: three runs per case, the
    table, the CSV and the plot; a finished run is reused by a second invocation."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    cmd = [sys.executable, str(root / "scripts" / "granular_collapse.py"), "--angles", "35", "--aspects", "2",
           "--frames", "2", "--dx", "0.015625", "--jobs", "2", "--work", str(tmp_path / "work"), "--out",
           str(tmp_path / "out")]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "out" / "runout.csv").read_text().splitlines()
    assert rows[0] == "angle,aspect,integrator,L_inf,runout,wall_seconds" and len(rows) == 4
    assert {row.split(",")[2] for row in rows[1:]} == {"ground_truth", "explicit_cfl", "plasticitynet"}
    table = (tmp_path / "out" / "runout.md").read_text()
    assert "| 35 | 2 |" in table and (tmp_path / "out" / "runout.png").stat().st_size > 0
    scene = json.loads((tmp_path / "work" / "phi35_a2" / "scene.json").read_text())
    assert scene["objects"][0]["material"]["plasticity"]["friction_angle_deg"] == 35
    assert scene["objects"][0]["max"][1] - scene["objects"][0]["min"][1] == pytest.approx(0.1)  # H = a L0
    # By default a Coulomb floor of the sand's own friction and AFLIP transfers (docs/methods.md).
    assert scene["boundary"]["floor_friction"] == pytest.approx(math.tan(math.radians(35)))
    assert scene["transfer"] == {"flip_relaxation_time": 0.01}
    assert "Floor: Coulomb, mu = tan(friction angle); transfers: AFLIP, relaxation time 0.01 s" in table
    frame = tmp_path / "work" / "phi35_a2" / "ground_truth" / "frame_00002.ply"
    written = frame.stat().st_mtime_ns
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and frame.stat().st_mtime_ns == written, r.stderr  # the finished runs are reused
    assert (tmp_path / "out" / "runout.csv").read_text().splitlines() == rows
    assert "Newton tolerance the default (1e-3 m/s)" in table
    # --newton-tolerance reruns plasticitynet alone, with that tolerance.
    implicit = tmp_path / "work" / "phi35_a2" / "plasticitynet"
    implicit_written = (implicit / "frame_00002.ply").stat().st_mtime_ns
    r = subprocess.run(cmd + ["--newton-tolerance", "1e-4"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert frame.stat().st_mtime_ns == written and (implicit / "frame_00002.ply").stat().st_mtime_ns != implicit_written
    assert json.loads((implicit / "run.json").read_text())["solver"]["newton_tolerance"] == pytest.approx(1e-4)
    assert "Newton tolerance 0.0001 m/s" in (tmp_path / "out" / "runout.md").read_text()


def test_granular_collapse_dt_study_end_to_end(tmp_path):
    """scripts/granular_collapse.py --dt-study at one case, 2 coarse frames: each of the four variants (APIC or
    AFLIP transfers, sticky or Coulomb floor) at every step, in one table row each."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    cmd = [sys.executable, str(root / "scripts" / "granular_collapse.py"), "--dt-study", "--angles", "30",
           "--aspects", "1", "--frames", "2", "--dx", "0.015625", "--jobs", "2", "--work", str(tmp_path / "work"),
           "--out", str(tmp_path / "out")]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    table = (tmp_path / "out" / "dt_study.md").read_text()
    rows = [line for line in table.splitlines() if line.startswith("| 30 | 1 |")]
    assert [row.split(" | ")[2] for row in rows] == ["APIC, sticky floor", "APIC, Coulomb floor",
                                                      "AFLIP 0.01 s, sticky floor", "AFLIP 0.01 s, Coulomb floor"]
    assert all(len(row.strip("|").split("|")) == 3 + 6 for row in rows)
    scenes = sorted((tmp_path / "work" / "phi30_a1").glob("*/scene.json"))
    kinds = {(json.loads(p.read_text())["boundary"].get("floor_friction") is not None,
              "transfer" in json.loads(p.read_text())) for p in scenes}
    assert kinds == {(False, False), (True, False), (False, True), (True, True)}
