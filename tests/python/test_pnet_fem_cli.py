"""`pnet simulate` on the FEM scenes (issue 15): the tiny metal frames with every integrator,
mesh frames (PLY triangles + PNG), stats and steps with contact columns, resume, and errors
that name the file and the JSON path."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from test_pnet_cli import PNET, ROOT, TINY, frame_data, pnet, tiny_scene

sys.path.insert(0, str(ROOT / "python"))
from plasticitynet.frames import read_mesh_ply  # noqa: E402


def write(tmp_path: Path, scene: dict, name="scene.json") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(scene))
    return path


def csv_rows(path: Path) -> list[dict]:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    return [dict(zip(header, line.split(","))) for line in lines[1:]]


@pytest.mark.parametrize("integrator", ["plasticitynet", "lagged", "analytic", "explicit"])
@pytest.mark.parametrize("name", ["metal_frame_2d", "metal_nh_frame_2d"])
def test_every_integrator_runs_the_tiny_frames(tmp_path, name, integrator):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / f"{name}.json", "--integrator", integrator, "--out", out)
    if integrator == "analytic" and name == "metal_nh_frame_2d":
        assert r.returncode == 2
        assert "meshes[0].material: the analytic integrator needs StVK-Hencky elasticity" in r.stderr
        return
    assert r.returncode == 0, r.stderr
    assert "contact: no intersection at any frame" in r.stdout and "wrote 2 frames" in r.stdout
    run = json.loads((out / "run.json").read_text())
    assert run["integrator"] == integrator and run["elements"] > 100 and run["kappa"] > 0
    frames = [read_mesh_ply(out / f"frame_{f:05d}.ply") for f in range(3)]
    rest = frames[0]
    for frame in frames:
        assert frame.triangles.shape == (run["elements"], 3) and np.array_equal(frame.triangles, rest.triangles)
        assert frame.position.shape == (run["nodes"], 2)
    for f in range(3):
        assert (out / f"frame_{f:05d}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The plate (the second mesh) moved 0.05 m/s x 0.04 s down; nothing went below the ground.
    plate = slice(run["mesh_first_node"][1], run["mesh_first_node"][2])
    assert np.allclose(frames[2].position[plate, 1] - rest.position[plate, 1], -0.002, atol=1e-12)
    assert frames[2].position[:, 1].min() > 0
    stats = csv_rows(out / "stats.csv")
    assert [int(s["frame"]) for s in stats] == [1, 2]
    assert all(float(s["min_distance_m"]) > 0 and int(s["contact_pairs"]) > 0 for s in stats)
    steps = csv_rows(out / "steps.csv")
    assert {"kinematic_stages", "ccd_queries", "ccd_limited", "contact_pairs", "min_distance_m"} <= set(steps[0])
    if integrator != "explicit":
        assert len(steps) == 4 and all(s["converged"] == "1" for s in steps)
        assert sum(int(s["ccd_queries"]) for s in steps) > 0
        # From frame 2 on the plate presses the frame: CCD holds its first move back.
        assert int(steps[-1]["kinematic_stages"]) > 0 and steps[-1]["kinematic_reached"] == "1"
    if integrator == "plasticitynet":
        assert int(steps[-1]["fixed_point_iterations"]) > 1 and steps[-1]["fixed_point_converged"] == "1"


@pytest.mark.parametrize("integrator", ["plasticitynet", "lagged"])
def test_the_tiny_3d_frame_writes_surface_ply_vtu_and_png(tmp_path, integrator):
    out = tmp_path / "run3d"
    r = pnet("simulate", TINY / "metal_frame_3d.json", "--integrator", integrator, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "contact: no intersection at any frame" in r.stdout and "wrote 2 frames" in r.stdout
    run = json.loads((out / "run.json").read_text())
    assert run["dim"] == 3 and run["elements"] > 100
    frames = [read_mesh_ply(out / f"frame_{f:05d}.ply") for f in range(3)]
    for frame in frames:
        assert frame.dim == 3 and frame.position.shape == (run["nodes"], 3)
        assert frame.triangles.shape[1] == 3 and frame.triangles.max() < run["nodes"]
    plate = slice(run["mesh_first_node"][1], run["mesh_first_node"][2])
    assert np.allclose(frames[2].position[plate, 1] - frames[0].position[plate, 1], -0.002, atol=1e-12)
    assert frames[2].position[:, 1].min() > 0
    vtu = (out / "frame_00002.vtu").read_text()
    assert f'NumberOfPoints="{run["nodes"]}" NumberOfCells="{run["elements"]}"' in vtu
    assert (out / "frame_00002.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    steps = csv_rows(out / "steps.csv")
    assert len(steps) == 4 and all(s["converged"] == "1" for s in steps)
    assert all(float(s["broad_phase_s"]) >= 0 and float(s["ccd_s"]) >= 0 for s in steps)


def test_learned_and_exact_return_maps_differ_slightly(tmp_path):
    runs = {}
    for rm in ("learned", "exact"):
        out = tmp_path / rm
        # The tiny frame first yields in frame 6 (the plate 5 mm in); positions differ from frame 7.
        r = pnet("simulate", TINY / "metal_nh_frame_2d.json", "--return-map", rm, "--frames", 7, "--out", out)
        assert r.returncode == 0, r.stderr
        assert json.loads((out / "run.json").read_text())["solver"]["learned_return_map"] == (rm == "learned")
        runs[rm] = read_mesh_ply(out / "frame_00007.ply")
    assert runs["exact"].hardening.max() > 0.05  # elements yielded
    gap = np.linalg.norm(runs["learned"].position - runs["exact"].position, axis=1).max()
    assert 0 < gap < 1e-4  # the same physics; the network's dgamma is not the root-find's


def test_resume_continues_bit_identically(tmp_path):
    scene = TINY / "metal_frame_2d.json"
    full, part = tmp_path / "full", tmp_path / "part"
    assert pnet("simulate", scene, "--out", full, "--frames", 3).returncode == 0
    assert pnet("simulate", scene, "--out", part, "--frames", 1, "--checkpoint-every", 1).returncode == 0
    r = pnet("simulate", scene, "--out", part, "--frames", 3, "--resume")
    assert r.returncode == 0, r.stderr
    assert "resumed at frame 1" in r.stderr
    for f in range(4):
        assert frame_data(full / f"frame_{f:05d}.ply") == frame_data(part / f"frame_{f:05d}.ply")
    strip = lambda rows: [{k: v for k, v in row.items() if not k.endswith("_s") or k == "time_s"} for row in rows]
    assert strip(csv_rows(full / "stats.csv")) == strip(csv_rows(part / "stats.csv"))


def cantilever(integrator: str) -> dict:
    """A metal bar 10 x 1 cm clamped at its left end (the nodes at x = 0), sagging under gravity."""
    return {
        "dim": 2, "domain": {"min": [-0.01, -0.1], "max": [0.15, 0.1]}, "frame_dt": 0.01, "frames": 2,
        "integrator": {"name": integrator, "dt": 2e-3 if integrator != "explicit" else 2e-5},
        "meshes": [{"shape": "box", "min": [0.0, 0.05], "max": [0.1, 0.06], "element_size": 0.005,
                    "material": {"name": "metal", "density": 7800, "initial_hardening": 0.005,
                                 "elasticity": {"model": "stvk_hencky", "E": 1e7, "nu": 0.3},
                                 "plasticity": {"model": "von_mises", "hardening_coefficient": 0.1}},
                    "clamp": {"min": [-0.001, 0.04], "max": [1e-9, 0.07]}}],
    }


@pytest.mark.parametrize("integrator", ["return_map", "lagged", "explicit"])
def test_a_clamp_holds_its_nodes_at_rest_and_the_bar_sags(tmp_path, integrator):
    out = tmp_path / "run"
    r = pnet("simulate", write(tmp_path, cantilever(integrator)), "--out", out)
    assert r.returncode == 0, r.stderr
    rest, last = (read_mesh_ply(out / f"frame_{f:05d}.ply").position for f in (0, 2))
    root = rest[:, 0] <= 1e-9
    assert 2 <= root.sum() < len(rest) // 4
    assert np.array_equal(last[root], rest[root])  # held exactly
    tip = rest[:, 0] >= 0.1 - 1e-9
    sag = rest[tip, 1] - last[tip, 1]
    assert (sag > 1e-3).all(), sag  # the free end falls (a free bar: 4.9 mm in 0.02 s)
    beside = (rest[:, 0] > 1e-9) & (rest[:, 0] < 0.006)
    assert (np.abs(last[beside] - rest[beside]).max(axis=1) > 0).all()  # the next column is not held


@pytest.mark.parametrize("case", ["plate_through_frame", "no_material", "bad_element_size", "mesh_file_missing",
                                  "garbage_mesh_file", "no_model", "clamp_holds_no_node"])
def test_bad_fem_scenes_exit_2_naming_file_and_path(tmp_path, case):
    scene = tiny_scene("metal_frame_2d", "meshes")
    args = []
    if case == "plate_through_frame":
        scene["meshes"][1]["min"][1], scene["meshes"][1]["max"][1] = 0.1711, 0.1811
        expected = "meshes: the start state intersects or touches: "
    elif case == "no_material":
        del scene["meshes"][0]["material"]
        expected = "meshes[0].material: missing"
    elif case == "bad_element_size":
        scene["meshes"][0]["element_size"] = 0.5
        expected = "meshes[0]: element_size must be > 0 and at most the shape's size"
    elif case == "mesh_file_missing":
        scene["meshes"][0] = {"shape": "file", "file": "nope.msh", "material": "metal"}
        expected = "meshes[0].file: "
    elif case == "garbage_mesh_file":
        (tmp_path / "junk.msh").write_text("$MeshFormat\nthis is not a mesh\n")
        scene["meshes"][0] = {"shape": "file", "file": "junk.msh", "material": "metal"}
        expected = "meshes[0].file: "
    elif case == "clamp_holds_no_node":
        scene["meshes"][0]["clamp"] = [{"min": [0.0, 0.0], "max": [1.0, 0.01]},
                                       {"min": [0.0, 0.3], "max": [0.01, 0.4]}]
        expected = "meshes[0].clamp[1]: no node of the mesh lies in the box"
    else:
        del scene["meshes"][0]["model"]
        args = ["--integrator", "plasticitynet"]
        expected = "meshes[0].model"
    path = write(tmp_path, scene)
    r = pnet("simulate", path, "--out", tmp_path / "out", *args)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert f"{path}: " in r.stderr and expected in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and "terminate" not in r.stderr


@pytest.mark.parametrize("integrator", ["plasticitynet", "lagged", "explicit"])
def test_the_tiny_coupling_writes_particles_mesh_and_png_without_penetration(tmp_path, integrator):
    """MPM-FEM coupling (issue 18): the stiff disk falls onto the sand bed; every frame has the
    particles (frame_N.ply), the mesh (frame_N_mesh.ply) and one picture, and no particle ends a
    frame inside the disk (the run fails otherwise)."""
    out = tmp_path / "run"
    extra = ["--dt", "1e-5", "--frames", "2"] if integrator == "explicit" else []
    r = pnet("simulate", TINY / "sand_fem_coupling_2d.json", "--integrator", integrator, "--out", out, *extra)
    assert r.returncode == 0, r.stderr
    assert "contact: no intersection at any frame" in r.stdout
    run = json.loads((out / "run.json").read_text())
    assert run["particles"] > 300 and run["nodes"] > 50 and run["particle_dhat"] == pytest.approx(run["dx"] / 2)
    frames = 2
    for f in range(frames + 1):
        mesh = read_mesh_ply(out / f"frame_{f:05d}_mesh.ply")
        assert mesh.position.shape == (run["nodes"], 2)
        assert (out / f"frame_{f:05d}.ply").exists()
        assert (out / f"frame_{f:05d}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = csv_rows(out / "stats.csv")
    assert len(rows) == frames
    if integrator != "explicit":
        # The disk lands on the bed in the first frame: pairs within dhat, and it is slowed down.
        assert max(int(row["contact_pairs"]) for row in rows) > 0
        start = read_mesh_ply(out / "frame_00000_mesh.ply").position
        end = read_mesh_ply(out / f"frame_{frames:05d}_mesh.ply").position
        assert end[:, 1].min() > 0.03 and end[:, 1].mean() < start[:, 1].mean()


def test_the_python_module_runs_the_tiny_coupling():
    import plasticitynet_sim as pns

    sim = pns.Simulation(str(TINY / "sand_fem_coupling_2d.json"), integrator="lagged")
    assert sim.is_fem and sim.is_coupled and sim.num_particles > 300
    nodes0 = sim.nodes.copy()
    frames = sim.advance(2)
    assert [f["frame"] for f in frames] == [1, 2]
    contact = sim.contact
    assert contact["penetrations"] == 0 and contact["dhat"] == pytest.approx(sim.scene.dx / 2)
    assert max(f["contact_pairs"] for f in frames) > 0
    assert sim.positions.shape == (sim.num_particles, 2) and sim.nodes.shape == nodes0.shape
    assert sim.nodes[:, 1].mean() < nodes0[:, 1].mean()
    assert sim.grid_mass().sum() == pytest.approx(sim.mass.sum(), rel=1e-9)


def test_the_tiny_3d_coupling_runs_from_the_command_line_and_python_without_penetration(tmp_path):
    """MPM-FEM coupling in 3D (issue 33): the stiff sphere lands on the sand bed (learned sand_3d
    energy, friction 0.3); the CLI writes the particles, the surface and one picture per frame, and
    the Python module gives the same run's arrays."""
    import plasticitynet_sim as pns

    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_fem_coupling_3d.json", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "contact: no intersection at any frame" in r.stdout
    run = json.loads((out / "run.json").read_text())
    rows = csv_rows(out / "stats.csv")
    assert len(rows) == 2 and max(int(row["contact_pairs"]) for row in rows) > 0
    for f in range(3):
        assert read_mesh_ply(out / f"frame_{f:05d}_mesh.ply").position.shape == (run["nodes"], 3)
        assert (out / f"frame_{f:05d}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    sim = pns.Simulation(str(TINY / "sand_fem_coupling_3d.json"))
    assert sim.is_coupled and sim.dim == 3 and sim.boundary_faces.shape[1] == 3
    nodes0 = sim.nodes.copy()
    frames = sim.advance(2)
    assert sim.contact["penetrations"] == 0 and max(f["contact_pairs"] for f in frames) > 0
    assert sim.nodes[:, 1].mean() < nodes0[:, 1].mean()
    # The same run as the command line's (same scene, same settings, deterministic).
    assert np.array_equal(sim.nodes, read_mesh_ply(out / "frame_00002_mesh.ply").position)
