"""`pnet simulate` end to end, as a user runs it: outputs, exit codes and messages for malformed
scenes, checkpoint/resume, blow-ups. Runs the C++ binary built by scripts/setup.sh (the build
folder is $PNET_BUILD_DIR, default build/)."""

from __future__ import annotations

import copy
import csv
import json
import os
import re
import struct
import subprocess
import zlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PNET = ROOT / os.environ.get("PNET_BUILD_DIR", "build") / "cpp" / "pnet"
TINY = ROOT / "scenes" / "tiny"


def pnet(*args, timeout=300) -> subprocess.CompletedProcess:
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    return subprocess.run([str(PNET), *map(str, args)], capture_output=True, text=True, timeout=timeout)


def tiny_scene(name: str, parts: str = "objects") -> dict:
    """A tiny scene as a dict, the model paths of its `parts` ("objects" or "meshes") made absolute,
    so that the scene can be written anywhere (dicts resolve them against the working directory)."""
    scene = json.loads((TINY / f"{name}.json").read_text())
    for part in scene[parts]:
        if "model" in part:
            part["model"] = str((TINY / part["model"]).resolve())
    return scene


def frame_data(path: Path) -> bytes:
    """A frame file's bytes without the id of the run that wrote it (two runs differ there)."""
    return re.sub(rb"comment run_id \w+\n", b"", path.read_bytes())


def write_scene(tmp_path: Path, scene: dict, name="scene.json") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(scene, indent=1))
    return path


@pytest.mark.parametrize("name", ["sand_column_2d", "snowball_2d", "sand_column_3d", "snowball_3d"])
def test_tiny_scene_writes_frames_stats_and_run_json(tmp_path, name):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / f"{name}.json", "--integrator", "explicit", "--frames", 2, "--out", out)
    assert r.returncode == 0, r.stderr
    assert f"wrote 2 frames" in r.stdout and str(out) in r.stdout
    assert "frame 2/2" in r.stderr and "ETA" in r.stderr  # the progress line
    for frame in range(3):
        ply = (out / f"frame_{frame:05d}.ply").read_bytes()
        assert ply.startswith(b"ply\nformat binary_little_endian 1.0\n")
        assert (out / f"frame_{frame:05d}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (out / "stats.csv").read_text().splitlines()
    assert rows[0].startswith("frame,time_s,steps,dt_min_s,dt_max_s,wall_s,clamped,kinetic_J,potential_J,momentum_x")
    assert [int(r.split(",")[0]) for r in rows[1:]] == [1, 2]
    run = json.loads((out / "run.json").read_text())
    assert run["integrator"] == "explicit" and run["frames"] == 2 and run["dim"] == int(name[-2])
    assert not list(out.glob("*.tmp")), "temporary files left behind"


def test_resume_continues_bit_identically(tmp_path):
    scene = TINY / "snowball_2d.json"
    full, part = tmp_path / "full", tmp_path / "part"
    assert pnet("simulate", scene, "--integrator", "explicit", "--frames", 4, "--out", full).returncode == 0
    r = pnet("simulate", scene, "--integrator", "explicit", "--frames", 2, "--checkpoint-every", 1, "--out", part)
    assert r.returncode == 0, r.stderr
    r = pnet("simulate", scene, "--integrator", "explicit", "--frames", 4, "--resume", "--out", part)
    assert r.returncode == 0, r.stderr
    assert "resumed at frame 2" in r.stderr
    for frame in (3, 4):
        assert frame_data(full / f"frame_{frame:05d}.ply") == frame_data(part / f"frame_{frame:05d}.ply")
    # stats.csv continues from the checkpoint: one row per frame, the same simulated quantities.
    strip_wall = lambda rows: [",".join(c for i, c in enumerate(r.split(",")) if i != 5) for r in rows]
    assert strip_wall((full / "stats.csv").read_text().splitlines()) == \
        strip_wall((part / "stats.csv").read_text().splitlines())


def test_resume_without_checkpoint_is_an_input_error(tmp_path):
    r = pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--resume", "--out", tmp_path)
    assert r.returncode == 2
    assert "checkpoint.bin: no checkpoint to resume from" in r.stderr


def test_resume_refuses_a_checkpoint_of_another_scene(tmp_path):
    out = tmp_path / "run"
    assert pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--frames", 1,
                "--checkpoint-every", 1, "--out", out).returncode == 0
    scene = tiny_scene("sand_column_2d")
    scene["gravity"] = [0, -5.0]
    r = pnet("simulate", write_scene(tmp_path, scene), "--integrator", "explicit", "--frames", 2, "--resume",
             "--out", out)
    assert r.returncode == 2
    assert "written for a different scene" in r.stderr


def _frame_run_ids(out: Path) -> dict[str, str]:
    """frame file -> the run id it carries (PLY `comment run_id`, PNG tEXt `pnet_run_id`; "" if none)."""
    ids = {}
    for path in sorted(out.glob("frame_*.ply")):
        header = path.read_bytes().split(b"end_header")[0].decode()
        m = re.search(r"^comment run_id (\S+)$", header, re.M)
        ids[path.name] = m.group(1) if m else ""
    for path in sorted(out.glob("frame_*.png")):
        ids[path.name] = png_text(path.read_bytes()).get("pnet_run_id", "")
    return ids


def png_text(data: bytes) -> dict[str, str]:
    """The tEXt chunks of a PNG, read chunk by chunk (length, type, data, CRC), so that a CRC byte
    that happens to be printable is never taken as part of the text."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    text, at = {}, 8
    while at + 8 <= len(data):
        length, kind = struct.unpack(">I", data[at:at + 4])[0], data[at + 4:at + 8]
        body = data[at + 8:at + 8 + length]
        if kind == b"tEXt":
            key, _, value = body.partition(b"\x00")
            text[key.decode("latin-1")] = value.decode("latin-1")
        if kind == b"IEND":
            break
        at += 12 + length
    return text


def test_png_text_stops_at_the_chunk_end():
    """A tEXt chunk whose CRC begins with an ASCII hex digit (run id 0...06 gives CRC byte '9'):
    a pattern match would read the digit as part of the id; the chunk reader must not."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    run_id = "0000000000000006"
    text_chunk = chunk(b"tEXt", b"pnet_run_id\x00" + run_id.encode())
    assert text_chunk[-4:-3] in b"0123456789abcdef"
    png = b"\x89PNG\r\n\x1a\n" + text_chunk + chunk(b"IEND", b"")
    assert png_text(png) == {"pnet_run_id": run_id}


def test_a_run_never_mixes_with_another(tmp_path):
    """4 frames, then 2 frames into the same folder: refused, and nothing of the first run is touched;
    with --overwrite the first run's files are removed first (only those), so the folder holds one run."""
    scene, out = TINY / "sand_column_2d.json", tmp_path / "run"
    assert pnet("simulate", scene, "--integrator", "explicit", "--frames", 4, "--out", out).returncode == 0
    first = json.loads((out / "run.json").read_text())["run_id"]
    assert set(_frame_run_ids(out).values()) == {first} and len(_frame_run_ids(out)) == 10
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    (out / "notes.txt").write_text("mine")

    r = pnet("simulate", scene, "--integrator", "explicit", "--frames", 2, "--out", out)
    assert r.returncode == 2
    assert f"{out}: holds another run" in r.stderr and '"sand_column_2d_tiny"' in r.stderr, r.stderr
    assert "4 frames" in r.stderr and "--overwrite" in r.stderr and "--resume" in r.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "notes.txt"} == before

    r = pnet("simulate", scene, "--integrator", "explicit", "--frames", 2, "--overwrite", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "--overwrite: removed" in r.stderr
    run = json.loads((out / "run.json").read_text())
    assert run["frames"] == 2 and run["run_id"] != first
    ids = _frame_run_ids(out)
    assert sorted(ids) == sorted(f"frame_{f:05d}.{e}" for f in range(3) for e in ("ply", "png"))
    assert set(ids.values()) == {run["run_id"]}
    assert [int(r.split(",")[0]) for r in (out / "stats.csv").read_text().splitlines()[1:]] == [1, 2]
    assert (out / "notes.txt").read_text() == "mine"
    r = pnet("video", out)
    assert r.returncode == 0 and "3 frames" in r.stdout, r.stderr

    r = pnet("simulate", scene, "--integrator", "explicit", "--resume", "--overwrite", "--out", out)
    assert r.returncode == 2 and "give one" in r.stderr


def test_video_and_compare_refuse_frames_of_another_run(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--frames", 2,
                    "--out", out).returncode == 0
    for ext in ("png", "ply"):  # a frame of run a slipped into run b
        (b / f"frame_00002.{ext}").write_bytes((a / f"frame_00002.{ext}").read_bytes())
    run_a = json.loads((a / "run.json").read_text())["run_id"]

    r = pnet("video", b)
    assert r.returncode == 2, r.stderr
    assert f"{b / 'frame_00002.png'}: not written by the run in {b / 'run.json'}" in r.stderr and run_a in r.stderr
    assert not (b / "video.mp4").exists()
    r = pnet("compare", a, b)
    assert r.returncode == 2, r.stderr
    assert f"{b / 'frame_00002.ply'}: not written by the run in" in r.stderr
    assert not (b / "compare_a").exists()


def test_resume_keeps_the_run_id_and_drops_later_frames(tmp_path):
    scene, out = TINY / "sand_column_2d.json", tmp_path / "run"
    assert pnet("simulate", scene, "--integrator", "explicit", "--frames", 1, "--checkpoint-every", 1,
                "--out", out).returncode == 0
    run_id = json.loads((out / "run.json").read_text())["run_id"]
    (out / "frame_00007.ply").write_bytes((out / "frame_00001.ply").read_bytes())  # left by a longer attempt
    r = pnet("simulate", scene, "--integrator", "explicit", "--frames", 2, "--resume", "--out", out)
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "run.json").read_text())["run_id"] == run_id
    ids = _frame_run_ids(out)
    assert sorted(ids) == sorted(f"frame_{f:05d}.{e}" for f in range(3) for e in ("ply", "png"))
    assert set(ids.values()) == {run_id}


def _malformed(scene: dict, case: str) -> tuple[dict, str]:
    """A copy of `scene` broken in one way, and the message `pnet` must print."""
    s = copy.deepcopy(scene)
    if case == "missing key":
        del s["dx"]
        return s, "dx: missing"
    if case == "wrong type":
        s["frames"] = "fifty"
        return s, "frames: expected an integer >= 1"
    if case == "unknown material":
        s["objects"][0]["material"]["plasticity"]["model"] = "butter"
        return s, "objects[0].material.plasticity.model: unknown plasticity model 'butter'"
    if case == "negative dx":
        s["dx"] = -0.03125
        return s, "dx: expected a positive number"
    if case == "object outside the domain":
        s["objects"][0]["max"] = [1.5, 0.3]
        return s, "objects[0]: extends outside the domain"
    if case == "model of the wrong dimension":
        s["objects"][0]["model"] = str(ROOT / "models" / "sand_3d.pt")
        return s, "objects[0].model: "
    raise ValueError(case)


@pytest.mark.parametrize("case", ["missing key", "wrong type", "unknown material", "negative dx",
                                  "object outside the domain", "model of the wrong dimension"])
def test_malformed_scene_exits_2_naming_file_and_path(tmp_path, case):
    scene, expected = _malformed(tiny_scene("sand_column_2d"), case)
    path = write_scene(tmp_path, scene, "broken.json")
    out = tmp_path / "run"
    # Only an integrator that reads models opens them (docs/integrators.md).
    integrator = "plasticitynet" if case == "model of the wrong dimension" else "explicit"
    r = pnet("simulate", path, "--integrator", integrator, "--out", out)
    assert r.returncode == 2, (case, r.stderr)
    assert r.stderr.startswith(f"pnet simulate: {path}: "), r.stderr
    assert expected in r.stderr, r.stderr
    assert not out.exists() or not list(out.glob("frame_*")), "nothing is simulated for a bad scene"


def test_wrong_dimension_model_message_says_what_was_expected(tmp_path):
    scene, _ = _malformed(tiny_scene("sand_column_2d"), "model of the wrong dimension")
    r = pnet("simulate", write_scene(tmp_path, scene), "--integrator", "plasticitynet", "--out", tmp_path / "o")
    assert r.returncode == 2
    assert "sand_3d.pt: a 3D model where a 2D one is needed" in r.stderr


def test_parametric_model_runs_a_scene_of_its_family_and_refuses_a_value_outside_its_range(tmp_path):
    """One parametric model (models/sand_param_2d.pt) for a 40 deg sand scene through --model; at 50 deg it
    exits 2 naming the object, the field and the range, and writes no frame."""
    scene = tiny_scene("sand_column_2d")
    scene["objects"][0]["material"]["plasticity"]["friction_angle_deg"] = 40
    model = ROOT / "models" / "sand_param_2d.pt"
    r = pnet("simulate", write_scene(tmp_path, scene, "s40.json"), "--integrator", "plasticitynet", "--frames", 2,
             "--model", model, "--out", tmp_path / "s40")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "s40" / "frame_00002.ply").exists()
    scene["objects"][0]["material"]["plasticity"]["friction_angle_deg"] = 50
    path = write_scene(tmp_path, scene, "s50.json")
    r = pnet("simulate", path, "--integrator", "plasticitynet", "--frames", 2, "--model", model, "--out", tmp_path / "s50")
    assert r.returncode == 2, r.stderr
    assert f"objects[0].model: {model}: material.plasticity.friction_angle_deg = 50.0 is outside the range " \
           "[20.0, 45.0] this parametric model was trained for" in r.stderr, r.stderr
    assert not list((tmp_path / "s50").glob("frame_*"))


def test_an_uncapped_implicit_mpm_blow_up_names_the_advection_limit(tmp_path):
    # scenes/elastic_ball_2d.json thrown at 16 m/s and stepped at 1e-2 s with the advection limit off: the
    # ball crosses 20 cells a step, its impact's Newton solves stop at the iteration cap and the run blows
    # up. The error names the cure (docs/solver.md, "The advection limit"); the same run with the limit on
    # by default completes. (At the scene's own 2 m/s, 2.6 cells a step, whether the unconverged run
    # blows up or limps on turned on round-off: it did until 2026-11-30 and did not after the grid's sums
    # changed order; at 12-24 m/s every build measured blew up.)
    scene = json.loads((ROOT / "scenes" / "elastic_ball_2d.json").read_text())
    scene["objects"][0]["velocity"] = [0, -16]
    path = write_scene(tmp_path, scene, "thrown_ball.json")
    r = pnet("simulate", path, "--integrator", "lagged", "--dt", 0.01, "--advection-cfl", 0,
             "--out", tmp_path / "uncapped")
    assert r.returncode == 1, r.stderr
    assert "blew up" in r.stderr and "--advection-cfl" in r.stderr and "integrator.advection_cfl" in r.stderr
    assert "advection limit off" in r.stderr
    r = pnet("simulate", path, "--integrator", "lagged", "--dt", 0.01, "--out", tmp_path / "default")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "default" / "frame_00040.ply").exists()


def test_missing_scene_file_and_usage_errors(tmp_path):
    r = pnet("simulate", tmp_path / "nope.json", "--out", tmp_path / "o")
    assert r.returncode == 2 and "nope.json" in r.stderr
    r = pnet("simulate", TINY / "sand_column_2d.json")
    assert r.returncode == 2 and "--out DIR is required" in r.stderr
    r = pnet("simulate", TINY / "sand_column_2d.json", "--out", tmp_path / "o", "--frames", 0)
    assert r.returncode == 2 and "--frames" in r.stderr
    r = pnet("simulate", TINY / "sand_column_2d.json", "--out", tmp_path / "o", "--integrator", "magic")
    assert r.returncode == 2 and "magic" in r.stderr


def test_blow_up_stops_with_step_and_particle_keeping_written_frames(tmp_path):
    # dt far above the CFL step (~1e-3 s at dx = 1/32): the run must stop with a message naming
    # the step and the particle, exit 1, and leave the frames already written intact.
    scene = tiny_scene("snowball_2d")
    scene["objects"][0]["velocity"] = [0, -30]
    out = tmp_path / "run"
    r = pnet("simulate", write_scene(tmp_path, scene), "--integrator", "explicit", "--dt", 0.01, "--frames", 6,
             "--out", out)
    assert r.returncode == 1, r.stderr
    assert "error: step " in r.stderr and "particle " in r.stderr and "blew up" in r.stderr
    frames = sorted(out.glob("frame_*.ply"))
    assert frames and frames[0].name == "frame_00000.ply"
    for ply in frames:
        assert ply.read_bytes().startswith(b"ply\n")
    last = int(frames[-1].stem.split("_")[1])
    rows = (out / "stats.csv").read_text().splitlines()[1:]
    assert len(rows) == last, "stats.csv has one row per completed frame"
    assert not list(out.glob("*.tmp"))


# The implicit integrators with the shipped models.

@pytest.mark.parametrize("integrator", ["plasticitynet", "return_map", "lagged"])
@pytest.mark.parametrize("name", ["sand_column_2d", "snowball_2d", "sand_column_3d", "snowball_3d"])
def test_implicit_integrators_run_every_tiny_scene(tmp_path, name, integrator):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / f"{name}.json", "--integrator", integrator, "--frames", 2, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "Newton" in r.stderr and "CG" in r.stderr  # the implicit progress line
    run = json.loads((out / "run.json").read_text())
    assert run["integrator"] == integrator and run["dt"] == 1e-3
    assert run["solver"]["max_fixed_point_iterations"] >= 1 and run["solver"]["regularizer_weight"] == "auto"
    frames = (out / "stats.csv").read_text().splitlines()
    assert frames[0].endswith(",newton_iterations,cg_iterations,line_search_steps,fixed_point_iterations,"
                              "network_evaluations,network_points,max_residual_m_per_s,converged,unconverged_steps,"
                              "hardening_clamped,advection_capped_steps,floor_friction_retried_steps,"
                              "prediction_rejected_steps")
    frame_rows = [dict(zip(frames[0].split(","), row.split(","))) for row in frames[1:]]
    assert len(frames) == 3 and all(r["converged"] == "1" and r["unconverged_steps"] == "0" for r in frame_rows), \
        "every solve converged"
    assert "all 40 steps converged" in r.stdout
    steps = (out / "steps.csv").read_text().splitlines()
    header = steps[0].split(",")
    assert len(steps) == 1 + 40, "one row per step: 2 frames of 20 steps at dt 1e-3"
    rows = [dict(zip(header, line.split(","))) for line in steps[1:]]
    assert [int(r["step"]) for r in rows] == list(range(40))
    assert abs(float(rows[-1]["time_s"]) - 0.04) < 1e-12
    if name.startswith("sand"):  # the snowball falls freely for 2 frames: v* is already the minimizer
        assert sum(int(r["newton_iterations"]) for r in rows) > 0
    fixed_point = {int(r["fixed_point_iterations"]) for r in rows}
    assert fixed_point <= set(range(1, 9)) and (integrator == "plasticitynet" or fixed_point == {1})
    assert all(float(r["residual_m_per_s"]) <= 1e-3 for r in rows)


def test_implicit_options_override_the_scene(tmp_path):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_column_2d.json", "--frames", 1, "--fixed-point-iterations", 1,
             "--regularizer", 0, "--newton-tol", 1e-4, "--dt", 2e-3, "--preconditioner", "block_jacobi", "--lazy-hessian", 0,
             "--tangent-damping", 0.1, "--out", out)
    assert r.returncode == 0, r.stderr
    run = json.loads((out / "run.json").read_text())
    assert run["integrator"] == "plasticitynet" and run["dt"] == 2e-3
    assert run["solver"]["tangent_damping"] == 0.1
    assert run["solver"]["max_fixed_point_iterations"] == 1 and run["solver"]["regularizer_weight"] == 0
    assert run["solver"]["newton_tolerance"] == 1e-4 and run["solver"]["preconditioner"] == "block_jacobi"
    assert run["solver"]["lazy_hessian"] == 0
    lines = (out / "steps.csv").read_text().splitlines()
    solves = lines[0].split(",").index("fixed_point_iterations")
    assert len(lines) == 11 and all(line.split(",")[solves] == "1" for line in lines[1:])


def test_advection_limit_cuts_the_steps_of_a_fast_scene(tmp_path):
    """--advection-cfl C: a step of 0.02 s would carry the tiny snowball (3 m/s) over several cells;
    capped, the frame takes several steps, none longer than C dx / max |v|; the run records C, and
    steps.csv and stats.csv say which steps the limit cut. 0 turns it off; 0.2 is the default."""
    runs = {}
    for name, extra in (("whole", ["--advection-cfl", 0]), ("capped", ["--advection-cfl", 0.25]), ("default", [])):
        out = tmp_path / name
        r = pnet("simulate", TINY / "snowball_2d.json", "--integrator", "lagged", "--dt", 0.02, "--frames", 1,
                 "--out", out, *extra)
        assert r.returncode == 0, r.stderr
        runs[name] = (json.loads((out / "run.json").read_text()), list(csv.DictReader(open(out / "stats.csv"))))
    (whole_run, whole), (capped_run, capped) = runs["whole"], runs["capped"]
    assert whole_run["solver"]["advection_cfl"] == 0 and capped_run["solver"]["advection_cfl"] == 0.25
    assert runs["default"][0]["solver"]["advection_cfl"] == 0.2
    assert int(runs["default"][1][0]["steps"]) > 1 and int(runs["default"][1][0]["advection_capped_steps"]) > 0
    assert int(whole[0]["advection_capped_steps"]) == 0
    steps = list(csv.DictReader(open(tmp_path / "capped" / "steps.csv")))
    assert sum(int(s["advection_capped"]) for s in steps) == int(capped[0]["advection_capped_steps"]) >= len(steps) - 1
    assert int(whole[0]["steps"]) == 1 and float(whole[0]["dt_max_s"]) == 0.02
    dx = json.loads((TINY / "snowball_2d.json").read_text())["dx"]
    assert int(capped[0]["steps"]) > 1
    # 3 m/s: the fastest at the start; stats.csv holds 6 significant digits
    assert float(capped[0]["dt_max_s"]) <= 0.25 * dx / 3.0 * (1 + 1e-5)


@pytest.mark.parametrize("args, expected", [
    (["--advection-cfl", 2], '--advection-cfl: expected a number in [0, 1], got "2"'),
    (["--fixed-point-iterations", 0], '--fixed-point-iterations: expected an integer >= 1, got "0"'),
    (["--cg-tol", 1.5], '--cg-tol: expected a number in (0, 1), got "1.5"'),
    (["--regularizer", -1], '--regularizer: expected a number >= 0 or auto, got "-1"'),
    (["--tangent-damping", -1], '--tangent-damping: expected a number >= 0, got "-1"'),
    (["--integrator", "implicit"], '--integrator: unknown integrator "implicit" (expected explicit, plasticitynet, '
                                   'return_map, lagged or analytic)'),
    (["--preconditioner", "ilu"], '--preconditioner: expected jacobi, block_jacobi, ichol or multigrid, got "ilu"'),
    (["--lazy-hessian", 1], '--lazy-hessian: expected a number in [0, 1) or auto, got "1"'),
    (["--dt", -1], "--dt must be a number >= 0"),
    (["--dt", "nan"], "--dt must be a number >= 0"),
    (["--cfl", 0], "--cfl must be a number > 0"),
    (["--outer-iteration", "anderson"], '--outer-iteration: expected auto, newton or fixed_point, got "anderson"'),
    (["--hessian", "exact"], '--hessian: expected auto, network or tangent, got "exact"'),
    (["--analytic-regularizer", -1], '--analytic-regularizer: expected a number >= 0, got "-1"'),
    (["--kinematic-start", "warm"], '--kinematic-start: expected scaled or last_velocity, got "warm"'),
    (["--time-integrator", "euler"], '--time-integrator: expected backward_euler or bdf2, got "euler"'),
    (["--flip-relaxation-time", -1], "--flip-relaxation-time must be a finite number >= 0"),
    (["--floor-friction", -0.5], "--floor-friction must be a finite number >= 0"),
])
def test_implicit_usage_errors(tmp_path, args, expected):
    r = pnet("simulate", TINY / "sand_column_2d.json", "--out", tmp_path / "o", *args)
    assert r.returncode == 2 and expected in r.stderr, r.stderr


def test_transfer_and_floor_overrides_reach_the_run(tmp_path):
    """--flip-relaxation-time and --floor-friction override the scene's transfer and floor: the run differs
    from the scene's own, its checkpoint belongs to the overridden scene (a resume without them is refused,
    naming the checkpoint), and a scene without particles refuses them."""
    out, plain = tmp_path / "o", tmp_path / "plain"
    base = ["simulate", TINY / "sand_column_2d.json", "--frames", 1, "--checkpoint-every", 1]
    overrides = ["--flip-relaxation-time", 0.01, "--floor-friction", 0.5]
    assert pnet(*base, "--out", out, *overrides).returncode == 0
    assert pnet(*base, "--out", plain).returncode == 0
    assert (out / "frame_00001.ply").read_bytes() != (plain / "frame_00001.ply").read_bytes()
    r = pnet("simulate", TINY / "sand_column_2d.json", "--frames", 2, "--out", out, "--resume")
    assert r.returncode != 0 and "checkpoint.bin: written for a different scene" in r.stderr, r.stderr
    r = pnet("simulate", TINY / "sand_column_2d.json", "--frames", 2, "--out", out, "--resume", *overrides)
    assert r.returncode == 0 and (out / "frame_00002.ply").exists(), r.stderr
    r = pnet("simulate", TINY / "metal_frame_2d.json", "--out", tmp_path / "m", "--floor-friction", 0.5)
    assert r.returncode == 2 and "--floor-friction: " in r.stderr and "has no particles" in r.stderr, r.stderr


def test_plasticitynet_without_a_model_names_the_object(tmp_path):
    scene = tiny_scene("sand_column_2d")
    del scene["objects"][0]["model"]
    path = write_scene(tmp_path, scene)
    r = pnet("simulate", path, "--integrator", "plasticitynet", "--out", tmp_path / "o")
    assert r.returncode == 2
    assert f"{path}: objects[0].model: the plasticitynet integrator needs an energy model" in r.stderr
    # lagged needs no model
    assert pnet("simulate", path, "--integrator", "lagged", "--frames", 1, "--out", tmp_path / "l").returncode == 0


def test_bad_solver_option_in_the_scene_names_the_key(tmp_path):
    scene = tiny_scene("sand_column_2d")
    scene["integrator"]["max_fixed_point_iterations"] = 0
    path = write_scene(tmp_path, scene)
    r = pnet("simulate", path, "--out", tmp_path / "o")
    assert r.returncode == 2
    assert f"{path}: integrator.max_fixed_point_iterations: expected an integer >= 1, got 0" in r.stderr


def test_unconverged_steps_are_counted_reported_and_can_fail_the_run(tmp_path):
    # One Newton iteration per solve against a tolerance no iteration reaches: every step ends
    # unconverged. The run goes on, marks the steps, and says so at the end; --fail-on-unconverged
    # stops at the first such step instead, keeping the frames already written.
    scene = tiny_scene("sand_column_2d")
    scene["integrator"].update({"max_newton_iterations": 1, "newton_tolerance": 1e-9})
    path = write_scene(tmp_path, scene)
    out = tmp_path / "run"
    r = pnet("simulate", path, "--frames", 1, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "warning: 20 of 20 steps ended with the Newton solve unconverged" in r.stdout, r.stdout
    stats = (out / "stats.csv").read_text().splitlines()
    row = dict(zip(stats[0].split(","), stats[1].split(",")))
    assert row["converged"] == "0" and row["unconverged_steps"] == "20"
    steps = (out / "steps.csv").read_text().splitlines()
    assert all(dict(zip(steps[0].split(","), line.split(",")))["converged"] == "0" for line in steps[1:])
    # The learned step's unconverged steps point to the classical solver of the same step; its own do not.
    assert "--integrator return_map solves the same step" in r.stdout, r.stdout
    r = pnet("simulate", path, "--frames", 1, "--integrator", "return_map", "--out", tmp_path / "classical")
    assert r.returncode == 0 and "warning: 20 of 20 steps ended" in r.stdout, r.stdout + r.stderr
    assert "--integrator return_map" not in r.stdout, r.stdout

    # A fixed point on F0 (the paper's outer iteration) stopped by its cap is reported too.
    r = pnet("simulate", TINY / "sand_column_2d.json", "--frames", 1, "--outer-iteration", "fixed_point",
             "--fixed-point-iterations", 1, "--fixed-point-tol", 0, "--out", tmp_path / "capped")
    assert r.returncode == 0, r.stderr
    steps = (tmp_path / "capped" / "steps.csv").read_text().splitlines()
    capped = sum(dict(zip(steps[0].split(","), line.split(",")))["fixed_point_converged"] == "0" for line in steps[1:])
    assert capped > 10, "a change of exactly 0 (the column at rest) is the only way to meet tolerance 0"
    assert f"note: in {capped} of 20 steps the fixed point on F0 stopped above its tolerance" in r.stdout, r.stdout

    r = pnet("simulate", path, "--frames", 1, "--fail-on-unconverged", "--out", tmp_path / "strict")
    assert r.returncode == 1
    assert "error: step 0" in r.stderr and "did not converge" in r.stderr, r.stderr
    assert (tmp_path / "strict" / "frame_00000.ply").exists()


def test_a_model_trained_for_other_plasticity_parameters_is_refused(tmp_path):
    # sand_2d.pt was trained for a 30 deg friction angle: a 35 deg scene would mix both.
    scene = tiny_scene("sand_column_2d")
    scene["objects"][0]["material"]["plasticity"]["friction_angle_deg"] = 35
    path = write_scene(tmp_path, scene)
    r = pnet("simulate", path, "--frames", 1, "--out", tmp_path / "o")
    assert r.returncode == 2
    assert f"{path}: objects[0].model: " in r.stderr
    assert "sand_2d.pt was trained for material.plasticity.friction_angle_deg = 30" in r.stderr
    assert "the object's material has 35" in r.stderr, r.stderr
    # lagged uses no model: the same scene runs.
    assert pnet("simulate", path, "--integrator", "lagged", "--frames", 1, "--out", tmp_path / "l").returncode == 0


def _video_frames(path: Path) -> int:
    """Frames in an MP4 as ffprobe counts them by decoding."""
    r = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
                        "stream=nb_read_frames,codec_name,pix_fmt", "-of", "json", str(path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    stream = json.loads(r.stdout)["streams"][0]
    assert stream["codec_name"] == "h264" and stream["pix_fmt"] == "yuv420p"
    return int(stream["nb_read_frames"])


def test_video_encodes_every_frame_and_refuses_gaps(tmp_path):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--frames", 4, "--out", out)
    assert r.returncode == 0, r.stderr
    r = pnet("video", out)
    assert r.returncode == 0, r.stderr
    assert "5 frames" in r.stdout and "50 frames per second" in r.stdout  # frame_dt 0.02 s: real time
    assert _video_frames(out / "video.mp4") == 5
    assert not list(out.glob("*.tmp.mp4"))

    (out / "frame_00002.png").unlink()
    r = pnet("video", out, "--out", tmp_path / "gap.mp4")
    assert r.returncode == 2 and "frame 2.png is missing" in r.stderr
    assert not (tmp_path / "gap.mp4").exists()


@pytest.mark.parametrize("args, expected", [
    (["--fps", "0"], "--fps: expected a frame rate in (0, 1000]"),
    (["--fps", "nan"], "--fps: expected a frame rate"),
    (["--bogus"], "unknown option --bogus"),
    ([], "no frame_NNNNN.png images"),
])
def test_video_usage_errors(tmp_path, args, expected):
    r = pnet("video", tmp_path, *args)
    assert r.returncode == 2 and expected in r.stderr, r.stderr


@pytest.mark.parametrize("command", ["video", "compare", "simulate"])
def test_every_command_prints_its_usage_on_help(command):
    """`pnet COMMAND --help` (and -h), as pnet's own usage tells a newcomer to type: the usage on stdout,
    exit 0, no error."""
    for flag in ("--help", "-h"):
        r = pnet(command, flag)
        assert r.returncode == 0 and r.stdout.startswith(f"usage: pnet {command}"), (r.returncode, r.stdout, r.stderr)
        assert "unknown option" not in r.stderr


def test_video_without_ffmpeg_says_how_to_get_it(tmp_path):
    out = tmp_path / "run"
    assert pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--frames", 1,
                "--out", out).returncode == 0
    (out / "video.mp4").write_bytes(b"an earlier video")
    r = subprocess.run([str(PNET), "video", str(out)], capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PATH": str(tmp_path / "empty")})
    assert r.returncode == 1 and "cannot run ffmpeg" in r.stderr and "apt-get install ffmpeg" in r.stderr
    assert (out / "video.mp4").read_bytes() == b"an earlier video", "a failed encode must not touch the old video"


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


@pytest.mark.parametrize("name, panels", [("sand_column_2d", 3), ("sand_column_3d", 2)])
def test_compare_image_puts_the_runs_side_by_side(tmp_path, name, panels):
    """--image: each run's last common frame, and in 2D an overlay of both (three panels)."""
    a, b = tmp_path / "a", tmp_path / "b"
    for out, extra in ((a, ["--integrator", "explicit"]), (b, ["--integrator", "explicit", "--dt", "2e-4"])):
        r = pnet("simulate", TINY / f"{name}.json", *extra, "--frames", 2, "--out", out)
        assert r.returncode == 0, r.stderr
    r = pnet("compare", a, b, "--image", "--out", tmp_path / "cmp")
    assert r.returncode == 0, r.stderr
    assert "compare.png (frame 2)" in r.stdout
    width, height = _png_size(tmp_path / "cmp" / "compare.png")
    frame_width, frame_height = _png_size(a / "frame_00002.png")
    assert width == panels * frame_width + 8 * (panels - 1)
    assert height == frame_height + 20  # the title band


@pytest.mark.parametrize("name, cell_type", [("sand_column_2d", "1"), ("sand_column_3d", "1"),
                                             ("metal_frame_2d", "5"), ("sand_fem_coupling_2d", "1")])
def test_vtu_frames_hold_the_ply_frames_points(tmp_path, name, cell_type):
    """--vtu: each frame also as a VTK unstructured grid (ParaView): the same points as the PLY,
    vertex cells for particles, triangles for a 2D mesh, with the velocity field."""
    import xml.etree.ElementTree as ET

    out = tmp_path / "run"
    r = pnet("simulate", TINY / f"{name}.json", "--integrator", "explicit", "--frames", 1, "--vtu", "--out", out)
    assert r.returncode == 0, r.stderr
    for frame in (0, 1):
        piece = ET.parse(out / f"frame_{frame:05d}.vtu").getroot().find("UnstructuredGrid/Piece")
        header = (out / f"frame_{frame:05d}.ply").read_bytes().split(b"end_header")[0].decode()
        vertices = int(re.search(r"element vertex (\d+)", header).group(1))
        assert int(piece.get("NumberOfPoints")) == vertices
        names = [a.get("Name") for a in piece.iter("DataArray")]
        assert "velocity" in names
        types = piece.find("Cells").findall("DataArray")[2].text.split()
        assert set(types) == {cell_type}


# Every numeric option of `pnet simulate` with values a typo or a script bug produces: each is refused
# with exit 2, a message naming the option and what it accepts, and nothing written.
_BAD_OPTIONS = [
    ("--dt", ["-1", "nan", "inf", "1e400", "abc", ""]),
    ("--cfl", ["0", "-0.5", "nan", "inf", "2"]),
    ("--frames", ["0", "-1", "-5", "1.5", "nan", "1e12", "ten"]),
    ("--threads", ["-1", "2.5", "nan", "100000"]),
    ("--checkpoint-every", ["-1", "0.5", "nan", "1e12"]),
    ("--newton-tol", ["0", "-1", "nan", "inf"]),
    ("--cg-tol", ["0", "1", "nan", "inf"]),
    ("--fixed-point-tol", ["-1", "nan", "inf"]),
    ("--regularizer", ["-1", "nan", "inf"]),
    ("--tangent-damping", ["-1", "nan", "inf"]),
    ("--lazy-hessian", ["-0.1", "1", "nan"]),
    ("--advection-cfl", ["-0.1", "1.5", "nan"]),
    ("--fixed-point-iterations", ["0", "-2", "1.5", "nan", "1e12"]),
    ("--fixed-point-inexact", ["-0.1", "1", "nan"]),
    ("--fixed-point-anderson", ["-1", "1.5", "nan", "1e12"]),
]


@pytest.mark.parametrize("option, value", [(o, v) for o, values in _BAD_OPTIONS for v in values])
def test_bad_numeric_option_exits_2_naming_it(tmp_path, option, value):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_column_2d.json", option, value, "--frames", 1, "--out", out) \
        if option != "--frames" else pnet("simulate", TINY / "sand_column_2d.json", option, value, "--out", out)
    assert r.returncode == 2, f"{option} {value!r} accepted: {r.stdout[-300:]} {r.stderr[-300:]}"
    assert option in r.stderr, r.stderr
    assert not out.exists(), "a refused command must write nothing"


def test_model_option_replaces_the_scenes_models(tmp_path):
    """--model FILE: every object that names a model uses FILE instead (checked as the scene's would be);
    run.json lists the models a run used."""
    scene = TINY / "sand_column_2d.json"
    r = pnet("simulate", scene, "--integrator", "plasticitynet", "--frames", 1, "--out", tmp_path / "own")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "own" / "run.json").read_text())["models"] == [str((ROOT / "models" / "sand_2d.pt"))]
    other = ROOT / "models" / "ablation" / "sand_2d_global.pt"
    r = pnet("simulate", scene, "--integrator", "plasticitynet", "--frames", 1, "--model", other, "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "o" / "run.json").read_text())["models"] == [str(other)]
    # The frames differ: another energy moved the particles.
    assert frame_data(tmp_path / "o" / "frame_00001.ply") != frame_data(tmp_path / "own" / "frame_00001.ply")


@pytest.mark.parametrize(
    "model,expected",
    [
        ("/no/such/model.pt", "/no/such/model.pt"),
        ("", "--model: expected a model file"),
        (str(ROOT / "models" / "snow_2d.pt"), "objects[0].model: "),
        (str(ROOT / "models" / "sand_3d.pt"), "objects[0].model: "),
    ],
)
def test_model_option_errors(tmp_path, model, expected):
    r = pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "plasticitynet", "--frames", 1,
             "--model", model, "--out", tmp_path / "o")
    assert r.returncode == 2 and expected in r.stderr, r.stderr
    assert not (tmp_path / "o" / "frame_00001.ply").exists()


def test_model_option_needs_a_scene_that_names_a_model(tmp_path):
    scene = tiny_scene("sand_column_2d")
    del scene["objects"][0]["model"]
    path = write_scene(tmp_path, scene)
    r = pnet("simulate", path, "--integrator", "lagged", "--model", ROOT / "models" / "sand_2d.pt", "--out", tmp_path / "o")
    assert r.returncode == 2
    assert f"{path} names no model to replace" in r.stderr, r.stderr


def test_scene_view_frames_the_pictures(tmp_path):
    """A scene's "view" is the region its pictures show (the domain by default): same width, the height
    of the view's aspect ratio; run.json records it; a view with max <= min is refused naming it."""
    scene = tiny_scene("sand_column_2d")
    scene.pop("view", None)
    r = pnet("simulate", write_scene(tmp_path, scene), "--integrator", "explicit", "--frames", 1, "--out", tmp_path / "a")
    assert r.returncode == 0, r.stderr
    lo, hi = scene["domain"]["min"], scene["domain"]["max"]
    scene["view"] = {"min": lo, "max": [hi[0], lo[1] + 0.4 * (hi[1] - lo[1])]}
    r = pnet("simulate", write_scene(tmp_path, scene, "view.json"), "--integrator", "explicit", "--frames", 1,
             "--out", tmp_path / "b")
    assert r.returncode == 0, r.stderr
    (wa, ha), (wb, hb) = _png_size(tmp_path / "a" / "frame_00001.png"), _png_size(tmp_path / "b" / "frame_00001.png")
    assert wa == wb and hb < 0.6 * ha
    run = json.loads((tmp_path / "b" / "run.json").read_text())
    assert run["view_min"] == scene["view"]["min"] and run["view_max"] == scene["view"]["max"]
    assert run["domain_max"] == hi
    scene["view"]["max"][1] = lo[1]
    path = write_scene(tmp_path, scene, "bad.json")
    r = pnet("simulate", path, "--integrator", "explicit", "--frames", 1, "--out", tmp_path / "c")
    assert r.returncode == 2 and f"{path}: view.max[1]: must exceed view.min[1]" in r.stderr, r.stderr


def _available_cores() -> int:
    env = os.environ.get("OMP_NUM_THREADS", "")
    return int(env) if env.isdigit() and int(env) > 0 else len(os.sched_getaffinity(0))


def test_default_threads_are_every_available_core(tmp_path):
    # LibTorch's first operation (loading the model) used to impose its own intra-op count (1 on a
    # 2-core machine) on OpenMP, so runs without --threads used one core and run.json said so.
    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "plasticitynet", "--frames", 1, "--out", out)
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "run.json").read_text())["threads"] == _available_cores()
    r = pnet("simulate", TINY / "sand_column_2d.json", "--frames", 1, "--threads", 1, "--out", tmp_path / "one")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "one" / "run.json").read_text())["threads"] == 1


@pytest.mark.parametrize("outer", ["newton", "fixed_point"])
def test_steps_report_the_true_residual_of_the_outer_iteration(tmp_path, outer):
    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_column_2d.json", "--frames", 1, "--outer-iteration", outer, "--out", out)
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "run.json").read_text())["solver"]["outer_iteration"] == outer
    lines = (out / "steps.csv").read_text().splitlines()
    header = lines[0].split(",")
    rows = [dict(zip(header, line.split(","))) for line in lines[1:]]
    assert rows and all(int(r["reference_updates"]) >= 1 for r in rows)
    residuals = [float(r["true_residual_m_per_s"]) for r in rows]
    assert all(x > 0.0 for x in residuals), "the true residual was measured"
    if outer == "newton":  # one solve per step, converged on the true residual (the Newton tolerance, m/s)
        assert all(int(r["fixed_point_iterations"]) == 1 for r in rows)
        assert all(x <= 1e-3 for x in residuals) and all(r["converged"] == "1" for r in rows)


def test_kinematic_start_from_the_last_velocities_skips_plate_stages(tmp_path):
    # The tiny metal frame under its plate: starting each step from the last velocities with the plate
    # on its target needs fewer kinematic stages than the scaled start, and both runs stay converged
    # on the true residual and intersection-free (the run's exact test).
    stages = {}
    for start in ("scaled", "last_velocity"):
        out = tmp_path / start
        r = pnet("simulate", TINY / "metal_frame_2d.json", "--frames", 3, "--kinematic-start", start, "--out", out)
        assert r.returncode == 0, r.stderr
        assert "no intersection at any frame" in r.stdout, r.stdout
        assert json.loads((out / "run.json").read_text())["solver"]["kinematic_start"] == start
        lines = (out / "steps.csv").read_text().splitlines()
        rows = [dict(zip(lines[0].split(","), line.split(","))) for line in lines[1:]]
        assert all(r["converged"] == "1" for r in rows)
        stages[start] = sum(int(r["kinematic_stages"]) for r in rows)
    assert stages["scaled"] > 0, "the plate is held back by CCD in this scene, or the test shows nothing"
    assert stages["last_velocity"] < stages["scaled"]


def test_bdf2_is_refused_on_the_coupling_naming_the_key(tmp_path):
    r = pnet("simulate", TINY / "sand_fem_coupling_2d.json", "--integrator", "lagged", "--frames", 1,
             "--time-integrator", "bdf2", "--out", tmp_path / "o")
    assert r.returncode == 2, r.stderr
    assert 'integrator.time_integrator: "bdf2" is implemented for MPM and FEM scenes' in r.stderr, r.stderr


def test_bdf2_runs_a_fem_scene_and_records_itself(tmp_path):
    """--time-integrator bdf2 on the tiny metal frame: it runs, run.json records it, and the frames differ
    from backward Euler's (the first step, without history, is backward Euler's; the later ones are not)."""
    outs = {}
    for name in ("backward_euler", "bdf2"):
        outs[name] = tmp_path / name
        r = pnet("simulate", TINY / "metal_frame_2d.json", "--integrator", "lagged", "--dt", "1e-2", "--frames", 2,
                 "--time-integrator", name, "--out", outs[name])
        assert r.returncode == 0, r.stderr
        run = json.loads((outs[name] / "run.json").read_text())
        assert run["solver"]["time_integrator"] == name, run["solver"]
    assert frame_data(outs["bdf2"] / "frame_00002.ply") != frame_data(outs["backward_euler"] / "frame_00002.ply")
