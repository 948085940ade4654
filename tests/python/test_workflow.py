"""The evaluation workflow (workflow/Snakefile, python/plasticitynet/workflow, docs/workflow.md):
keys, the tiny-scene pipeline end to end through scripts/reproduce.sh, a second invocation that does
nothing, a model change that re-runs only its dependants, and the cluster path (a local stand-in for the
scheduler)."""
from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from plasticitynet.workflow import catalogue
from plasticitynet.workflow.plan import Plan, refined, target_names
from plasticitynet.workflow.tables import write_sweep

ROOT = Path(__file__).resolve().parents[2]
BUILD = ROOT / os.environ.get("PNET_BUILD_DIR", "build")
PNET = BUILD / "cpp" / "pnet"
REPRODUCE = ROOT / "scripts" / "reproduce.sh"


@pytest.fixture
def fake_pnet(tmp_path):
    """A `pnet` that only answers --version (keys need nothing else)."""
    def make(version="pnet 9.9.9"):
        path = tmp_path / f"pnet-{version.split()[-1]}"
        path.write_text(f"#!/bin/sh\n[ \"$1\" = --version ] && echo '{version}' && exit 0\nexit 3\n")
        path.chmod(0o755)
        return str(path)
    return make


def copy_tiny(dest: Path) -> Path:
    """scenes/tiny (and its stiff variants) with the models they read copied beside them, so that a
    test may change a model without touching models/."""
    scenes = dest / "scenes"
    models = dest / "models"
    models.mkdir(parents=True)
    shutil.copyfile(ROOT / "models" / "MANIFEST", models / "MANIFEST")  # pins the copies' sha256
    for folder, rel in ((ROOT / "scenes" / "tiny", scenes), (ROOT / "scenes" / "stiff" / "tiny", scenes / "stiff")):
        rel.mkdir(parents=True, exist_ok=True)
        for path in folder.glob("*.json"):
            scene = json.loads(path.read_text())
            for group in ("objects", "meshes"):
                for item in scene.get(group, []):
                    if isinstance(item.get("model"), str):
                        source = (path.parent / item["model"]).resolve()
                        for f in [source] + [source.parent / "metal_nh_rm_2d.pt"] * (source.name == "metal_nh_2d.pt"):
                            if not (models / f.name).exists():
                                shutil.copyfile(f, models / f.name)
                        item["model"] = str(models / source.name)
            (rel / path.name).write_text(json.dumps(scene, indent=1))
    return scenes


def plan_for(fake, scenes=ROOT / "scenes" / "tiny", **config) -> Plan:
    return Plan({"scenes": str(scenes), "pnet": fake, "frames": 2, **config})


def test_keys_are_stable_and_independent_of_where_the_clone_is(tmp_path, fake_pnet):
    fake = fake_pnet()
    a = plan_for(fake, copy_tiny(tmp_path / "a"))
    b = plan_for(fake, copy_tiny(tmp_path / "b"))
    again = plan_for(fake, tmp_path / "a" / "scenes")
    assert list(a.runs) == list(again.runs) == list(b.runs)
    assert len(a.runs) > 40


def test_a_model_change_changes_only_the_keys_of_the_runs_that_read_it(tmp_path, fake_pnet):
    fake = fake_pnet()
    scenes = copy_tiny(tmp_path)
    before = plan_for(fake, scenes)
    with open(tmp_path / "models" / "sand_2d.pt", "ab") as f:
        f.write(b"retrained")
    after = plan_for(fake, scenes)
    changed = {before.runs[k].scene + "/" + before.runs[k].run for k in set(before.runs) - set(after.runs)}
    assert changed, "a changed model must change its runs' keys"
    for name in changed:
        scene, run = name.rsplit("/", 1)
        assert "sand" in scene and scene != "sand_column_3d", name  # sand_2d's scenes only
        assert not run.startswith("gt") and "explicit" not in run, f"{name}: explicit runs read no model"
        assert not run.startswith(("return_map", "lagged")), f"{name}: reads no model"
    # The 2D sand scenes' plasticitynet runs all changed; the ground truths, return_map and lagged did not.
    assert "sand_column_2d/plasticitynet_1e-3" in changed and "sand_fem_coupling_2d/plasticitynet_1e-3" in changed


def test_the_version_and_the_step_are_part_of_the_key_the_threads_are_not(tmp_path, fake_pnet):
    one = plan_for(fake_pnet("pnet 1.0.0"), threads=1)
    two = plan_for(fake_pnet("pnet 1.0.0"), threads=2)
    other = plan_for(fake_pnet("pnet 1.0.1"))
    assert list(one.runs) == list(two.runs)
    assert not set(one.runs) & set(other.runs)
    keys = {(j.scene, j.run): k for k, j in one.runs.items()}
    assert keys[("sand_column_2d", "plasticitynet_1e-3")] != keys[("sand_column_2d", "plasticitynet_1e-4")]


@pytest.mark.parametrize("scene", ["sand_column_2d", "stiff/sand_column_2d", "stiff/snowball_2d"])
def test_an_implicit_run_is_keyed_by_the_model_its_scene_file_names(scene, fake_pnet):
    """Model paths are relative to the scene file (scenes/stiff/ for the stiff variants)."""
    plan = Plan({"pnet": fake_pnet()})
    job = next(j for j in plan.runs.values() if j.scene == scene and j.run == "plasticitynet_1e-3")
    models = [Path(f) for f in job.files if f.endswith(".pt")]
    assert models and all(m.is_file() and m.parent == ROOT / "models" for m in models)
    gt = next(j for j in plan.runs.values() if j.scene == scene and j.run == "gt")
    assert not any(f.endswith(".pt") for f in gt.files)


def test_every_study_names_runs_of_its_family_and_every_target_resolves(fake_pnet):
    plan = Plan({"pnet": fake_pnet()})
    for study in catalogue.STUDIES.values():
        assert "gt" in study.runs
        for run in study.runs:
            assert run in catalogue.RUNS[study.family], (study.name, run)
    for target in list(catalogue.TARGETS) + ["sweep_dt", "sweep_dx"]:
        assert plan.target_outputs(target) or target in ("fig04", "fig14_16"), target
    with pytest.raises(KeyError, match="unknown target 'fig99'"):
        plan.target_outputs("fig99")
    # A study on its own: its record; the progress line follows its runs and their ground truths.
    from plasticitynet.workflow.progress import needed_runs
    assert plan.target_outputs("regularizer_ablation") == [plan.study_record("regularizer_ablation")]
    runs = {(plan.runs[k].scene, plan.runs[k].run) for k in needed_runs(plan, ["regularizer_ablation"])}
    assert runs == {("sand_column_2d", r) for r in ("gt", "plasticitynet_1e-3", "plasticitynet_1e-3_w0")}
    listed = subprocess.run([str(REPRODUCE), "--list"], capture_output=True, text=True).stdout.split()
    assert set(listed) == set(target_names()), "reproduce.sh knows every target the plan does"


def test_refinement_divides_the_grid_and_the_elements_and_refuses_a_scene_without_either():
    scene = {"dx": 0.01, "meshes": [{"element_size": 0.003}, {"shape": "box"}]}
    fine = refined(scene, 4, "x.json")
    assert fine["dx"] == pytest.approx(0.0025) and fine["meshes"][0]["element_size"] == pytest.approx(0.00075)
    assert scene["dx"] == 0.01, "the original is left alone"
    # The floor layer keeps its thickness in metres (the column stands on it): k times the cells.
    column = {"dx": 0.01, "boundary": {"walls": "slip", "sticky_floor_cells": 3, "floor_friction": 0.5}}
    assert refined(column, 4, "x.json")["boundary"] == {"walls": "slip", "sticky_floor_cells": 12,
                                                         "floor_friction": 0.5}
    assert column["boundary"]["sticky_floor_cells"] == 3
    with pytest.raises(ValueError, match=r"x\.json: no dx and no meshes\[\]\.element_size"):
        refined({"meshes": [{"shape": "box"}]}, 2, "x.json")


def test_a_scale_study_written_before_its_runs_finished_lists_them_as_not_run(tmp_path, fake_pnet):
    """`python -m plasticitynet.workflow sweep NAME` after a stopped workflow: no run of the sweep has
    finished, so each is listed as not run (the sweep rule itself waits for all of them)."""
    plan = plan_for(fake_pnet(), work=str(tmp_path / "work"), results=str(tmp_path / "results"),
                    sweep_refinements=[1, 2])
    write_sweep(plan, "sand_column_2d_dx")
    table = (tmp_path / "results" / "sweeps" / "sand_column_2d_dx" / "summary.md").read_text()
    assert "| return_map_1e-3_uncapped | dx/2 | - | not run |" in table
    rows = list(csv.DictReader(open(tmp_path / "results" / "sweeps" / "sand_column_2d_dx" / "summary.csv")))
    assert len(rows) == 14 and all(r["not_run"] == "True" for r in rows)


def test_the_tiny_folder_finds_the_tiny_stiff_variants(fake_pnet):
    plan = plan_for(fake_pnet())
    assert plan.scene_file("stiff/snowball_2d") == ROOT / "scenes" / "stiff" / "tiny" / "snowball_2d.json"
    assert plan.scene_file("snowball_2d") == ROOT / "scenes" / "tiny" / "snowball_2d.json"


def test_a_missing_scene_is_named(tmp_path, fake_pnet):
    with pytest.raises(FileNotFoundError, match=r"sand_column_2d\.json: no such scene file"):
        plan_for(fake_pnet(), tmp_path)


# --- end to end -----------------------------------------------------------------------------------------
def reproduce(*args, timeout=900) -> subprocess.CompletedProcess:
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    return subprocess.run([str(REPRODUCE), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT)


def tiny_config(tmp_path: Path, scenes: Path, name: str, **extra) -> Path:
    config = {"scenes": str(scenes), "frames": 2, "work": str(tmp_path / name / "work"),
              "results": str(tmp_path / name / "results"), "sweep_frames": 2, "sweep_dx_frames": 2, "sweep_dts": [1e-3, 1e-2],
              "sweep_refinements": [1, 2], "progress_every": 5, **extra}
    path = tmp_path / f"{name}.yaml"
    path.write_text(json.dumps(config))  # JSON is YAML
    return path


def jobs_of(dry_run_output: str) -> dict[str, int]:
    """The 'Job stats' table of a dry run: rule -> count."""
    table = dry_run_output.split("Job stats:", 1)[1] if "Job stats:" in dry_run_output else ""
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)\s+\d+\s+\d+$", table, re.M)
            if m.group(1) != "total"}


def test_the_tiny_pipeline_end_to_end_then_nothing_then_only_a_changed_models_dependants(tmp_path):
    """`reproduce.sh all` on the tiny scenes (2 frames): every study, sweep, Table 1 and notebook."""
    scenes = copy_tiny(tmp_path)
    config = tiny_config(tmp_path, scenes, "local")
    r = reproduce("all", "--jobs", "2", "--", "--configfile", config)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "[progress] runs:" in r.stderr, "the progress line"
    results = tmp_path / "local" / "results"
    for study in catalogue.TARGETS["all"].studies:
        assert (results / study / "summary.md").is_file(), study
    # The regularizer ablation (MPM) and the FEM evaluation, in the layout the notebooks read.
    summary = (results / "regularizer_ablation" / "summary.md").read_text()
    assert "plasticitynet_1e-3_w0" in summary and "(reference)" in summary
    iou = list(csv.DictReader(open(results / "regularizer_ablation" / "sand_column_2d" / "iou.csv")))
    assert [int(r["frame"]) for r in iou][-1] == 2
    assert all(0.0 < float(r["plasticitynet_1e-3"]) <= 1.0 for r in iou)
    fem = list(csv.DictReader(open(results / "fem_eval" / "summary.csv")))
    assert {r["scene"] for r in fem} == {"metal_frame_2d", "metal_nh_frame_2d", "metal_frame_3d"}
    assert all(r["final_mean_pct"] for r in fem if r["run"] != "gt")
    assert (results / "fem_eval" / "metal_frame_2d" / "nodal_error.png").is_file()
    coupling = list(csv.DictReader(open(results / "coupling_eval" / "summary.csv")))
    assert [r["run"] for r in coupling] == ["explicit_1e-6", "explicit_cfl", "plasticitynet_1e-3", "return_map_1e-3",
                                            "lagged_1e-3"]
    assert all(r["penetrations"] in ("0", "") for r in coupling)
    sweep = list(csv.DictReader(open(results / "sweeps" / "sand_column_2d_dt" / "summary.csv")))
    assert [r["run"] for r in sweep] == ["explicit_cfl", "plasticitynet_0.001", "plasticitynet_0.01",
                                         "return_map_0.001", "return_map_0.01", "lagged_0.001", "lagged_0.01"]
    assert all(0.0 < float(r["accuracy"]) <= 1.0 for r in sweep)
    assert (results / "sweeps" / "sand_column_2d_dt" / "sand_column_2d_dt.png").stat().st_size > 10000
    refined = list(csv.DictReader(open(results / "sweeps" / "sand_column_2d_dx" / "summary.csv")))
    assert [float(r["dx_m"]) for r in refined if r["run"] == "explicit_cfl"] == [0.03125, 0.015625]
    # The scale study: every integrator capped and uncapped at each resolution, each against that
    # resolution's own ground truth, with its Krylov products and its speed against explicit at CFL.
    assert [r["run"] for r in refined if r["refinement"] == "2"] == [
        "explicit_cfl", "plasticitynet_1e-3", "plasticitynet_1e-3_uncapped", "return_map_1e-3",
        "return_map_1e-3_uncapped", "lagged_1e-3", "lagged_1e-3_uncapped"]
    assert all(0.0 < float(r["accuracy"]) <= 1.0 and r["spread_error"] and r["height_error"] for r in refined)
    assert all(float(r["krylov_per_step"]) > 0 for r in refined if r["integrator"] != "explicit")
    coarse, fine = (int(r["particles"]) for r in refined if r["run"] == "explicit_cfl")
    assert 3.5 * coarse < fine < 4.5 * coarse, (coarse, fine)  # 2D: about four times the particles at dx/2
    assert all(float(r["speedup_vs_explicit_cfl"]) > 0 for r in refined)
    table = (results / "sweeps" / "sand_column_2d_dx" / "summary.md").read_text()
    assert "| return_map_1e-3_uncapped | dx/2 |" in table
    assert "| sand_column_2d | plasticitynet |" in (results / "table1" / "mpm.md").read_text()
    for notebook in catalogue.TARGETS["all"].notebooks:
        assert (tmp_path / "local" / "work" / "notebooks" / f"{notebook}.executed").is_file(), notebook

    again = reproduce("all", "--dry-run", "--", "--configfile", config)
    assert again.returncode == 0 and "Nothing to be done" in again.stdout + again.stderr, again.stdout[-2000:]

    with open(tmp_path / "models" / "sand_2d.pt", "ab") as f:
        f.write(b"retrained")
    changed = reproduce("all", "--dry-run", "--", "--configfile", config)
    jobs = jobs_of(changed.stdout)
    assert "ground_truth" not in jobs and "bench" not in jobs, jobs
    simulated = set(re.findall(r"simulate (\S+) (\S+) \(", changed.stdout))
    assert {scene for scene, _ in simulated} == {"sand_column_2d", "stiff/sand_column_2d", "sand_fem_coupling_2d"}
    # Only the runs that read the model: not explicit, return_map or lagged (nor the ablation's own models).
    assert not any(run.startswith(("explicit", "return_map", "lagged", "form_")) for _, run in simulated), simulated
    assert {("sand_column_2d", "plasticitynet_1e-3"), ("sand_fem_coupling_2d", "plasticitynet_1e-3")} <= simulated
    # One comparison per changed run (a refined run against its own resolution's ground truth).
    assert jobs["simulate"] == len(simulated), jobs
    assert jobs["metric"] == len(simulated), jobs

    # A fresh clone: the committed tables are there, the work folder is not; everything runs again.
    shutil.rmtree(tmp_path / "local" / "work")
    fresh = jobs_of(reproduce("all", "--dry-run", "--", "--configfile", config).stdout)
    assert fresh["ground_truth"] >= 10 and fresh["study"] == len(catalogue.TARGETS["all"].studies), fresh
    assert fresh["bench"] == 3, fresh


def test_the_cluster_path_gives_the_local_results(tmp_path):
    """The same target through workflow/profiles/local-cluster (submit / status / cancel scripts standing
    in for sbatch / sacct / scancel) and locally: identical metrics (the runs are deterministic)."""
    scenes = copy_tiny(tmp_path)
    outputs = {}
    for name, how in (("local", ["--jobs", "1"]), ("cluster", ["--profile", "workflow/profiles/local-cluster"])):
        config = tiny_config(tmp_path, scenes, name, sweep_dts=[1e-3])
        env_queue = tmp_path / name / "queue"
        os.environ["PNET_LOCAL_QUEUE"] = str(env_queue)
        try:
            r = reproduce("sweep_dt", *how, "--", "--configfile", config)
        finally:
            del os.environ["PNET_LOCAL_QUEUE"]
        assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
        rows = list(csv.DictReader(open(tmp_path / name / "results" / "sweeps" / "sand_column_2d_dt" / "summary.csv")))
        outputs[name] = [(r["run"], r["frames"], r["accuracy"], r["steps_per_frame"]) for r in rows]
        if name == "cluster":
            assert len(list(env_queue.glob("*.status"))) >= 5, "every job went through the stand-in scheduler"
    assert outputs["local"] == outputs["cluster"]


def test_pnet_reports_the_project_version_runs_are_keyed_by():
    if not PNET.exists():
        pytest.fail(f"{PNET} is not built (run scripts/setup.sh)")
    version = re.search(r"project\(plasticitynet VERSION ([0-9.]+)", (ROOT / "CMakeLists.txt").read_text()).group(1)
    out = subprocess.run([str(PNET), "--version"], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == f"pnet {version}"


def test_the_time_left_comes_from_the_runs_own_frame_timings(tmp_path, fake_pnet):
    from plasticitynet.workflow.progress import report
    plan = plan_for(fake_pnet(), work=str(tmp_path / "work"), frames=6)
    keys = [k for k, j in plan.runs.items() if j.scene == "sand_column_2d"][:3]
    done, running, waiting = keys
    for key, rows in ((done, [1.5, 2.5]), (running, [0.1, 4.0, 4.0, 4.0])):
        folder = plan.run_dir(key) / "frames"
        folder.mkdir(parents=True)
        (folder / "stats.csv").write_text("frame,wall_s\n" + "".join(f"{i + 1},{w}\n" for i, w in enumerate(rows)))
    (plan.run_dir(done) / "done.json").write_text("{}")
    line = report(plan, keys, jobs=1)
    # running: frames 5-6 left at its last three frames' 4 s (not its mean, 3.0); waiting: its 6 frames at the
    # finished runs' mean rate, 2 s (no run of its own name has finished): 8 + 12 = 20 s.
    assert "runs: 1 done, 1 running, 1 waiting; ~20 s left" in line, line
    assert f"{plan.runs[running].scene}/{plan.runs[running].run} 4/6" in line
    timings = json.loads((tmp_path / "work" / "timings.json").read_text())
    assert timings == {f"sand_column_2d/{plan.runs[done].run}": 2.0}
    assert "~10 s left" in report(plan, keys, jobs=2), "two jobs at once halve it"
