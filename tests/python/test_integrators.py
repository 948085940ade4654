"""The integrators are named by what they compute (cpp/pnet/solver/integrators.hpp, docs/solver.md):
plasticitynet evaluates its network on every Newton iteration, so the network decides its path;
return_map, the classical solver, reads no model at all. Refused combinations name the other one."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import plasticitynet_sim as pns

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "models"
TINY = ROOT / "scenes" / "tiny"
PNET = ROOT / os.environ.get("PNET_BUILD_DIR", "build") / "cpp" / "pnet"

# Two different eq. 8 networks per material: the shipped one and another (the sand ablation's
# eq. 8 network: raw input, width 32; for metal the parametric network at the preset's parameters).
OTHER_MODEL = {"sand_column_2d": MODELS / "ablation" / "sand_2d_eq8.pt", "metal_frame_2d": MODELS / "metal_param_2d.pt"}


def tiny(name: str, model: Path | None = None, drop_models: bool = False) -> dict:
    """A tiny scene as a dict, its model paths absolute, optionally another model or none."""
    scene = json.loads((TINY / f"{name}.json").read_text())
    for item in scene.get("objects", []) + scene.get("meshes", []):
        if "model" not in item:
            continue
        if drop_models:
            del item["model"]
        else:
            item["model"] = str(model if model else (TINY / item["model"]).resolve())
    return scene


def run(scene: dict, integrator: str, frames: int, solver: dict | None = None):
    sim = pns.Simulation(scene, integrator=integrator, solver=solver)
    sim.advance(frames)
    state = sim.nodes.copy() if sim.is_fem else sim.positions.copy()
    return sim, state, sim.step_stats()


def test_the_list_of_integrators():
    names = [i["name"] for i in pns.integrators()]
    assert names == ["explicit", "plasticitynet", "return_map", "lagged", "analytic"]
    by_name = {i["name"]: i for i in pns.integrators()}
    assert by_name["plasticitynet"]["reads_models"] and not by_name["return_map"]["reads_models"]
    assert all(not by_name[n]["reads_models"] for n in ("explicit", "lagged", "analytic"))
    assert "network" in by_name["plasticitynet"]["solves"] and "tangent" in by_name["return_map"]["solves"]


@pytest.mark.parametrize("name,frames", [("sand_column_2d", 1), ("metal_frame_2d", 1)])
def test_plasticitynet_evaluates_its_network_on_every_newton_iteration(name, frames):
    sim, _, steps = run(tiny(name), "plasticitynet", frames)
    newton, network = steps["newton_iterations"], steps["network_evaluations"]
    if sim.is_fem:  # the elastic predictor's iterations (part of the count) evaluate no network
        newton = newton - steps["predictor_iterations"]
    assert newton.sum() > 0, "no Newton iteration: nothing was checked"
    assert np.all(network >= newton), f"network passes {network} below Newton iterations {newton}"
    # Each step's first pass covers every point (network_reuse keeps Hessians within a step only), and
    # no step evaluates more points than its passes over all of them.
    points, everywhere = steps["network_points"], network * (len(sim.velocities) if not sim.is_fem else 1)
    assert np.all(points > 0)
    if not sim.is_fem:
        assert np.all(points >= len(sim.velocities)) and np.all(points <= everywhere), (points, everywhere)
    # return_map on the same scene passes the network zero times.
    _, _, classical = run(tiny(name), "return_map", frames)
    assert classical["newton_iterations"].sum() > 0 and classical["network_evaluations"].sum() == 0


def test_network_reuse_zero_evaluates_every_particle_at_every_pass():
    """`network_reuse` reaches the energy: at 0 every pass covers every particle; at the default the
    network evaluates fewer points over the frame, and the steps converge to the same tolerance."""
    sim, _, every = run(tiny("sand_column_2d"), "plasticitynet", 1, solver={"network_reuse": 0.0})
    n = len(sim.velocities)
    assert np.array_equal(every["network_points"], every["network_evaluations"] * n)
    _, _, reused = run(tiny("sand_column_2d"), "plasticitynet", 1)
    assert np.all(reused["network_points"] >= n), "each step's first pass covers every particle"
    assert reused["network_points"].sum() < every["network_points"].sum()
    assert reused["converged"].all() and every["converged"].all()


@pytest.mark.parametrize("name", ["sand_column_2d", "metal_frame_2d"])
def test_two_networks_give_different_paths_and_frames(name):
    _, a, steps_a = run(tiny(name), "plasticitynet", 1)
    _, b, steps_b = run(tiny(name, OTHER_MODEL[name]), "plasticitynet", 1)
    assert not np.array_equal(a, b), "two different networks gave bit-identical frames: the network is not on the path"
    paths_differ = any(not np.array_equal(steps_a[k], steps_b[k]) for k in ("newton_iterations", "residual", "energy"))
    assert paths_differ


def test_the_budgeted_mode_depends_on_the_network_beyond_the_tolerance():
    """One solve per step about F0 = F(v*), not converged (the paper's cheapest mode): the network's
    accuracy decides the result, so two networks differ by more than the Newton tolerance (m/s), and
    both far more from the converged classical step. dt 5e-3 s, so that a step deforms enough for the
    reference F(v*) to be far from F(v)."""
    budget = {"outer_iteration": "fixed_point", "max_fixed_point_iterations": 1}
    sims = [pns.Simulation(tiny("sand_column_2d", model), integrator="plasticitynet", dt=5e-3, solver=budget)
            for model in (None, OTHER_MODEL["sand_column_2d"])]
    classical = pns.Simulation(tiny("sand_column_2d"), integrator="return_map", dt=5e-3)
    for sim in sims + [classical]:
        sim.advance(2)
    tolerance = sims[0].solver["newton_tolerance"]
    assert np.abs(sims[0].velocities - sims[1].velocities).max() > 3 * tolerance
    assert np.abs(sims[0].velocities - classical.velocities).max() > 30 * tolerance
    assert sims[0].step_stats()["fixed_point_iterations"].max() == 1


@pytest.mark.parametrize("name", ["sand_column_2d", "metal_frame_2d"])
def test_return_map_reads_no_model(name):
    _, with_model, _ = run(tiny(name), "return_map", 1)
    _, other_model, _ = run(tiny(name, OTHER_MODEL[name]), "return_map", 1)
    _, no_model, _ = run(tiny(name, drop_models=True), "return_map", 1)
    assert np.array_equal(with_model, other_model) and np.array_equal(with_model, no_model)
    # A model file that does not exist is not even opened.
    _, missing, _ = run(tiny(name, ROOT / "no-such-model.pt"), "return_map", 1)
    assert np.array_equal(with_model, missing)


@pytest.mark.parametrize(
    "integrator,solver,message",
    [
        ("plasticitynet", {"hessian": "tangent"}, "integrator return_map"),
        ("return_map", {"hessian": "network"}, "integrator plasticitynet"),
        ("return_map", {"outer_iteration": "fixed_point"}, "plasticitynet's"),
    ],
)
def test_refused_combinations_name_the_other_integrator(integrator, solver, message):
    with pytest.raises(ValueError, match=message):
        pns.Simulation(tiny("sand_column_2d"), integrator=integrator, solver=solver)


def test_a_scene_file_with_plasticitynet_and_the_tangent_is_refused(tmp_path):
    scene = tiny("sand_column_2d")
    scene["integrator"]["hessian"] = "tangent"
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    with pytest.raises(ValueError, match=r"scene\.json: integrator\.hessian: .*return_map"):
        pns.Simulation(str(path))
    done = subprocess.run([str(PNET), "simulate", str(path), "--out", str(tmp_path / "out"), "--frames", "1"],
                          capture_output=True, text=True)
    assert done.returncode == 2 and "return_map" in done.stderr


def test_the_integrator_is_named_in_run_json_steps_csv_and_python(tmp_path):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(tiny("sand_column_2d")))
    for integrator in ("plasticitynet", "return_map"):
        out = tmp_path / integrator
        subprocess.run([str(PNET), "simulate", str(scene), "--integrator", integrator, "--out", str(out),
                        "--frames", "1", "--threads", "1"], check=True, capture_output=True)
        run_json = json.loads((out / "run.json").read_text())
        assert run_json["integrator"] == integrator
        assert (run_json["models"] != []) == (integrator == "plasticitynet")
        lines = (out / "steps.csv").read_text().splitlines()
        header = lines[0].split(",")
        assert header[-1] == "integrator" and all(line.split(",")[-1] == integrator for line in lines[1:])
        network = [int(line.split(",")[header.index("network_evaluations")]) for line in lines[1:]]
        assert (sum(network) > 0) == (integrator == "plasticitynet")
        assert pns.Simulation(str(scene), integrator=integrator).integrator == integrator


def test_a_checkpoint_from_before_the_renaming_resumes_under_return_map(tmp_path):
    """Before 2026-11-28 `plasticitynet` named the classical solver: its checkpoints (no naming revision
    in the name field) resume under return_map and are refused, naming it, under plasticitynet."""
    sim = pns.Simulation(tiny("sand_column_2d"), integrator="return_map")
    sim.advance(1)
    path = tmp_path / "checkpoint.bin"
    sim.save_checkpoint(path)
    data = path.read_bytes()
    field = b"return_map" + b"\0" * 4 + b"n2"
    assert data.count(field) == 1
    # The payload, its name field as before the revision, sealed again ("PNETSHA2" + SHA-256 hex of the
    # bytes before it, cpp/pnet/io/checkpoint_arrays.hpp).
    payload = data[: data.rindex(b"PNETSHA2")].replace(field, b"plasticitynet" + b"\0" * 3)
    old = tmp_path / "old.bin"
    old.write_bytes(payload + b"PNETSHA2" + hashlib.sha256(payload).hexdigest().encode())
    resumed = pns.Simulation(tiny("sand_column_2d"), integrator="return_map")
    resumed.load_checkpoint(old)
    assert resumed.frame == 1 and np.array_equal(resumed.positions, sim.positions)
    with pytest.raises(ValueError, match="return_map"):
        pns.Simulation(tiny("sand_column_2d"), integrator="plasticitynet").load_checkpoint(old)
    # A checkpoint of today's plasticitynet is refused by return_map as another integrator's.
    learned = pns.Simulation(tiny("sand_column_2d"), integrator="plasticitynet")
    learned.save_checkpoint(tmp_path / "learned.bin")
    with pytest.raises(ValueError, match="written by the plasticitynet integrator"):
        pns.Simulation(tiny("sand_column_2d"), integrator="return_map").load_checkpoint(tmp_path / "learned.bin")


@pytest.mark.parametrize("integrator", ["return_map", "lagged"])
def test_another_implicit_integrator_on_a_coupled_scene_takes_the_particles_step(integrator):
    """Particles beside meshes (MPM-FEM coupling) step at implicit MPM's 1e-3 s, not FEM's 1e-2 s: with
    1e-2 s the sand's particles cross cells per step (the coupling's docs/scenes.md step is 1e-3)."""
    scene = json.loads((TINY / "sand_fem_coupling_2d.json").read_text())
    assert scene["integrator"]["name"] == "plasticitynet"
    sim = pns.Simulation(TINY / "sand_fem_coupling_2d.json", integrator=integrator)
    assert sim.dt == 1e-3


def test_pnet_simulate_help_lists_every_integrator():
    done = subprocess.run([str(PNET), "simulate", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and done.stderr == ""
    assert done.stdout.startswith("usage: pnet simulate")
    for integrator in pns.integrators():
        assert f"    {integrator['name']} " in done.stdout
    assert all(len(line) <= 112 for line in done.stdout.splitlines()[-14:])
