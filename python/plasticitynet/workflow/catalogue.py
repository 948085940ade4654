"""What the evaluation runs, declared once: the runs of each scene family, the studies (one results
folder each), the sweeps and the named targets (docs/workflow.md).

A *run* is one `pnet simulate` invocation: an integrator, a step (None: the scene's ground-truth step;
0: the explicit CFL step) and extra options. A *study* is a results folder under notebooks/results/:
a scene family (mpm, fem, coupling), the scenes it covers, the runs of each scene and the ground truth
every run is compared with. A *target* (fig05, table1, all, ...) names the studies, sweeps, benchmarks
and notebooks a figure or table needs.

Nothing here runs anything: plan.py turns these declarations and a configuration into keyed jobs.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Run:
    """One simulation of a scene. `scenes`: the scenes it applies to (None: all of the study's);
    `frames`: a cap on the study's frame count (the slow w = 0 ablation)."""
    integrator: str
    dt: float | None
    options: tuple[str, ...] = ()
    scenes: frozenset[str] | None = None
    frames: int | None = None


def _only(*scenes: str) -> frozenset[str]:
    return frozenset(scenes)


# --- The MPM family (pnet compare: soft IoU at dx and 4 dx, deposit spread and height) -------------
#: The stiff variants (scenes/stiff/, E x 100) have a CFL step 10x smaller: their ground truth is 1e-6 s.
STIFF = _only("stiff/sand_column_2d", "stiff/snowball_2d")
SOFT = _only("sand_column_2d", "snowball_2d", "sand_column_3d", "snowball_3d")

MPM_RUNS: dict[str, Run] = {
    "gt": Run("explicit", None),
    "explicit_2e-5": Run("explicit", 2e-5, scenes=SOFT),
    "explicit_cfl": Run("explicit", 0.0),
    "plasticitynet_1e-3": Run("plasticitynet", 1e-3),
    "plasticitynet_1e-4": Run("plasticitynet", 1e-4),
    "return_map_1e-3": Run("return_map", 1e-3),
    "lagged_1e-3": Run("lagged", 1e-3),
    "plasticitynet_1e-3_bdf2": Run("plasticitynet", 1e-3, ("--time-integrator", "bdf2")),
    "plasticitynet_1e-3_w0": Run("plasticitynet", 1e-3, ("--regularizer", "0")),
    "plasticitynet_1e-3_fp1": Run("plasticitynet", 1e-3, ("--fixed-point-iterations", "1")),
    "plasticitynet_1e-3_advection": Run("plasticitynet", 1e-3, ("--advection-cfl", "0.2")),
    # Without the advection limit (on by default since 2026-11-29): the step as the scene's dt alone.
    "plasticitynet_1e-3_uncapped": Run("plasticitynet", 1e-3, ("--advection-cfl", "0")),
}
#: The energy-representation ablation (paper Fig. 11): the 2D sand energy in eq. 8's form and in the three
#: forms the paper rejected (scripts/train_ablation_models.sh), each replacing the scene's model.
ENERGY_FORMS = ("eq8", "local_identity", "global_identity", "global")
for _form in ENERGY_FORMS:
    MPM_RUNS[f"form_{_form}_1e-3"] = Run("plasticitynet", 1e-3, ("--model", f"models/ablation/sand_2d_{_form}.pt"))

# --- The FEM family (nodal distance to the ground truth and to a same-step reference) ---------------
FEM_RUNS: dict[str, Run] = {
    "gt": Run("explicit", None),
    "explicit_2e-5": Run("explicit", 2e-5),
    "explicit_cfl": Run("explicit", 0.0),
    "analytic_1e-2": Run("analytic", 1e-2, scenes=_only("metal_frame_2d", "metal_frame_3d")),
    "plasticitynet_1e-2": Run("plasticitynet", 1e-2),
    "plasticitynet_1e-3": Run("plasticitynet", 1e-3),
    "return_map_1e-2": Run("return_map", 1e-2),
    "lagged_1e-2": Run("lagged", 1e-2),
    # The regularizer off (paper Fig. 12): ~10x the solves, so 30 frames.
    "plasticitynet_1e-2_w0": Run("plasticitynet", 1e-2, ("--regularizer", "0"), _only("metal_frame_2d"), frames=30),
    "plasticitynet_1e-2_exact_rm": Run("plasticitynet", 1e-2, ("--return-map", "exact"), _only("metal_nh_frame_2d")),
    "plasticitynet_1e-2_bdf2": Run("plasticitynet", 1e-2, ("--time-integrator", "bdf2")),
}
#: The same-step reference every implicit FEM run is also compared with: the closed-form energy, or for
#: metal_nh (no closed form) the classical solver with the exact return mapping.
FEM_REFERENCE = {"metal_frame_2d": "analytic_1e-2", "metal_nh_frame_2d": "return_map_1e-2",
                 "metal_frame_3d": "analytic_1e-2"}

# --- The coupling family (sand: IoU; body: nodal distance; particles inside the body) ---------------
COUPLING_RUNS: dict[str, Run] = {
    "gt": Run("explicit", None),
    "explicit_cfl": Run("explicit", 0.0),
    "plasticitynet_1e-3": Run("plasticitynet", 1e-3),
    "return_map_1e-3": Run("return_map", 1e-3),
    "lagged_1e-3": Run("lagged", 1e-3),
}

# --- Where does the network pay? (docs/integrators.md) ------------------------------------------------
#: plasticitynet against return_map: MPM at four steps with and without the advection limit, the
#: paper's "a few fixed-point iterations" as a budget of 1, 2 and 3 solves per step (not converged:
#: the network's accuracy decides the result); the metal frames at 1e-2 and 2e-2 s.
STUDY_MPM_DTS = (1e-3, 2e-3, 5e-3, 1e-2)


def _step(dt: float) -> str:
    """1e-3 -> "1e-3", as the other run keys write a step."""
    return f"{dt:.0e}".replace("e-0", "e-")


for _dt in STUDY_MPM_DTS:
    for _integrator in ("plasticitynet", "return_map"):
        MPM_RUNS[f"{_integrator}_{_step(_dt)}_study"] = Run(_integrator, _dt, ("--advection-cfl", "0"))
        MPM_RUNS[f"{_integrator}_{_step(_dt)}_capped"] = Run(_integrator, _dt, ("--advection-cfl", "0.2"))
    for _solves in (1, 2, 3):
        MPM_RUNS[f"plasticitynet_{_step(_dt)}_budget{_solves}"] = Run(
            "plasticitynet", _dt, ("--outer-iteration", "fixed_point", "--fixed-point-iterations", str(_solves),
                                   "--fixed-point-tol", "0", "--advection-cfl", "0"))
for _dt in (1e-2, 2e-2):
    for _integrator in ("plasticitynet", "return_map"):
        FEM_RUNS[f"{_integrator}_{_step(_dt)}_study"] = Run(_integrator, _dt)
    for _solves in (1, 2, 3):
        FEM_RUNS[f"plasticitynet_{_step(_dt)}_budget{_solves}"] = Run(
            "plasticitynet", _dt, ("--outer-iteration", "fixed_point", "--fixed-point-iterations", str(_solves),
                                   "--fixed-point-tol", "0"))
#: The coupling's runs take the default advection limit (the MPM runs above name theirs).
for _integrator in ("plasticitynet", "return_map"):
    COUPLING_RUNS[f"{_integrator}_5e-3_capped"] = Run(_integrator, 5e-3)
COUPLING_RUNS["plasticitynet_1e-3_budget1"] = Run(
    "plasticitynet", 1e-3, ("--outer-iteration", "fixed_point", "--fixed-point-iterations", "1", "--fixed-point-tol", "0"))
STUDY_MPM_RUNS = ("gt", "explicit_2e-5", "explicit_cfl") + tuple(
    k for k in MPM_RUNS if k.endswith(("_study", "_capped")) or "_budget" in k)
STUDY_FEM_RUNS = ("gt", "explicit_2e-5", "explicit_cfl") + tuple(
    k for k in FEM_RUNS if k.endswith("_study") or "_budget" in k)

RUNS = {"mpm": MPM_RUNS, "fem": FEM_RUNS, "coupling": COUPLING_RUNS}


def ground_truth_step(family: str, scene: str, dim: int) -> float:
    """The ground truth's step: the paper's 1e-5 s; 1e-6 s for the stiff variants and the 2D coupling
    (its stiff disk); the 3D coupling's 2 cm elements are stable at 1e-5 s."""
    if scene in STIFF or (family == "coupling" and dim == 2):
        return 1e-6
    return 1e-5


@dataclass(frozen=True)
class Study:
    """One results folder: `scenes` maps each scene (a name under the scene folder) to its frame count;
    `keep_frames`: frames whose pictures are copied beside the final ones (<run>_frame_NNNNN.png)."""
    name: str
    family: str
    scenes: dict[str, int]
    runs: tuple[str, ...]
    keep_frames: tuple[int, ...] = ()

    def runs_of(self, scene: str) -> list[str]:
        table = RUNS[self.family]
        return [r for r in self.runs if table[r].scenes is None or scene in table[r].scenes]


MAIN_MPM = ("gt", "explicit_2e-5", "explicit_cfl", "plasticitynet_1e-3", "plasticitynet_1e-4", "return_map_1e-3",
            "lagged_1e-3")
STUDIES: dict[str, Study] = {s.name: s for s in [
    Study("implicit_eval", "mpm", {"sand_column_2d": 50, "snowball_2d": 50, "sand_column_3d": 25, "snowball_3d": 25,
                                   "stiff/sand_column_2d": 50, "stiff/snowball_2d": 50}, MAIN_MPM),
    Study("representation_ablation", "mpm", {"sand_column_2d": 50},
          ("gt", "explicit_cfl", "plasticitynet_1e-3") + tuple(f"form_{f}_1e-3" for f in ENERGY_FORMS),
          keep_frames=(1, 5, 10, 25, 50)),
    Study("regularizer_ablation", "mpm", {"sand_column_2d": 50}, ("gt", "plasticitynet_1e-3", "plasticitynet_1e-3_w0")),
    Study("time_integrator_mpm", "mpm", {"sand_column_2d": 50, "snowball_2d": 50, "snowball_3d": 25},
          ("gt", "explicit_cfl", "plasticitynet_1e-3", "lagged_1e-3", "plasticitynet_1e-3_bdf2",
           "plasticitynet_1e-3_advection", "plasticitynet_1e-3_uncapped")),
    # Its 2D scenes re-measured with the network on every plasticitynet iteration (2026-11-29): what one
    # session fits on two cores (notebooks/results/implicit_eval_2d/).
    Study("implicit_eval_2d", "mpm", {"sand_column_2d": 50, "snowball_2d": 50}, MAIN_MPM),
    Study("fem_eval", "fem", {"metal_frame_2d": 100, "metal_nh_frame_2d": 100, "metal_frame_3d": 25},
          ("gt", "explicit_2e-5", "explicit_cfl", "analytic_1e-2", "plasticitynet_1e-2", "plasticitynet_1e-3",
           "return_map_1e-2", "lagged_1e-2", "plasticitynet_1e-2_w0", "plasticitynet_1e-2_exact_rm")),
    # Its 2D frames, re-measured with the network on every plasticitynet iteration (notebooks/results/fem_eval_2d/).
    Study("fem_eval_2d", "fem", {"metal_frame_2d": 100, "metal_nh_frame_2d": 100},
          ("gt", "explicit_2e-5", "explicit_cfl", "analytic_1e-2", "plasticitynet_1e-2", "plasticitynet_1e-3",
           "return_map_1e-2", "lagged_1e-2", "plasticitynet_1e-2_w0", "plasticitynet_1e-2_exact_rm")),
    Study("coupling_eval", "coupling", {"sand_fem_coupling_2d": 50},
          ("gt", "explicit_cfl", "plasticitynet_1e-3", "return_map_1e-3", "lagged_1e-3")),
    Study("coupling_eval_3d", "coupling", {"sand_fem_coupling_3d": 3},
          ("gt", "explicit_cfl", "plasticitynet_1e-3", "return_map_1e-3", "lagged_1e-3")),
    # Where does the network pay? Every family, 2D and 3D, the stiff variants (docs/integrators.md).
    Study("integrator_study", "mpm", {"sand_column_2d": 50, "snowball_2d": 50, "sand_column_3d": 25,
                                      "snowball_3d": 25, "stiff/sand_column_2d": 25, "stiff/snowball_2d": 25},
          STUDY_MPM_RUNS),
    Study("integrator_study_fem", "fem", {"metal_frame_2d": 100, "metal_nh_frame_2d": 100, "metal_frame_3d": 25},
          STUDY_FEM_RUNS),
    # Its sand column alone, the first half of the collapse: what one session measured
    # (notebooks/results/integrator_study_sand/).
    Study("integrator_study_sand", "mpm", {"sand_column_2d": 25}, STUDY_MPM_RUNS),
    # Its snowball, the first half of its fall and impact (notebooks/results/integrator_study_snow/).
    Study("integrator_study_snow", "mpm", {"snowball_2d": 25}, STUDY_MPM_RUNS),
    # Its 2D metal frames (notebooks/results/integrator_study_metal/).
    Study("integrator_study_metal", "fem", {"metal_frame_2d": 100, "metal_nh_frame_2d": 100}, STUDY_FEM_RUNS),
    # Its stiff sand column, the first 15 frames of the collapse, at the steps and budgets that fit one
    # session on two cores: capped, every step size runs at about the same step once the column flows
    # (notebooks/results/integrator_study_stiff/).
    Study("integrator_study_stiff", "mpm", {"stiff/sand_column_2d": 15},
          ("gt", "explicit_2e-5", "explicit_cfl", "plasticitynet_1e-3_study", "return_map_1e-3_study",
           "plasticitynet_1e-3_capped", "return_map_1e-3_capped", "return_map_2e-3_capped", "return_map_5e-3_capped",
           "return_map_1e-2_capped", "plasticitynet_5e-3_study", "return_map_5e-3_study", "plasticitynet_1e-2_study",
           "return_map_1e-2_study", "plasticitynet_1e-3_budget1", "plasticitynet_1e-3_budget2",
           "plasticitynet_1e-3_budget3", "plasticitynet_1e-2_budget1")),
    # Its stiff snowball, the first 10 frames (the fall and the impact), at the runs that fit one session
    # (notebooks/results/integrator_study_stiff_snow/).
    Study("integrator_study_stiff_snow", "mpm", {"stiff/snowball_2d": 10},
          ("gt", "explicit_cfl", "plasticitynet_1e-3_study", "return_map_1e-3_study", "plasticitynet_1e-3_capped",
           "return_map_1e-3_capped", "plasticitynet_5e-3_capped", "return_map_5e-3_capped",
           "plasticitynet_1e-3_budget1", "plasticitynet_1e-3_budget2")),
    # Its 3D metal frame, the first 5 frames (before the plate buckles it), at the scene's step; its floor
    # is fem_eval's (explicit at its CFL step, 147 s per frame, does not fit a session beside the rest)
    # (notebooks/results/integrator_study_metal_3d/).
    Study("integrator_study_metal_3d", "fem", {"metal_frame_3d": 5},
          ("gt", "analytic_1e-2", "plasticitynet_1e-2_study", "return_map_1e-2_study", "plasticitynet_1e-2_budget1")),
    # Its 3D snowball, 25 frames: the fall, the impact and the first spreading
    # (notebooks/results/integrator_study_snow_3d/).
    Study("integrator_study_snow_3d", "mpm", {"snowball_3d": 25},
          ("gt", "explicit_2e-5", "explicit_cfl", "plasticitynet_1e-3_study", "return_map_1e-3_study",
           "plasticitynet_1e-3_capped", "return_map_1e-3_capped", "plasticitynet_5e-3_capped", "return_map_5e-3_capped",
           "plasticitynet_1e-3_budget1")),
    # The coupling (sand on an elastic FEM disk): coupling_eval's runs, the same 50 frames (so they are
    # shared), with both integrators at a larger capped step and the budget of one solve per step
    # (notebooks/results/integrator_study_coupling/).
    Study("integrator_study_coupling", "coupling", {"sand_fem_coupling_2d": 50},
          ("gt", "explicit_cfl", "plasticitynet_1e-3", "return_map_1e-3", "lagged_1e-3", "plasticitynet_5e-3_capped",
           "return_map_5e-3_capped", "plasticitynet_1e-3_budget1")),
    # Its 3D sand column, the first 10 frames of the collapse, at 1e-3 s and one larger capped step
    # (notebooks/results/integrator_study_3d/).
    Study("integrator_study_3d", "mpm", {"sand_column_3d": 10},
          ("gt", "explicit_2e-5", "explicit_cfl", "plasticitynet_1e-3_study", "return_map_1e-3_study",
           "plasticitynet_1e-3_capped", "return_map_1e-3_capped", "plasticitynet_5e-3_capped", "return_map_5e-3_capped",
           "plasticitynet_1e-3_budget1", "plasticitynet_1e-3_budget2", "plasticitynet_1e-3_budget3")),
]}

# --- Sweeps ------------------------------------------------------------------------------------------
#: The time-step sweep's steps and integrators (every scene; explicit at CFL and the ground truth beside).
SWEEP_DTS = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2)
SWEEP_INTEGRATORS = ("plasticitynet", "return_map", "lagged")
#: The resolution sweep's refinements: dx, dx/2, dx/4 (MPM: the grid; FEM: the element size).
SWEEP_REFINEMENTS = (1, 2, 4)


@dataclass(frozen=True)
class Target:
    """What one figure or table needs: studies, sweeps (scene names), Table 1 benchmark rows and the
    notebook that draws it."""
    studies: tuple[str, ...] = ()
    dt_sweeps: tuple[str, ...] = ()
    resolution_sweeps: tuple[str, ...] = ()
    benchmarks: tuple[str, ...] = ()
    notebooks: tuple[str, ...] = field(default_factory=tuple)


#: Table 1's bench_table1 invocations (name: options), each writing notebooks/results/table1/<name>.md.
BENCHMARKS = {
    "mpm": ["--no-fem", "--frames", "10", "--with-lagged"],
    "fem": ["--only", "metal_frame_2d", "--with-lagged"],
    "coupling": ["--only", "sand_fem_coupling_2d"],
}

TARGETS: dict[str, Target] = {
    "fig04": Target(notebooks=("fig04_training_curves",)),
    "fig05": Target(studies=("implicit_eval", "fem_eval"), notebooks=("fig05_accuracy",)),
    "fig06_10": Target(studies=("implicit_eval", "fem_eval", "coupling_eval"), notebooks=("fig06_10_scenes_2d",)),
    "fig11": Target(studies=("representation_ablation",), notebooks=("fig11_energy_representations",)),
    "fig12": Target(studies=("regularizer_ablation", "fem_eval"), notebooks=("fig12_regularizer",)),
    "fig13": Target(studies=("implicit_eval", "fem_eval"), notebooks=("fig13_gallery_3d",)),
    "fig14_16": Target(notebooks=("fig14_16_elastic_regions",)),
    "table1": Target(benchmarks=tuple(BENCHMARKS), notebooks=("table1_timings",)),
    "time_integrator": Target(studies=("time_integrator_mpm",)),
    "coupling_3d": Target(studies=("coupling_eval_3d",)),
}
TARGETS["all"] = Target(
    studies=tuple(dict.fromkeys(s for t in TARGETS.values() for s in t.studies)),
    benchmarks=tuple(BENCHMARKS),
    notebooks=tuple(dict.fromkeys(n for t in TARGETS.values() for n in t.notebooks)))
#: Where does the network pay? (docs/integrators.md): on its own, not in `all` (44 runs per scene set).
TARGETS["integrators"] = Target(studies=("integrator_study", "integrator_study_fem"))
TARGETS["integrators_sand"] = Target(studies=("integrator_study_sand",))
TARGETS["integrators_metal"] = Target(studies=("integrator_study_metal",))
TARGETS["integrators_snow"] = Target(studies=("integrator_study_snow",))
TARGETS["integrators_stiff"] = Target(studies=("integrator_study_stiff",))
TARGETS["integrators_3d"] = Target(studies=("integrator_study_3d",))
TARGETS["integrators_stiff_snow"] = Target(studies=("integrator_study_stiff_snow",))
TARGETS["integrators_metal_3d"] = Target(studies=("integrator_study_metal_3d",))
TARGETS["integrators_snow_3d"] = Target(studies=("integrator_study_snow_3d",))
TARGETS["integrators_coupling"] = Target(studies=("integrator_study_coupling",))
