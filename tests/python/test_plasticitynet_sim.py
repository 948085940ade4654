"""The Python module plasticitynet_sim (bindings/): every public function, its shapes and dtypes, its
errors, and its consistency with the torch model reader and with `pnet simulate`."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import plasticitynet
import plasticitynet_sim as pns
from plasticitynet.materials import Material as TorchMaterial
from test_pnet_cli import tiny_scene

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "models"
TINY = ROOT / "scenes" / "tiny"
PNET = ROOT / os.environ.get("PNET_BUILD_DIR", "build") / "cpp" / "pnet"


def random_F(n: int, dim: int, seed: int, spread: float = 0.15) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.eye(dim) + spread * rng.standard_normal((n, dim, dim))


def read_ply(path: Path) -> dict:
    """The binary PLY frames of pnet simulate (cpp/pnet/io/ply.hpp): x y z vx vy vz mass hardening, doubles."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    n = int(header.split("element vertex ")[1].split()[0])
    dim = int(header.split("comment dim ")[1].split()[0])
    v = np.frombuffer(data[end:], dtype="<f8").reshape(n, 8)
    return {"x": v[:, :dim], "v": v[:, 3:3 + dim], "mass": v[:, 6], "hardening": v[:, 7]}


# --- scenes ---------------------------------------------------------------------------------------


def test_load_scene_and_dict_round_trip():
    scene = pns.load_scene(TINY / "sand_column_2d.json")
    assert scene.dim == 2 and scene.dx > 0 and scene.integrator in ("explicit", "plasticitynet", "lagged")
    assert len(scene.cells) == 2 and scene.domain_min == [0.0, 0.0]
    again = pns.Scene.from_dict(scene.to_dict())
    assert again.to_dict() == scene.to_dict()
    assert "Scene" in repr(scene)


def test_bad_scene_dict_names_the_field():
    scene = tiny_scene("snowball_2d")
    scene["objects"][0]["radius"] = -1
    with pytest.raises(ValueError, match=r"<dict>: objects\[0\]\.radius: expected a positive number, got -1"):
        pns.Scene.from_dict(scene)
    with pytest.raises(ValueError, match="<dict>"):
        pns.Simulation({"dim": 2})
    with pytest.raises(ValueError, match="not JSON-serializable"):
        pns.Scene.from_dict({"dim": object()})


def test_missing_files_raise_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.json"):
        pns.load_scene(tmp_path / "nope.json")
    with pytest.raises(FileNotFoundError, match="nope.pt"):
        pns.load_model(tmp_path / "nope.pt")
    scene = tiny_scene("sand_column_2d")
    scene["objects"][0]["model"] = str(tmp_path / "missing.pt")
    with pytest.raises(FileNotFoundError, match=r"objects\[0\]\.model: .*missing\.pt"):
        pns.Simulation(scene)


# --- simulation -----------------------------------------------------------------------------------


@pytest.mark.parametrize("integrator", ["explicit", "plasticitynet", "lagged"])
@pytest.mark.parametrize("name", ["sand_column_2d", "snowball_3d"])
def test_simulation_arrays_and_stats(name, integrator):
    sim = pns.Simulation(TINY / f"{name}.json", integrator=integrator)
    d, n = sim.dim, sim.num_particles
    assert sim.integrator == integrator and n > 0
    x = sim.positions
    views = {"positions": (n, d), "velocities": (n, d), "F_elastic": (n, d, d), "affine": (n, d, d),
             "hardening": (n,), "mass": (n,), "rest_volume": (n,)}
    for attr, shape in views.items():
        a = getattr(sim, attr)
        assert a.shape == shape and a.dtype == np.float64 and not a.flags.writeable, attr
    assert sim.object.shape == (n,) and sim.object.dtype == np.int32
    assert np.allclose(sim.F_elastic, np.eye(d))
    start = x.copy()

    step = sim.step()
    assert step["dt"] > 0 and step["wall_s"] >= 0 and sim.total_steps == 1
    assert (step["newton_iterations"] > 0) == (integrator != "explicit") or step["newton_iterations"] == 0
    frames = sim.advance(1)
    assert len(frames) == 1 and frames[0]["frame"] == 1 and sim.frame == 1
    assert np.isclose(sim.time, sim.scene.frame_dt)
    assert not np.array_equal(x, start), "the view shows the current state"
    stats = sim.step_stats()
    assert all(len(v) == sim.total_steps for v in stats.values())
    assert stats["newton_iterations"].dtype == np.int64 and stats["converged"].dtype == bool
    assert np.isclose(stats["dt"].sum(), sim.time)
    if integrator != "explicit":
        assert stats["converged"].all() and (stats["newton_iterations"] >= 0).all()
        assert not stats["line_search_failed"].any() and (stats["hardening_clamped"] >= 0).all()
        assert frames[0]["unconverged_steps"] == 0 and frames[0]["hardening_clamped"] >= 0

    mass = sim.grid_mass()
    assert mass.shape == tuple(c + 1 for c in sim.scene.cells)
    assert np.isclose(mass.sum(), sim.mass.sum(), rtol=1e-12)
    assert np.array_equal(mass, pns.rasterize_mass(sim.positions, sim.mass, sim.scene.domain_min,
                                                   sim.scene.domain_max, sim.scene.dx))


def test_views_keep_the_simulation_alive():
    sim = pns.Simulation(TINY / "sand_column_2d.json", integrator="explicit")
    x = sim.positions
    expected = x.copy()
    del sim
    assert np.array_equal(x, expected)


def test_simulation_options_and_errors():
    path = TINY / "sand_column_2d.json"
    sim = pns.Simulation(path, integrator="plasticitynet", dt=5e-4,
                         solver={"max_fixed_point_iterations": 3, "regularizer_weight": 0.5})
    assert sim.dt == 5e-4
    assert sim.solver["max_fixed_point_iterations"] == 3 and sim.solver["regularizer_weight"] == 0.5
    assert pns.Simulation(pns.load_scene(path)).integrator == pns.load_scene(path).integrator
    with pytest.raises(ValueError, match=r'unknown integrator "rk4" \(expected explicit, plasticitynet, return_map, '
                                         r'lagged or analytic\)'):
        pns.Simulation(path, integrator="rk4")
    with pytest.raises(ValueError, match='solver: unknown option "newton_tol"'):
        pns.Simulation(path, integrator="lagged", solver={"newton_tol": 1e-3})
    with pytest.raises(ValueError, match="solver: integrator.cg_tolerance"):
        pns.Simulation(path, integrator="lagged", solver={"cg_tolerance": 2})
    with pytest.raises(ValueError, match="dt must be >= 0"):
        pns.Simulation(path, dt=-1.0)
    with pytest.raises(ValueError, match="frames"):
        sim.advance(-1)
    with pytest.raises(ValueError, match="threads"):
        pns.set_threads(0)


def test_advance_callback_can_stop():
    sim = pns.Simulation(TINY / "sand_column_2d.json", integrator="lagged")
    seen = []

    def callback(s, frame):
        assert s is sim
        seen.append(frame["frame"])
        return frame["frame"] < 2

    frames = sim.advance(5, callback=callback)
    assert seen == [1, 2] and len(frames) == 2 and sim.frame == 2


def test_blow_up_raises_simulation_error():
    sim = pns.Simulation(TINY / "snowball_2d.json", integrator="explicit", dt=5e-3)  # far above its CFL step
    with pytest.raises(pns.SimulationError, match=r"step \d+: particle \d+ .* blew up") as info:
        sim.advance(10)
    assert isinstance(info.value, RuntimeError)
    assert len(sim.step_stats()["dt"]) == sim.total_steps  # the steps before the failure are recorded


def test_ctrl_c_interrupts_between_steps():
    sim = pns.Simulation(TINY / "sand_column_2d.json", integrator="explicit", dt=1e-6)
    # A process started in the background by a non-interactive shell (CI) inherits SIGINT as
    # ignored, and Python then leaves it ignored: install the handler an interactive session has.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    # A real SIGINT from another process, as Ctrl-C sends it.
    killer = subprocess.Popen(["sh", "-c", f"sleep 1; kill -INT {os.getpid()}"])
    try:
        with pytest.raises(KeyboardInterrupt):
            sim.advance(200)  # 20000 steps per frame: far longer than the second
    finally:
        killer.wait()
        signal.signal(signal.SIGINT, previous)
    interrupted_at = sim.total_steps
    assert 0 < interrupted_at and sim.frame < 1000
    assert len(sim.step_stats()["dt"]) == interrupted_at
    assert np.isfinite(sim.positions).all()
    sim.step()  # the state is consistent: it goes on
    assert sim.total_steps == interrupted_at + 1


def test_checkpoint_round_trip(tmp_path):
    path = TINY / "snowball_2d.json"
    sim = pns.Simulation(path, integrator="plasticitynet")
    sim.advance(1)
    sim.save_checkpoint(tmp_path / "c.bin")
    sim.advance(1)
    expected = {a: getattr(sim, a).copy() for a in ("positions", "velocities", "F_elastic", "hardening")}
    x = sim.positions
    resumed = pns.Simulation(path, integrator="plasticitynet")
    resumed.load_checkpoint(tmp_path / "c.bin")
    assert resumed.frame == 1 and len(resumed.step_stats()["dt"]) == 0
    resumed.advance(1)
    for attr, value in expected.items():
        assert np.array_equal(getattr(resumed, attr), value), attr
    sim.load_checkpoint(tmp_path / "c.bin")  # views of sim stay valid and show the loaded state
    assert sim.frame == 1 and not np.array_equal(x, expected["positions"])
    with pytest.raises(FileNotFoundError, match="nope.bin"):
        sim.load_checkpoint(tmp_path / "nope.bin")
    with pytest.raises(ValueError, match="written by the plasticitynet integrator, this run uses lagged"):
        pns.Simulation(path, integrator="lagged").load_checkpoint(tmp_path / "c.bin")


@pytest.mark.parametrize("name,integrator", [("snowball_2d", "plasticitynet"), ("sand_column_3d", "explicit")])
def test_python_stepping_equals_pnet_simulate(tmp_path, name, integrator):
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    out = tmp_path / "run"
    r = subprocess.run([str(PNET), "simulate", str(TINY / f"{name}.json"), "--integrator", integrator,
                        "--frames", "2", "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    sim = pns.Simulation(TINY / f"{name}.json", integrator=integrator)
    sim.advance(2)
    frame = read_ply(out / "frame_00002.ply")
    assert np.array_equal(sim.positions, frame["x"])
    assert np.array_equal(sim.velocities, frame["v"])
    assert np.array_equal(sim.hardening, frame["hardening"])


# --- models ---------------------------------------------------------------------------------------


def _ply_body(path: Path) -> bytes:
    """A frame's data and header without the run id (two runs differ only there)."""
    data = path.read_bytes()
    return b"\n".join(line for line in data.split(b"\n") if not line.startswith(b"comment run_id "))


@pytest.mark.parametrize("name", ["snowball_2d", "metal_frame_2d"])
def test_run_writes_the_folder_pnet_simulate_writes(tmp_path, name):
    """Simulation.run() is the driver behind pnet simulate: the same files, the same frames; pnet simulate
    resumes a Python run; a folder holding another run is refused."""
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    scene = TINY / f"{name}.json"
    cli, py = tmp_path / "cli", tmp_path / "py"
    r = subprocess.run([str(PNET), "simulate", str(scene), "--frames", "2", "--out", str(cli)], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    sim = pns.Simulation(scene)
    sim.run(py, frames=1, checkpoint_every=1)
    assert sim.frame == 1
    r = subprocess.run([str(PNET), "simulate", str(scene), "--frames", "2", "--resume", "--out", str(py)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and "resumed at frame 1" in r.stderr, r.stderr
    files = lambda d: sorted(p.name for p in d.iterdir() if p.name != "checkpoint.bin")  # py's checkpoints at 1
    assert files(py) == files(cli)
    for frame in sorted(cli.glob("frame_*.ply")):
        assert _ply_body(py / frame.name) == _ply_body(frame), frame.name
    strip_wall = lambda rows: [",".join(c for k, c in enumerate(r.split(",")) if k != 5) for r in rows]
    assert strip_wall((py / "stats.csv").read_text().splitlines()) == \
        strip_wall((cli / "stats.csv").read_text().splitlines())
    assert (py / "steps.csv").read_text().splitlines()[0] == (cli / "steps.csv").read_text().splitlines()[0]
    run_py, run_cli = (json.loads((d / "run.json").read_text()) for d in (py, cli))
    assert run_py.keys() == run_cli.keys() and run_py["run_id"] != run_cli["run_id"]

    with pytest.raises(ValueError, match="holds another run"):
        pns.Simulation(scene).run(cli, frames=1)
    pns.Simulation(scene).run(cli, frames=1, overwrite=True)
    assert json.loads((cli / "run.json").read_text())["frames"] == 1 and not (cli / "frame_00002.ply").exists()
    with pytest.raises(ValueError, match="give one"):
        pns.Simulation(scene).run(cli, resume=True, overwrite=True)
    with pytest.raises(ValueError, match="color"):
        pns.Simulation(scene).run(tmp_path / "other", color="rainbow")


def test_run_stops_on_a_failed_step_with_the_frames_before_it_complete(tmp_path):
    scene = tiny_scene("snowball_2d")
    scene["objects"][0]["velocity"] = [0, -30]
    sim = pns.Simulation(scene, integrator="explicit", dt=0.01)  # far above the CFL step: blows up
    with pytest.raises(pns.SimulationError, match="blew up(.|\n)*are complete"):
        sim.run(tmp_path / "run", frames=6)
    assert (tmp_path / "run" / "frame_00000.ply").exists() and (tmp_path / "run" / "stats.csv").exists()


@pytest.mark.parametrize("model_name,dim,E", [("sand_2d", 2, 3.537e5), ("snow_2d", 2, 1.4e5), ("snow_3d", 3, None),
                                              ("metal_nh_2d", 2, 2e9)])
def test_model_matches_torch(model_name, dim, E):
    path = MODELS / f"{model_name}.pt"
    model = pns.load_model(path, E=E)
    reference = plasticitynet.load_model(path, E=E)
    assert model.kind == "energy" and model.dim == dim and model.pinned and len(model.sha256) == 64
    assert model.metadata["dim"] == dim and model.widths[-1] == 1
    F0 = random_F(16, dim, seed=1)
    F = F0 + 0.05 * np.random.default_rng(2).standard_normal((16, dim, dim))
    # Hardening states inside and outside the trained range (snow: a > 0 and a below the range; metal:
    # h > 1): both implementations feed the network the clamped h of docs/physics.md.
    u = np.random.default_rng(3).random(16)
    h = 0.02 + 1.3 * u if model_name.startswith("metal") else -1.5 + 2.5 * u
    for w in (0.0, 1.0):
        tF, tF0, th = (torch.from_numpy(a) for a in (F, F0, h))
        scale = abs(model.E)
        psi = model.psi(F, F0, h, w=w)
        assert psi.shape == (16,)
        assert np.allclose(psi, reference.psi(tF, tF0, th, w=w).detach().numpy(), rtol=0, atol=1e-10 * scale)
        grad = model.gradient(F, F0, h, w=w)
        assert grad.shape == (16, dim, dim)
        assert np.allclose(grad, reference.gradient(tF, tF0, th, w=w).detach().numpy(), rtol=0, atol=1e-10 * scale)
        hess = model.hessian(F, F0, h, w=w)
        assert hess.shape == (16, dim * dim, dim * dim)
        assert np.allclose(hess, reference.hessian(tF, tF0, th, w=w).detach().numpy(), rtol=0, atol=1e-10 * scale)
    psd = model.hessian(F, F0, h, w=0.0, project_psd=True)
    assert (np.linalg.eigvalsh(psd) >= -1e-9 * np.abs(psd).max()).all()
    # grad Psi(F0; F0, h) = E Ptilde(F0, h), by construction of c
    assert np.allclose(model.gradient(F0, F0, h), model.stress(F0, h), rtol=0, atol=1e-9 * scale)
    assert np.allclose(model.stress(F0, h), reference.Ptilde(torch.from_numpy(F0), torch.from_numpy(h)).numpy(),
                       rtol=0, atol=1e-10 * scale)


def test_network_hardening_input_is_min_of_the_state_clamped_to_the_trained_range():
    reference = plasticitynet.load_model(MODELS / "snow_2d.pt", E=1.4e5)
    assert reference.hardening_range == (-0.5, 0.0)
    h = torch.tensor([2.0, 0.0, -0.2, -0.5, -1.29], dtype=torch.float64)
    assert reference.network_hardening(h).tolist() == [0.0, 0.0, -0.2, -0.5, -0.5]
    assert plasticitynet.load_model(MODELS / "metal_2d.pt").network_hardening(
        torch.tensor([0.05, 1.7], dtype=torch.float64)).tolist() == [0.05, 1.0]


def test_return_map_model_matches_torch():
    path = MODELS / "metal_nh_rm_2d.pt"
    model = pns.load_model(path)
    reference = plasticitynet.load_model(path)
    assert model.kind == "return_map"
    Sigma = 1.0 + 0.02 * np.random.default_rng(4).standard_normal((32, 2))
    h = 1e-3 * np.random.default_rng(5).random(32)
    out = model.project(Sigma, h)
    assert out["Sigma"].shape == (32, 2) and out["hardening"].shape == (32,)
    expected = reference.project(torch.from_numpy(Sigma), torch.from_numpy(h)).numpy()
    assert np.allclose(out["Sigma"], expected, rtol=0, atol=1e-10)
    with pytest.raises(ValueError, match="has no energy"):
        model.psi(np.eye(2)[None], np.eye(2)[None])
    with pytest.raises(ValueError, match="no return mapping of its own"):
        pns.load_model(MODELS / "sand_2d.pt").project(Sigma)


def test_model_input_checks():
    model = pns.load_model(MODELS / "sand_2d.pt")
    F = random_F(4, 2, seed=0)
    with pytest.raises(ValueError, match=r"F: expected a float64 array of shape \(n, 2, 2\), got shape \(4, 3, 3\)"):
        model.psi(random_F(4, 3, seed=0), F)
    with pytest.raises(ValueError, match=r"F0: expected a float64 array of shape \(4, 2, 2\), got shape \(3, 2, 2\)"):
        model.psi(F, F[:3])
    with pytest.raises(ValueError, match=r"F: expected a float64 array of shape \(n, 2, 2\), got dtype float32"):
        model.psi(F.astype(np.float32), F)
    with pytest.raises(ValueError, match=r"h: expected a float64 array of shape \(4,\), got shape \(5,\)"):
        model.psi(F, F, np.zeros(5))
    with pytest.raises(ValueError, match="w: expected a regularizer weight >= 0"):
        model.psi(F, F, w=-1.0)
    with pytest.raises(ValueError, match="E: expected a positive Young's modulus"):
        pns.load_model(MODELS / "sand_2d.pt", E=-1.0)
    # lists are taken as float64; a strided numpy array is copied
    assert np.allclose(model.psi(F.tolist(), F[:, :, :]), model.psi(F, F))
    assert np.allclose(model.psi(np.asfortranarray(F), F), model.psi(F, F))


def test_untrusted_model_is_refused(tmp_path):
    copy = tmp_path / "sand_2d.pt"
    shutil.copyfile(MODELS / "sand_2d.pt", copy)
    with pytest.raises(pns.UntrustedModelError, match="sand_2d.pt") as info:
        pns.load_model(copy)
    assert isinstance(info.value, ValueError)
    model = pns.load_model(copy, trusted=True)
    assert not model.pinned and model.kind == "energy"
    scene = tiny_scene("sand_column_2d")
    scene["objects"][0]["model"] = str(copy)
    with pytest.raises(pns.UntrustedModelError, match=r"objects\[0\]\.model"):
        pns.Simulation(scene)
    assert pns.Simulation(scene, trust_models=True).num_particles > 0


# --- materials and metrics -----------------------------------------------------------------------


@pytest.mark.parametrize("name,dim", [("sand", 2), ("snow", 3), ("metal", 2)])
def test_material_matches_torch(name, dim):
    material = pns.Material(name, dim)
    F = random_F(32, dim, seed=7, spread=0.2)
    h = np.full(32, material.to_dict().get("initial_hardening", 0.0))
    P = material.stress(F, h)
    r = material.return_map(F, h)
    assert P.shape == (32, dim, dim) and r["F_elastic"].shape == (32, dim, dim) and r["hardening"].shape == (32,)
    assert r["branch"].dtype == np.int32 and set(r["branch"]) <= set(range(len(pns.BRANCHES)))
    assert pns.Material(material.to_dict(), dim).to_dict() == material.to_dict()
    reference = TorchMaterial.from_dict(material.to_dict(), dim)
    tF, th = torch.from_numpy(F), torch.from_numpy(h)
    assert np.allclose(P, reference.elastoplastic_stress(tF, th).numpy(), rtol=1e-9, atol=1e-9 * np.abs(P).max())
    Fe, h_new = reference.elastic_part(tF, th)
    assert np.allclose(r["F_elastic"], Fe.numpy(), rtol=0, atol=1e-10)
    assert np.allclose(r["hardening"], h_new.numpy(), rtol=1e-10, atol=1e-12)
    assert name in pns.material_presets()


def test_material_errors():
    with pytest.raises(ValueError, match="granite"):
        pns.Material("granite", 2)
    with pytest.raises(ValueError, match="dim: expected 2 or 3"):
        pns.Material("sand", 4)
    with pytest.raises(ValueError, match=r"F: expected a float64 array of shape \(n, 2, 2\)"):
        pns.Material("sand", 2).stress(np.eye(2))


def test_iou():
    a = np.zeros((8, 8))
    a[2:5, 2:5] = 1.0
    b = np.roll(a, 1, axis=0)
    same = pns.iou(a, a)
    assert same["soft"] == 1.0 and same["binary"] == 1.0
    shifted = pns.iou(a, b)
    assert np.isclose(shifted["soft"], 6 / 12) and np.isclose(shifted["binary"], 6 / 12)
    assert 0 < pns.iou(np.ones((3, 3, 3)), np.ones((3, 3, 3)))["plasticinelab"] <= 1
    with pytest.raises(ValueError, match="different shapes"):
        pns.iou(a, np.zeros((8, 9)))
    with pytest.raises(ValueError, match="a: expected a float64 array"):
        pns.iou(np.zeros(8), a)
    with pytest.raises(ValueError, match="must be finite and >= 0"):
        pns.iou(-a, a)


def test_module_docstrings():
    public = [n for n in dir(pns) if not n.startswith("_")]
    for name in public:
        obj = getattr(pns, name)
        if callable(obj):
            assert obj.__doc__, name
    for cls in (pns.Simulation, pns.Model, pns.Material, pns.Scene):
        for name, member in vars(cls).items():
            if not name.startswith("_") and callable(member):
                assert member.__doc__ and len(member.__doc__.splitlines()[-1]) >= 0, f"{cls.__name__}.{name}"


def test_example_script(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "example_sand.py"), "--tiny", "--frames", "2",
                        "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    for name in ("particles.png", "iou.png"):
        assert (tmp_path / name).stat().st_size > 1000, name
    assert "soft IoU" in r.stdout


def test_readme_example_runs():
    """The README's Python example, on the tiny sand column (the full one takes longer)."""
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## From Python"):]
    code = section[section.index("```python\n") + len("```python\n"):]
    code = code[:code.index("```")]
    assert len(code.strip().splitlines()) <= 13
    code = code.replace("scenes/sand_column_2d.json", "scenes/tiny/sand_column_2d.json")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("soft IoU") == 5 and "hessian (1, 4, 4)" in r.stdout


def test_imports_beside_torch_in_either_order():
    for code in ("import plasticitynet_sim, torch; print(torch.ones(2).sum().item())",
                 "import torch, plasticitynet_sim; print(torch.ones(2).sum().item())"):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and r.stdout.strip() == "2.0", r.stderr


def test_compare_runs_matches_pnet_compare(tmp_path):
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    scene = TINY / "sand_column_2d.json"
    for name, integrator in (("a", "explicit"), ("b", "lagged")):
        r = subprocess.run([str(PNET), "simulate", str(scene), "--integrator", integrator, "--frames", "3",
                            "--out", str(tmp_path / name)], capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
    result = pns.compare_runs(tmp_path / "a", tmp_path / "b")
    assert list(result["frame"]) == [0, 1, 2, 3] and result["only_a"] == [] and result["dx"] > 0
    assert result["soft"][0] == 1.0 and 0 < result["soft"][-1] < 1
    r = subprocess.run([str(PNET), "compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "c")],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "c" / "iou.csv").read_text().splitlines()[1:]
    assert np.allclose([float(row.split(",")[2]) for row in rows], result["soft"], rtol=1e-8)
    assert np.allclose([float(row.split(",")[5]) for row in rows], result["soft_coarse"], rtol=1e-8)
    assert result["soft_coarse"][0] == 1.0 and (result["soft_coarse"] > 0).all()
    assert result["spread_a"][0] == result["spread_b"][0] > 0 and (result["height_a"] > 0).all()
    with pytest.raises(FileNotFoundError, match="nope"):
        pns.compare_runs(tmp_path / "a", tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="run.json"):
        pns.compare_runs(tmp_path / "a", tmp_path / "empty")


def test_compare_meshes_matches_pnet_compare_and_a_numpy_reference(tmp_path):
    """The meshes' comparison (FEM, coupling) from Python, from `pnet compare` and from numpy agree."""
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    for scene, coupled in (("metal_frame_2d", False), ("sand_fem_coupling_2d", True)):
        dirs = {}
        for name, integrator in (("a", "return_map"), ("b", "lagged")):  # implicit both: seconds, not minutes
            dirs[name] = tmp_path / f"{scene}_{name}"
            r = subprocess.run([str(PNET), "simulate", str(TINY / f"{scene}.json"), "--integrator", integrator,
                                "--frames", "2", "--out", str(dirs[name])], capture_output=True, text=True, timeout=600)
            assert r.returncode == 0, r.stderr
        result = pns.compare_meshes(dirs["a"], dirs["b"])
        assert list(result["frame"]) == [0, 1, 2]
        info = json.loads((dirs["a"] / "run.json").read_text())
        suffix = "_mesh.ply" if coupled else ".ply"
        rest = pns.read_mesh_frame(dirs["a"] / f"frame_00000{suffix}")["position"]
        nodes = len(rest) if coupled else info["mesh_first_node"][1]
        size = (np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)) if coupled else info["bbox_diagonal"])
        assert result["nodes"] == nodes and np.isclose(result["size"], size, rtol=1e-12)
        for k, frame in enumerate(result["frame"]):
            pa = pns.read_mesh_frame(dirs["a"] / f"frame_{frame:05d}{suffix}")["position"][:nodes]
            pb = pns.read_mesh_frame(dirs["b"] / f"frame_{frame:05d}{suffix}")["position"][:nodes]
            d = np.linalg.norm(pa - pb, axis=1)
            assert np.isclose(result["mean"][k], d.mean(), rtol=1e-12, atol=1e-15)
            assert np.isclose(result["max_pct"][k], 100 * d.max() / size, rtol=1e-12, atol=1e-12)
        assert result["max"][-1] > 0  # the two integrators part
        assert list(result["penetrations"]) == ([0, 0, 0] if coupled else [-1, -1, -1])
        r = subprocess.run([str(PNET), "compare", str(dirs["a"]), str(dirs["b"]), "--out", str(tmp_path / scene)],
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        rows = (tmp_path / scene / "nodal.csv").read_text().splitlines()[1:]
        assert np.allclose([float(row.split(",")[2]) for row in rows], result["mean"], rtol=1e-8, atol=1e-15)
        assert (tmp_path / scene / "iou.csv").exists() == coupled
    r = subprocess.run([str(PNET), "simulate", str(TINY / "sand_column_2d.json"), "--integrator", "explicit",
                        "--frames", "1", "--out", str(tmp_path / "mpm")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    with pytest.raises(ValueError, match="no meshes"):
        pns.compare_meshes(tmp_path / "mpm", tmp_path / "mpm")
    with pytest.raises(ValueError, match="what the frames hold"):
        pns.compare_meshes(tmp_path / "metal_frame_2d_a", tmp_path / "mpm")


def test_a_model_for_other_plasticity_parameters_raises_value_error():
    scene = json.loads((TINY / "sand_column_2d.json").read_text())
    scene["objects"][0]["material"]["plasticity"]["friction_angle_deg"] = 35
    scene["objects"][0]["model"] = str(MODELS / "sand_2d.pt")
    with pytest.raises(ValueError, match=r"trained for material\.plasticity\.friction_angle_deg = 30\.0, the object's "
                                         r"material has 35\.0"):
        pns.Simulation(scene, integrator="plasticitynet")


def _sand_at(angle: float, nu: float, E: float = 3.537e5) -> dict:
    material = TorchMaterial.preset("sand", 2).to_dict()
    material["plasticity"]["friction_angle_deg"] = angle
    material["elasticity"].update(nu=nu, E=E)
    return material


@pytest.mark.parametrize("angle,nu", [(20.0, 0.2), (30.0, 0.3), (37.5, 0.41), (45.0, 0.45)])
def test_parametric_model_matches_torch_at_each_parameter(angle, nu):
    """The C++ runtime (fused kernel, parameters as constant inputs) against the torch model, both bound to
    the same material of the family: value, gradient and Hessian; and exact at F0 for that material."""
    path = MODELS / "sand_param_2d.pt"
    material = _sand_at(angle, nu)
    model = pns.load_model(path, E=3.537e5, material=material)
    reference = plasticitynet.load_model(path, E=3.537e5, material=material)
    assert [p[0] for p in model.parameters] == ["plasticity.friction_angle_deg", "elasticity.nu"]
    F0 = random_F(16, 2, seed=4)
    F = F0 + 0.05 * np.random.default_rng(5).standard_normal((16, 2, 2))
    tF, tF0 = torch.from_numpy(F), torch.from_numpy(F0)
    scale = 3.537e5
    for w in (0.0, 1.0):
        assert np.allclose(model.psi(F, F0, w=w), reference.psi(tF, tF0, w=w).detach().numpy(), rtol=0, atol=1e-10 * scale)
        assert np.allclose(model.gradient(F, F0, w=w), reference.gradient(tF, tF0, w=w).detach().numpy(), rtol=0,
                           atol=1e-10 * scale)
        assert np.allclose(model.hessian(F, F0, w=w), reference.hessian(tF, tF0, w=w).detach().numpy(), rtol=0,
                           atol=1e-10 * scale)
    exact = TorchMaterial.from_dict(material, 2).elastoplastic_stress(tF0).numpy()
    assert np.allclose(model.gradient(F0, F0), exact, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("values", [(30.0, 0.2, 0.1, 0.15), (60.0, 1.0, 0.5, 0.35), (52.0, 0.7, 0.25, 0.3)])
def test_parametric_snow_model_matches_torch_with_hardening(values):
    """The 2D snow family (four parameters after h) at both ends of its box and inside, hardening states
    inside and outside the trained range: the C++ runtime against torch, and exact at F0."""
    path = MODELS / "snow_param_2d.pt"
    material = TorchMaterial.preset("snow", 2).to_dict()
    angle, xi, beta, nu = values
    material["plasticity"].update(friction_angle_deg=angle, xi=xi, beta=beta)
    material["elasticity"]["nu"] = nu
    model = pns.load_model(path, E=1.4e5, material=material)
    reference = plasticitynet.load_model(path, E=1.4e5, material=material)
    F0 = random_F(12, 2, seed=6)
    F = F0 + 0.05 * np.random.default_rng(7).standard_normal((12, 2, 2))
    h = -1.2 + 1.5 * np.random.default_rng(8).random(12)
    tF, tF0, th = (torch.from_numpy(a) for a in (F, F0, h))
    scale = 1.4e5
    assert np.allclose(model.gradient(F, F0, h, w=1.0), reference.gradient(tF, tF0, th, w=1.0).detach().numpy(),
                       rtol=0, atol=1e-10 * scale)
    assert np.allclose(model.hessian(F, F0, h), reference.hessian(tF, tF0, th).detach().numpy(), rtol=0,
                       atol=1e-10 * scale)
    assert np.allclose(model.gradient(F0, F0, h), reference.Ptilde(tF0, th).numpy(), rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("values", [(0.0, 0.25), (0.3, 0.45), (0.17, 0.31)])
def test_parametric_metal_model_matches_torch_with_hardening(values):
    """The 2D metal family (hardening coefficient and nu after the yield state h) at both ends of its box
    and inside: the C++ runtime against torch, and exact at F0."""
    path = MODELS / "metal_param_2d.pt"
    material = TorchMaterial.preset("metal", 2).to_dict()
    coefficient, nu = values
    material["plasticity"]["hardening_coefficient"] = coefficient
    material["elasticity"]["nu"] = nu
    E = 2.0e8
    model = pns.load_model(path, E=E, material=material)
    reference = plasticitynet.load_model(path, E=E, material=material)
    assert [p[0] for p in model.parameters] == ["plasticity.hardening_coefficient", "elasticity.nu"]
    F0 = random_F(12, 2, seed=9)
    F = F0 + 0.02 * np.random.default_rng(10).standard_normal((12, 2, 2))
    h = np.random.default_rng(11).random(12)
    tF, tF0, th = (torch.from_numpy(a) for a in (F, F0, h))
    assert np.allclose(model.gradient(F, F0, h, w=1.0), reference.gradient(tF, tF0, th, w=1.0).detach().numpy(),
                       rtol=0, atol=1e-10 * E)
    assert np.allclose(model.hessian(F, F0, h), reference.hessian(tF, tF0, th).detach().numpy(), rtol=0,
                       atol=1e-10 * E)
    assert np.allclose(model.gradient(F0, F0, h), reference.Ptilde(tF0, th).numpy(), rtol=0, atol=1e-9 * E)


def test_parametric_model_refuses_a_material_outside_its_ranges():
    with pytest.raises(ValueError, match=r"material\.plasticity\.friction_angle_deg = 50\.0 is outside the range "
                                         r"\[20\.0, 45\.0\]"):
        pns.load_model(MODELS / "sand_param_2d.pt", material=_sand_at(50.0, 0.3))


@pytest.mark.parametrize("angle,nu,accepted", [(20.0, 0.2, True), (45.0, 0.45, True), (19.0, 0.3, False)])
def test_a_scene_runs_with_a_parametric_model_at_each_end_of_its_ranges(tmp_path, angle, nu, accepted):
    scene = json.loads((TINY / "sand_column_2d.json").read_text())
    scene["objects"][0]["material"] = _sand_at(angle, nu)
    scene["objects"][0]["model"] = str(MODELS / "sand_param_2d.pt")
    if not accepted:
        with pytest.raises(ValueError, match=r"objects\[0\]\.model: .*sand_param_2d\.pt: material\.plasticity\."
                                             r"friction_angle_deg = 19\.0 is outside the range \[20\.0, 45\.0\]"):
            pns.Simulation(scene, integrator="plasticitynet")
        return
    sim = pns.Simulation(scene, integrator="plasticitynet")
    frames = sim.advance(2)
    assert all(f["converged"] for f in frames)


# FEM scenes (meshes): the same Simulation class, with node and element arrays.

def test_fem_scene_steps_with_mesh_arrays_and_contact_stats(tmp_path):
    sim = pns.Simulation(str(TINY / "metal_frame_2d.json"), integrator="analytic")
    assert sim.is_fem and sim.num_particles == 0 and sim.dt == 1e-2
    rest = sim.rest_nodes
    first = sim.mesh_first_node
    frames = sim.advance(2)
    assert [f["frame"] for f in frames] == [1, 2]
    assert all(f["converged"] and f["contact_pairs"] > 0 and f["min_distance"] > 0 for f in frames)
    nodes, elements = sim.nodes, sim.elements
    assert nodes.shape == rest.shape and elements.shape[1] == 3 and elements.max() < len(nodes)
    # The plate moved 2 mm down along its prescribed path.
    assert np.allclose(nodes[first[1]:first[2], 1] - rest[first[1]:first[2], 1], -0.002, atol=1e-12)
    assert sim.element_hardening.shape == (len(elements),)
    contact = sim.contact
    assert 0 < contact["min_distance"] and contact["dhat"] == pytest.approx(1e-3 * contact["bbox_diagonal"])
    stats = sim.step_stats()
    assert len(stats["kinematic_stages"]) == 4 and stats["ccd_queries"].sum() > 0
    with pytest.raises(ValueError, match="has no particles"):
        sim.positions
    with pytest.raises(ValueError, match="has no mesh"):
        pns.Simulation(str(TINY / "sand_column_2d.json")).nodes
    # Checkpoints resume bit-identically.
    sim.save_checkpoint(tmp_path / "state.bin")
    more = sim.advance(1)
    again = pns.Simulation(str(TINY / "metal_frame_2d.json"), integrator="analytic")
    again.load_checkpoint(tmp_path / "state.bin")
    assert again.frame == 2
    again.advance(1)
    assert np.array_equal(again.nodes, sim.nodes) and more[0]["frame"] == 3


def test_3d_fem_scene_has_tetrahedra_and_boundary_triangles():
    sim = pns.Simulation(str(TINY / "metal_frame_3d.json"), integrator="lagged")
    rest, first = sim.rest_nodes, sim.mesh_first_node
    frames = sim.advance(1)
    assert frames[0]["converged"] and frames[0]["contact_pairs"] > 0 and frames[0]["min_distance"] > 0
    nodes, elements, faces = sim.nodes, sim.elements, sim.boundary_faces
    assert nodes.shape == rest.shape == (first[-1], 3)
    assert elements.shape[1] == 4 and faces.shape[1] == 3 and elements.max() < len(nodes)
    assert np.allclose(nodes[first[1]:first[2], 1] - rest[first[1]:first[2], 1], -0.001, atol=1e-12)
    stats = sim.step_stats()
    assert stats["broad_phase_s"].sum() > 0


def test_fem_analytic_is_refused_for_neo_hookean_metal():
    with pytest.raises(ValueError, match=r"meshes\[0\]\.material: the analytic integrator needs StVK-Hencky"):
        pns.Simulation(str(TINY / "metal_nh_frame_2d.json"), integrator="analytic")


@pytest.mark.parametrize("kwargs, names", [
    (dict(dt=float("nan")), "dt"), (dict(dt=float("inf")), "dt"), (dict(dt=-1e-3), "dt"), (dict(dt="abc"), "dt"),
    (dict(cfl=float("nan")), "cfl"), (dict(cfl=0.0), "cfl"), (dict(cfl=[0.5]), "cfl"),
    (dict(integrator="implicit"), "integrator"), (dict(integrator=3), "integrator"),
    (dict(solver={"newton_tolerance": float("nan")}), "newton_tolerance"),
    (dict(solver={"newton_acceleration_tolerance": -1.0}), "newton_acceleration_tolerance"),
    (dict(solver={"cg_tolerance": float("inf")}), "cg_tolerance"),
    (dict(solver={"regularizer_weight": float("-inf")}), "regularizer_weight"),
    (dict(solver={"tangent_damping": -1.0}), "tangent_damping"),
    (dict(solver={"fixed_point_tolerance": float("nan")}), "fixed_point_tolerance"),
    (dict(solver={"max_newton_iterations": 2.5}), "max_newton_iterations"),
    (dict(solver={"preconditioner": "ilu"}), "preconditioner"),
    (dict(solver={"time_integrator": "rk4"}), "time_integrator"),
    (dict(solver=[1, 2]), "solver"),
])
def test_bad_keyword_is_a_value_or_type_error_naming_it(kwargs, names):
    """Every keyword of Simulation(): a ValueError (TypeError for a wrong type) whose message names it,
    never a RuntimeError from the JSON or cast layers underneath."""
    with pytest.raises((ValueError, TypeError)) as info:
        pns.Simulation(str(ROOT / "scenes" / "tiny" / "sand_column_2d.json"), **kwargs)
    assert names in str(info.value), str(info.value)


@pytest.mark.parametrize("form", ["local_identity", "global_identity", "global"])
def test_ablation_model_forms_match_torch(form):
    """The energy forms the paper rejected (models/ablation/): the C++ energy through the module equals
    plasticitynet.load_model's, and only eq. 8 would reproduce the stress at F = F0."""
    path = MODELS / "ablation" / f"sand_2d_{form}.pt"
    model = pns.load_model(path, E=3.537e5)
    reference = plasticitynet.load_model(path, E=3.537e5)
    assert model.energy_form == form == reference.energy_form and model.pinned
    F0 = random_F(12, 2, seed=4)
    F = F0 + 0.05 * np.random.default_rng(5).standard_normal((12, 2, 2))
    tF, tF0 = torch.from_numpy(F), torch.from_numpy(F0)
    scale = model.E
    assert np.allclose(model.gradient(F, F0, w=1.0), reference.gradient(tF, tF0, w=1.0).numpy(), rtol=0, atol=1e-10 * scale)
    assert np.allclose(model.hessian(F, F0, w=1.0), reference.hessian(tF, tF0, w=1.0).numpy(), rtol=0, atol=1e-10 * scale)
    assert not np.allclose(model.gradient(F0, F0), model.stress(F0), rtol=0, atol=1e-4 * scale)


def test_default_threads_are_every_available_core():
    # Set when the module is imported, before LibTorch loads a model (which would otherwise impose
    # its own intra-op count on OpenMP).
    env = os.environ.get("OMP_NUM_THREADS", "")
    cores = int(env) if env.isdigit() and int(env) > 0 else len(os.sched_getaffinity(0))
    assert pns.available_cores() == cores
    sim = pns.Simulation(TINY / "sand_column_2d.json", integrator="plasticitynet")
    sim.step()
    assert pns.threads() == cores
    stats = sim.step_stats()
    assert stats["reference_updates"][-1] >= 1 and 0.0 < stats["true_residual"][-1] <= 1e-3


def test_bdf2_is_a_solver_option_of_fem_scenes():
    """solver={"time_integrator": "bdf2"} steps a FEM scene with BDF2 (after a backward-Euler first step)."""
    path = TINY / "metal_frame_2d.json"
    frames = {}
    for name in ("backward_euler", "bdf2"):
        sim = pns.Simulation(path, integrator="lagged", dt=1e-2, solver={"time_integrator": name})
        assert sim.solver["time_integrator"] == name
        sim.advance(2)
        frames[name] = np.array(sim.nodes)
    assert np.abs(frames["bdf2"] - frames["backward_euler"]).max() > 0.0


def test_frames_are_read_by_the_simulators_own_readers(tmp_path):
    """plasticitynet.frames reads what Simulation.run() wrote with the C++ readers: the particle and mesh
    frames of a coupled run hold the simulation's positions; bad files name the file and the problem."""
    from plasticitynet.frames import read_mesh_ply, read_particle_positions

    sim = pns.Simulation(TINY / "sand_fem_coupling_2d.json", integrator="explicit")
    sim.run(tmp_path / "run", frames=1, checkpoint_every=0)
    assert np.array_equal(read_particle_positions(tmp_path / "run" / "frame_00001.ply"), sim.positions)
    mesh = read_mesh_ply(tmp_path / "run" / "frame_00001_mesh.ply")
    assert mesh.dim == 2 and np.array_equal(mesh.position, sim.nodes)
    assert np.array_equal(mesh.triangles, sim.elements) and mesh.hardening.shape == (len(sim.elements),)
    frame = pns.read_particle_frame(tmp_path / "run" / "frame_00001.ply")
    assert frame["run_id"] == json.loads((tmp_path / "run" / "run.json").read_text())["run_id"]
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_particle_positions(tmp_path / "missing.ply")
    with pytest.raises(ValueError, match="frame_00001.ply"):
        read_mesh_ply(tmp_path / "run" / "frame_00001.ply")  # a particle frame is not a mesh frame


def test_one_launcher_writes_pnet_simulates_command_line(tmp_path):
    from plasticitynet import launch

    cmd = launch.simulate_command("pnet", "s.json", tmp_path, integrator="explicit", dt=1e-5, frames=2, threads=1,
                                  overwrite=True, options=["--color", "hardening"])
    assert cmd == ["pnet", "simulate", "s.json", "--integrator", "explicit", "--dt", "1e-05", "--frames", "2",
                   "--threads", "1", "--out", str(tmp_path), "--overwrite", "--color", "hardening"]
    finished = launch.run(launch.simulate_command(PNET, TINY / "sand_column_2d.json", tmp_path / "r", frames=1))
    assert finished.status == 0 and (tmp_path / "r" / "frame_00001.ply").exists()
    bad = launch.run(launch.simulate_command(PNET, TINY / "sand_column_2d.json", tmp_path / "r2", dt=-1))
    assert bad.status == 2 and "--dt" in bad.output


def test_inside_count_is_the_simulators_test():
    """plasticitynet_sim.inside_count (the C++ inside_boundary) on a unit square's edges and a unit cube's
    triangles: inside, outside and on the boundary (counted, as the simulator counts penetrations)."""
    from plasticitynet.frames import inside_count

    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    points = np.array([[0.5, 0.5], [0.1, 0.9], [1.5, 0.5], [-0.1, 0.2], [0.5, 0.0]])  # 2 in, 2 out, 1 on
    assert inside_count(points, square, edges) == 3
    cube = np.array([[x, y, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)])
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    assert inside_count(np.array([[0.5, 0.5, 0.5], [0.2, 0.7, 0.9], [1.2, 0.5, 0.5]]), cube, faces) == 2
    with pytest.raises(ValueError, match="facets: node index 9"):
        pns.inside_count(points, square, np.array([[0, 9]]))
