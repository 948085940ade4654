"""From the catalogue and a configuration to keyed jobs (docs/workflow.md).

Every simulation is keyed by everything that determines its frames: the scene's content (its prose
description left out; an explicit run also leaves out the "integrator" block, which only sets the
implicit solvers), the sha256 of every file it reads (models, a metal model's learned return map, mesh
files), the simulator's version (`pnet --version`), the integrator, step, frame count and options. The
thread count is not part of it: frames are bit-identical at 1 and 2 threads (the C++ tests
OneAndTwoThreads...). Two studies that need the same run share it; an unchanged run is never recomputed;
a retrained model changes the key of exactly the runs that read it.

Metrics are keyed by the runs they compare, studies and sweeps by what they list, so the workflow engine
re-runs a table only when one of its runs changed.
"""
from __future__ import annotations

import copy
import hashlib
import json
import subprocess
import zipfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from . import catalogue
from .catalogue import RUNS, STUDIES, SWEEP_DTS, SWEEP_INTEGRATORS, SWEEP_REFINEMENTS, Run

ROOT = Path(__file__).resolve().parents[3]

#: The configuration's keys and defaults (workflow/config.yaml holds the same; --config overrides).
DEFAULTS = {
    "root": str(ROOT),
    "scenes": "scenes",                      # the scene folder (tests: scenes/tiny)
    "results": "notebooks/results",          # where studies write their tables and figures
    "work": "out/workflow",                  # keyed runs, metrics, logs
    "pnet": "build/cpp/pnet",
    "bench": "build/cpp/bench/bench_table1",
    "frames": 0,                             # 0: each study's own frame counts; N: every run N frames
    "threads": 1,                            # threads per simulation
    "sweep_scenes": ["sand_column_2d"],      # the scenes of the sweep_dt / sweep_dx targets
    "sweep_frames": 25,                      # the time-step sweep's frames
    "sweep_dx_frames": 10,                   # the resolution sweep's (dx / 4 costs ~64x the explicit steps)
    "sweep_dts": list(SWEEP_DTS),
    "sweep_refinements": list(SWEEP_REFINEMENTS),
}


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def digest(value) -> str:
    """A short, stable key of a JSON-serialisable value."""
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16]


@lru_cache(maxsize=None)
def pnet_version(pnet: str) -> str:
    """`pnet --version`'s line: the simulator version every run is keyed by."""
    if not Path(pnet).is_file():
        raise FileNotFoundError(f"{pnet}: no pnet binary; build first (./scripts/setup.sh)")
    done = subprocess.run([pnet, "--version"], capture_output=True, text=True)
    if done.returncode != 0 or not done.stdout.strip():
        raise RuntimeError(f"{pnet} --version failed (exit {done.returncode}): {done.stderr.strip()}")
    return done.stdout.strip()


def _integrators_reading_models() -> frozenset[str]:
    """The integrators that read the objects' model files, from the simulator's own list."""
    import plasticitynet_sim

    return frozenset(i["name"] for i in plasticitynet_sim.integrators() if i["reads_models"])


def _model_return_map(path: Path) -> Path | None:
    """The learned return-mapping file an energy model names in its metadata (metal_nh), if any."""
    try:
        with zipfile.ZipFile(path) as archive:
            name = next(n for n in archive.namelist() if n.endswith("/extra/metadata.json"))
            meta = json.loads(archive.read(name))
    except (zipfile.BadZipFile, StopIteration, json.JSONDecodeError, OSError):
        return None  # not ours to judge here: pnet refuses it with the file's name
    rm = meta.get("return_map") or {}
    return path.parent / rm["file"] if rm.get("type") == "learned" and rm.get("file") else None


@dataclass
class SceneFile:
    """A scene's JSON with every file path it names made absolute, and those files' sha256."""
    name: str
    content: dict
    files: dict[str, str]

    @classmethod
    def load(cls, path: Path, name: str) -> "SceneFile":
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such scene file (scene {name!r})")
        try:
            content = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"{path}: not valid JSON ({err})") from None
        files = {}
        for group in ("objects", "meshes"):
            for item in content.get(group, []):
                for key in ("model", "file"):
                    if isinstance(item.get(key), str):
                        file = (path.parent / item[key]).resolve()
                        item[key] = str(file)
                        files.update(file_hashes(file))
        return cls(name, content, files)


def file_hashes(file: Path) -> dict[str, str]:
    """{path: sha256} of a file a run reads and of the learned return map it names; a missing file is
    keyed as missing (the run then fails naming it)."""
    out = {str(file): sha256_file(file) if file.is_file() else "missing"}
    rm = _model_return_map(file) if file.suffix == ".pt" and file.is_file() else None
    if rm is not None:
        out[str(rm)] = sha256_file(rm) if rm.is_file() else "missing"
    return out


@dataclass
class RunJob:
    """One `pnet simulate`: its key, its scene (content, absolute paths) and its command-line options."""
    key: str
    scene: str
    run: str
    family: str
    scene_content: dict
    integrator: str
    dt: float
    frames: int
    options: list[str]
    files: dict[str, str]
    ground_truth: bool = False

    def describe(self) -> str:
        dt = "CFL" if self.dt == 0 else f"{self.dt:g}"
        return f"{self.scene} {self.run} ({self.integrator}, dt {dt}, {self.frames} frames)"


@dataclass
class MetricJob:
    """The comparison of one run with its ground truth (and, FEM, its same-step reference)."""
    key: str
    family: str
    scene: str
    run: str
    run_key: str
    gt_key: str
    reference_key: str | None = None


@dataclass
class StudyJob:
    name: str
    study: catalogue.Study
    runs: dict[str, dict[str, str]]     # scene -> run name -> run key
    metrics: dict[str, dict[str, str]]  # scene -> run name -> metric key
    frames: dict[str, int]


@dataclass
class SweepJob:
    """A time-step (kind "dt") or resolution ("dx") sweep of one scene."""
    name: str
    kind: str
    scene: str
    family: str
    points: list[dict] = field(default_factory=list)  # {label, integrator, dt, refinement, run_key, metric_key}


class Plan:
    """Every job a configuration asks for, by key."""

    def __init__(self, config: dict | None = None):
        self.config = {**DEFAULTS, **(config or {})}
        self.root = Path(self.config["root"])
        self.pnet = str(self.path(self.config["pnet"]))
        # A job rebuilding the workflow's plan is given the version the workflow keyed with.
        self.version = self.config.get("pnet_version") or pnet_version(self.pnet)
        self.config["pnet_version"] = self.version
        self.runs: dict[str, RunJob] = {}
        self.metrics: dict[str, MetricJob] = {}
        self.studies: dict[str, StudyJob] = {}
        self.sweeps: dict[str, SweepJob] = {}
        self._scenes: dict[str, SceneFile] = {}
        for study in STUDIES.values():
            self.studies[study.name] = self._study(study)
        for scene in self.config["sweep_scenes"]:
            self.sweeps[f"{scene}_dt"] = self._sweep(scene, "dt")
            self.sweeps[f"{scene}_dx"] = self._sweep(scene, "dx")

    # --- paths -------------------------------------------------------------------------------------
    def path(self, value: str) -> Path:
        p = Path(value)
        return p if p.is_absolute() else self.root / p

    @property
    def work(self) -> Path:
        return self.path(self.config["work"])

    @property
    def results(self) -> Path:
        return self.path(self.config["results"])

    def run_dir(self, key: str) -> Path:
        return self.work / "runs" / key

    def metric_file(self, key: str) -> Path:
        return self.work / "metrics" / f"{key}.json"

    def compare_dir(self, key: str) -> Path:
        return self.work / "metrics" / f"{key}.compare"

    # --- scenes and runs ---------------------------------------------------------------------------
    def scene_file(self, name: str) -> Path:
        """<scenes>/<name>.json; a variant of a variant folder ("stiff/x" with scenes = scenes/tiny) is
        looked up in the variant's own folder for it too (scenes/stiff/tiny/x.json)."""
        folder = self.path(self.config["scenes"])
        path = folder / f"{name}.json"
        if not path.exists() and "/" in name:
            variant, base = name.rsplit("/", 1)
            nested = folder.parent / variant / folder.name / f"{base}.json"
            if nested.exists():
                return nested
        return path

    def scene(self, name: str) -> SceneFile:
        if name not in self._scenes:
            self._scenes[name] = SceneFile.load(self.scene_file(name), name)
        return self._scenes[name]

    def family_of(self, content: dict) -> str:
        if content.get("meshes") and content.get("objects"):
            return "coupling"
        return "fem" if content.get("meshes") else "mpm"

    def frames_for(self, frames: int) -> int:
        return int(self.config["frames"]) or frames

    def add_run(self, scene: str, name: str, run: Run, frames: int, family: str, content: dict | None = None,
                label: str | None = None) -> RunJob:
        """The keyed job of `run` on `scene` (content: a derived scene, e.g. a refined grid)."""
        base = self.scene(scene)
        content = copy.deepcopy(content if content is not None else base.content)
        dim = int(content.get("dim", 2))
        dt = catalogue.ground_truth_step(family, scene, dim) if run.dt is None else run.dt
        frames = min(frames, run.frames) if run.frames else frames
        # Only an integrator that reads models (cpp/pnet/solver/integrators.hpp: plasticitynet) is keyed
        # by them: a retrained model re-runs neither the ground truth nor return_map, lagged, analytic.
        explicit = run.integrator == "explicit"
        reads_models = run.integrator in _integrators_reading_models()
        replaced = "--model" in run.options  # `pnet simulate --model M` replaces the scene's models
        options, files = [], {f: h for f, h in base.files.items()
                              if not ((not reads_models or replaced) and f.endswith(".pt"))}
        it = iter(run.options)
        for option in it:  # a model path among the options is absolute, and keyed by its content
            options.append(option)
            if option == "--model":
                model = self.path(next(it))
                options.append(str(model))
                files.update(file_hashes(model))
        keyed = copy.deepcopy(content)
        keyed.pop("description", None)
        keyed.pop("name", None)
        for group in ("objects", "meshes"):  # files by name: a key does not depend on where the clone is
            for item in keyed.get(group, []):
                if not reads_models:
                    item.pop("model", None)
                for k in ("model", "file"):
                    if isinstance(item.get(k), str):
                        item[k] = Path(item[k]).name
        if explicit:
            keyed.pop("integrator", None)
        key = digest({"pnet": self.version, "scene": keyed, "files": {Path(k).name: v for k, v in files.items()},
                      "integrator": run.integrator, "dt": dt, "frames": frames, "options": [
                          Path(o).name if o.endswith(".pt") else o for o in options]})
        job = RunJob(key, scene, label or name, family, content, run.integrator, dt, frames, options, files,
                     ground_truth=name == "gt")
        self.runs.setdefault(key, job)
        return self.runs[key]

    def add_metric(self, family: str, scene: str, run: str, run_key: str, gt_key: str,
                   reference_key: str | None = None) -> str:
        key = digest({"family": family, "run": run_key, "gt": gt_key, "reference": reference_key})
        self.metrics.setdefault(key, MetricJob(key, family, scene, run, run_key, gt_key, reference_key))
        return key

    def _study(self, study: catalogue.Study) -> StudyJob:
        table = RUNS[study.family]
        runs, metrics, frames = {}, {}, {}
        for scene, n in study.scenes.items():
            n = self.frames_for(n)
            frames[scene] = n
            keys = {name: self.add_run(scene, name, table[name], n, study.family).key for name in study.runs_of(scene)}
            gt = keys.get("gt") or self.add_run(scene, "gt", table["gt"], n, study.family).key
            reference = None
            if study.family == "fem":
                ref_name = catalogue.FEM_REFERENCE.get(scene)
                if ref_name in keys:
                    reference = keys[ref_name]
            runs[scene] = keys
            metrics[scene] = {}
            for name, key in keys.items():
                if name == "gt":
                    continue
                ref = reference if (reference and name != catalogue.FEM_REFERENCE.get(scene)
                                    and table[name].integrator != "explicit") else None
                metrics[scene][name] = self.add_metric(study.family, scene, name, key, gt, ref)
        return StudyJob(study.name, study, runs, metrics, frames)

    def _sweep(self, scene: str, kind: str) -> SweepJob:
        base = self.scene(scene)
        family = self.family_of(base.content)
        table = RUNS[family]
        frames = int(self.config["sweep_frames" if kind == "dt" else "sweep_dx_frames"])
        sweep = SweepJob(f"{scene}_{kind}", kind, scene, family)
        # The sweeps take each step as given: the advection limit (on by default) off for the particles.
        uncapped = () if family == "fem" else ("--advection-cfl", "0")
        if kind == "dt":
            gt = self.add_run(scene, "gt", table["gt"], frames, family)
            cfl = self.add_run(scene, "explicit_cfl", table["explicit_cfl"], frames, family)
            points = [("explicit_cfl", "explicit", 0.0, cfl)]
            for integrator in SWEEP_INTEGRATORS:
                for dt in self.config["sweep_dts"]:
                    name = f"{integrator}_{dt:g}"
                    points.append((name, integrator, dt,
                                   self.add_run(scene, name, Run(integrator, dt, uncapped), frames, family)))
            for label, integrator, dt, job in points:
                sweep.points.append({"label": label, "integrator": integrator, "dt": dt, "refinement": 1,
                                     "run_key": job.key,
                                     "metric_key": self.add_metric(family, scene, label, job.key, gt.key)})
        else:
            # The scale study: at each resolution its own ground truth and explicit at its CFL step (the
            # floor), and each implicit integrator at 1e-3 s as a user runs it (within the default
            # advection limit, "capped") and as the step alone ("uncapped"; FEM has no advection limit).
            for k in self.config["sweep_refinements"]:
                content = refined(base.content, int(k), f"{base.name}.json")
                gt = self.add_run(scene, "gt", table["gt"], frames, family, content=content, label=f"gt_dx{k}")
                runs = {"explicit_cfl": table["explicit_cfl"]}
                for i in SWEEP_INTEGRATORS:
                    runs[f"{i}_1e-3"] = Run(i, 1e-3)
                    if uncapped:
                        runs[f"{i}_1e-3_uncapped"] = Run(i, 1e-3, uncapped)
                for name, run in runs.items():
                    label = f"{name}_dx{k}"
                    job = self.add_run(scene, name, run, frames, family, content=content, label=label)
                    sweep.points.append({"label": name, "integrator": run.integrator, "dt": run.dt, "refinement": k,
                                         "capped": bool(uncapped) and run.integrator != "explicit" and
                                         "--advection-cfl" not in run.options,
                                         "run_key": job.key,
                                         "metric_key": self.add_metric(family, scene, label, job.key, gt.key)})
        return sweep

    # --- what a target needs -----------------------------------------------------------------------
    def target_outputs(self, target: str) -> list[Path]:
        """The files a target name stands for: the work folder's records of its studies, sweeps and
        benchmarks and its notebooks' executed markers. They (not the committed tables beside them) are
        the targets: a fresh clone lacks them, so there everything the target needs runs."""
        if target.startswith("sweep_"):  # sweep_dt, sweep_dx: every configured sweep scene
            kind = target.split("_", 1)[1]
            return [self.sweep_record(s.name) for s in self.sweeps.values() if s.kind == kind]
        if target in catalogue.STUDIES:  # one results folder
            return [self.study_record(target)]
        if target not in catalogue.TARGETS:
            raise KeyError(f"unknown target {target!r}; known: {', '.join(target_names())}")
        t = catalogue.TARGETS[target]
        out = [self.study_record(s) for s in t.studies]
        out += [self.benchmark_record(b) for b in t.benchmarks]
        out += [self.notebook_output(n) for n in t.notebooks]
        if target == "all":
            out += [self.sweep_record(s.name) for s in self.sweeps.values()]
        return out

    def study_record(self, name: str) -> Path:
        return self.work / "studies" / f"{name}.json"

    def sweep_record(self, name: str) -> Path:
        return self.work / "sweeps" / f"{name}.json"

    def study_outputs(self, name: str) -> list[Path]:
        folder = self.results / name
        return [folder / "summary.md", folder / "summary.csv"]

    def sweep_outputs(self, name: str) -> list[Path]:
        folder = self.results / "sweeps" / name
        return [folder / "summary.md", folder / "summary.csv", folder / f"{name}.png"]

    def benchmark_output(self, name: str) -> Path:
        return self.results / "table1" / f"{name}.md"

    def benchmark_record(self, name: str) -> Path:
        """The work folder's copy: missing in a fresh clone, so that Table 1 is measured there."""
        return self.work / "bench" / f"{name}.md"

    def notebook_output(self, name: str) -> Path:
        return self.work / "notebooks" / f"{name}.executed"


def target_names() -> list[str]:
    """Figures and tables, the two sweeps, and every study (one results folder) on its own."""
    return sorted(catalogue.TARGETS) + ["sweep_dt", "sweep_dx"] + list(catalogue.STUDIES)


def refined(content: dict, k: int, where: str) -> dict:
    """The scene with its grid spacing (MPM, coupling) and element sizes (FEM) divided by k (and the MPM
    floor layer's cells multiplied by k, so that its thickness stays)."""
    content = copy.deepcopy(content)
    if k == 1:
        return content
    changed = False
    if "dx" in content:
        content["dx"] = content["dx"] / k
        changed = True
        # The floor layer keeps its thickness in metres: the material stands on it.
        boundary = content.get("boundary", {})
        if "sticky_floor_cells" in boundary:
            boundary["sticky_floor_cells"] = int(boundary["sticky_floor_cells"]) * k
    for mesh in content.get("meshes", []):
        if "element_size" in mesh:
            mesh["element_size"] = mesh["element_size"] / k
            changed = True
    if not changed:
        raise ValueError(f"{where}: no dx and no meshes[].element_size to refine")
    content["name"] = f"{content.get('name', 'scene')}_dx{k}"
    return content
