#!/usr/bin/env python3
"""The granular column collapse swept over friction angle and aspect ratio with one parametric sand model
(models/sand_param_2d.pt; docs/physics.md), against the explicit ground truth at each angle.

A column of half-width L0 and height H = a L0 stands on a rough floor (by default a Coulomb floor of the
sand's own friction, mu = tan(angle), with AFLIP transfers, so that the explicit runs converge as the
step shrinks: docs/methods.md) and collapses on both sides (the
symmetric 2D collapse: each half is the classic column against a wall). Its final half-extent L_inf gives
the normalised run-out (L_inf - L0) / L0, which experiments find to grow as ~lambda a for small a and as
~a^(2/3) beyond a ~ 2-3 (Lajeunesse et al. 2004, Lube et al. 2005); the coefficients depend on the
friction. For each (angle, a) the script writes the scene (scenes/sand_column_2d.json with the column,
the domain and the material changed), runs

    explicit at the ground-truth step (--ground-truth-dt, default 2e-5 s),
    explicit at its CFL step (the noise floor: what a valid explicit run differs by),
    plasticitynet at 1e-3 s (--implicit-dt; --time-integrator bdf2) with the parametric model,

with `pnet simulate`, and measures L_inf = L0 + e(last frame) - e(first frame), e the 99.5th mass
percentile of |x - x_c| (the outermost particle alone swings between two valid runs; docs/metrics.md).
It writes

    OUT/runout.csv    angle, aspect, integrator, L_inf, run-out, wall seconds;
    OUT/runout.md     the table: run-out per integrator, the plasticitynet error and the floor;
    OUT/runout.png    run-out against a per angle (log-log), ground truth and plasticitynet.

Runs are kept in --work (a finished run of the same scene, integrator and step is not run again).

    .venv/bin/python scripts/granular_collapse.py [--angles 20 30 40] [--aspects 0.5 1 2 4 8]
        [--floor tan|sticky|MU] [--flip-relaxation-time 0.01] [--dt-study]
        [--newton-tolerance M_PER_S] [--implicit-dt 1e-3] [--time-integrator bdf2] [--jobs 2] [--frames 50] [--dx 0.0078125] [--work out/granular_collapse]
        [--out notebooks/results/granular_collapse]
"""

from __future__ import annotations

import argparse
import copy
import csv
import hashlib
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

from plasticitynet import launch  # noqa: E402

launch.with_simulator()  # the frames are read by plasticitynet_sim
from plasticitynet.frames import read_particle_positions  # noqa: E402

HALF_WIDTH = 0.05  # L0, m
MODEL = ROOT / "models" / "sand_param_2d.pt"
PERCENTILE = 99.5


def scene_for(angle: float, aspect: float, dx: float, frames: int, sticky_cells: int = 3,
              floor_friction: float | None = None, flip_relaxation_time: float = 0.0) -> dict:
    """scenes/sand_column_2d.json with a column of half-width L0 and height a L0 centred in a domain wide
    enough for its run-out (walls at L0 (2 + 2.5 a) from the centre: 20 deg sand at a = 8 stops at ~0.7 of it),
    sand at `angle` degrees, the parametric model; a Coulomb floor of `floor_friction` (None: the sticky
    floor layer) and AFLIP transfers of `flip_relaxation_time` s (0: APIC), docs/methods.md."""
    scene = json.loads((ROOT / "scenes" / "sand_column_2d.json").read_text())
    scene = copy.deepcopy(scene)
    floor = sticky_cells * dx
    height = aspect * HALF_WIDTH
    scene["name"] = f"granular_collapse_phi{angle:g}_a{aspect:g}"
    scene["description"] = (f"scripts/granular_collapse.py: sand column of half-width {HALF_WIDTH} m and height "
                            f"{height:g} m (aspect {aspect:g}), friction angle {angle:g} deg, dx {dx:g} m")
    cells = lambda length: math.ceil(length / dx) * dx  # noqa: E731 (the domain is whole cells)
    width = 2.0 * cells(max(0.3, HALF_WIDTH * (2.0 + 2.5 * aspect)))
    centre = 0.5 * width
    scene["domain"] = {"min": [0, 0], "max": [width, cells(height + 0.2)]}
    scene["view"] = {"min": [0, 0], "max": [width, height + 0.05]}
    scene["dx"] = dx
    scene["frames"] = frames
    scene["boundary"]["sticky_floor_cells"] = sticky_cells
    # Both set or removed here, whatever scenes/sand_column_2d.json says (it has a Coulomb floor and AFLIP).
    scene["boundary"].pop("floor_friction", None)
    scene.pop("transfer", None)
    if floor_friction is not None:
        scene["boundary"]["floor_friction"] = floor_friction
    if flip_relaxation_time > 0.0:
        scene["transfer"] = {"flip_relaxation_time": flip_relaxation_time}
    obj = scene["objects"][0]
    obj["min"] = [centre - HALF_WIDTH, floor]
    obj["max"] = [centre + HALF_WIDTH, floor + height]
    obj["material"]["plasticity"]["friction_angle_deg"] = angle
    obj["model"] = str(MODEL)
    return scene


def extent(frame: Path) -> float:
    """The PERCENTILE-th percentile of |x - x_c| over the particles of a frame (equal masses)."""
    x = read_particle_positions(frame)[:, 0]
    return float(np.percentile(np.abs(x - x.mean()), PERCENTILE))


def runout(run: Path) -> float:
    """L_inf: L0 plus how far the extent grew from the first frame to the last (the first frame's extent is
    below L0 by the particles' spacing and the percentile, the same offset as the last one's)."""
    frames = sorted(run.glob("frame_*.ply"))
    return HALF_WIDTH + extent(frames[-1]) - extent(frames[0])


def simulate(pnet: Path, scene_file: Path, out: Path, integrator: str, dt: float | None,
             newton_tolerance: float | None = None, time_integrator: str | None = None) -> float:
    """Runs one simulation unless `out` holds a finished one of the same scene, integrator, step, Newton
    tolerance and time integrator (implicit runs; None: the scene's); the wall seconds (the recorded ones if
    reused)."""
    tolerance = f"\n{newton_tolerance}" if newton_tolerance is not None else ""
    tolerance += f"\n{time_integrator}" if time_integrator is not None else ""
    key = hashlib.sha256(f"{scene_file.read_text()}\n{integrator}\n{dt}{tolerance}".encode()).hexdigest()
    done = out / "done"
    if done.exists() and done.read_text().split()[1:] == [key]:
        return float(done.read_text().split()[0])
    options = []
    if newton_tolerance is not None:
        options += ["--newton-tol", f"{newton_tolerance:g}"]
    if time_integrator is not None:
        options += ["--time-integrator", time_integrator]
    cmd = launch.simulate_command(pnet, scene_file, out, integrator=integrator, threads=1, overwrite=True,
                                  dt=None if dt is None else f"{dt:g}", options=options)
    finished = launch.run(cmd)
    if finished.status != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({finished.status}):\n{finished.output[-2000:]}")
    wall = round(finished.wall_s, 1)
    done.write_text(f"{wall:.1f} {key}")
    return wall


def floor_friction(floor: str, angle: float) -> float | None:
    """--floor's mu at `angle` degrees (None: sticky)."""
    if floor == "sticky":
        return None
    if floor == "tan":
        return math.tan(math.radians(angle))
    try:
        mu = float(floor)
    except ValueError:
        raise SystemExit(f"--floor: expected 'tan', 'sticky' or a friction coefficient >= 0, got {floor!r}")
    if not mu >= 0.0:
        raise SystemExit(f"--floor: a friction coefficient must be >= 0, got {floor!r}")
    return mu


def floor_description(floor: str) -> str:
    if floor == "sticky":
        return "the sticky floor layer"
    if floor == "tan":
        return "Coulomb, mu = tan(friction angle)"
    return f"Coulomb, mu = {float(floor):g}"


# --dt-study: each variant's run-out against the step, explicit and plasticitynet (docs/methods.md).
STUDY_VARIANTS = {  # name: (floor, flip relaxation time)
    "APIC, sticky floor": ("sticky", 0.0),
    "APIC, Coulomb floor": ("tan", 0.0),
    "AFLIP 0.01 s, sticky floor": ("sticky", 0.01),
    "AFLIP 0.01 s, Coulomb floor": ("tan", 0.01),
}
STUDY_STEPS = [("explicit", None), ("explicit", 1e-4), ("explicit", 2e-5), ("explicit", 1e-5),
               ("plasticitynet", 1e-3), ("plasticitynet", 2.5e-4)]


def dt_study(args, pnet: Path) -> int:
    """Runs every variant at every step for each (angle, aspect) and writes OUT/dt_study.md."""
    jobs = []
    for angle in args.angles:
        for aspect in args.aspects:
            for variant, (floor, tau) in STUDY_VARIANTS.items():
                folder = args.work / f"phi{angle:g}_a{aspect:g}" / variant.replace(" ", "_").replace(",", "")
                folder.mkdir(parents=True, exist_ok=True)
                scene_file = folder / "scene.json"
                scene = scene_for(angle, aspect, args.dx, args.frames, args.sticky_floor_cells,
                                  floor_friction(floor, angle), tau)
                scene_file.write_text(json.dumps(scene, indent=2))
                for integrator, dt in STUDY_STEPS:
                    name = f"{integrator}_{'cfl' if dt is None else f'{dt:g}'}"
                    jobs.append(((angle, aspect, variant, integrator, dt), scene_file, folder / name, integrator, dt))
    def finished(out: Path, wall: float) -> tuple[float, float]:
        return (runout(out) - HALF_WIDTH) / HALF_WIDTH, wall

    results = launch.run_all(
        [(j[0], lambda j=j: finished(j[2], simulate(pnet, j[1], j[2], j[3], j[4]))) for j in jobs], args.jobs,
        lambda done, total, key, r: print(f"[{done}/{total}] {key}: run-out {r[0]:.3f} ({r[1]:.0f} s)", flush=True))
    heads = [f"{i} {'CFL' if dt is None else f'{dt:g} s'}" for i, dt in STUDY_STEPS]
    lines = ["# Granular collapse run-out against the step (scripts/granular_collapse.py --dt-study)", "",
             f"Run-out (L_inf - L0) / L0 as in runout.md, {args.frames} frames of 0.02 s, dx = {args.dx:g} m; Coulomb "
             "floor mu = tan(friction angle); plasticitynet with the parametric sand model. A run-out that does "
             "not settle as the explicit step shrinks means the explicit ground truth depends on its step.", "",
             "| angle | a | variant | " + " | ".join(heads) + " |", "|---|---|---|" + "---|" * len(heads)]
    for angle in args.angles:
        for aspect in args.aspects:
            for variant in STUDY_VARIANTS:
                cells = [f"{results[(angle, aspect, variant, i, dt)][0]:.3f}" for i, dt in STUDY_STEPS]
                lines.append(f"| {angle:g} | {aspect:g} | {variant} | " + " | ".join(cells) + " |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "dt_study.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--angles", type=float, nargs="+", default=[20, 25, 30, 35, 40], help="friction angles, deg")
    p.add_argument("--aspects", type=float, nargs="+", default=[0.5, 1, 2, 4, 8], help="aspect ratios H / L0")
    p.add_argument("--dx", type=float, default=1 / 128, help="grid spacing, m (1/128)")
    p.add_argument("--frames", type=int, default=50, help="frames of 0.02 s (50: 1 s)")
    p.add_argument("--sticky-floor-cells", type=int, default=3,
                   help="grid rows of the sticky floor the column stands on (3, as scenes/sand_column_2d.json)")
    p.add_argument("--floor", default="tan",
                   help="the floor: 'tan' (default), a Coulomb floor of mu = tan(friction angle), a rough bed of the "
                        "sand's own friction; a number, that mu at every angle; 'sticky', the sticky floor layer")
    p.add_argument("--flip-relaxation-time", type=float, default=0.01,
                   help="AFLIP transfers' relaxation time, s (0.01; 0: APIC). With APIC and the sticky floor the "
                        "explicit run-out does not converge as dt shrinks (docs/methods.md)")
    p.add_argument("--ground-truth-dt", type=float, default=2e-5, help="explicit ground-truth step, s (2e-5)")
    p.add_argument("--newton-tolerance", type=float, default=None,
                   help="plasticitynet's Newton tolerance, m/s (default: the scene's, 1e-3 with 1 m/s^2 x dt below "
                        "1e-3 s; docs/solver.md: a tall column's run-out needs ~1e-4 to converge)")
    p.add_argument("--implicit-dt", type=float, default=1e-3, help="plasticitynet's step, s (1e-3)")
    p.add_argument("--time-integrator", choices=("backward_euler", "bdf2"), default=None,
                   help="plasticitynet's time integrator (default: the scene's, backward_euler)")
    p.add_argument("--jobs", type=int, default=2, help="simulations at once (one thread each)")
    p.add_argument("--dt-study", action="store_true",
                   help="instead of the sweep: the run-out of APIC / AFLIP transfers on a sticky / Coulomb floor, "
                        "explicit at CFL, 1e-4, 2e-5, 1e-5 s and plasticitynet at 1e-3, 2.5e-4 s (OUT/dt_study.md)")
    p.add_argument("--work", type=Path, default=ROOT / "out" / "granular_collapse")  # runs keyed by their scene
    p.add_argument("--out", type=Path, default=ROOT / "notebooks" / "results" / "granular_collapse")
    args = p.parse_args()
    floor_friction(args.floor, 30.0)  # a bad --floor fails before any run
    pnet = ROOT / os.environ.get("PNET_BUILD_DIR", "build") / "cpp" / "pnet"
    if not pnet.exists():
        p.error(f"{pnet}: not built (./scripts/setup.sh)")
    if not MODEL.exists():
        p.error(f"{MODEL}: no parametric sand model (python train.py --material sand --dim 2 --parametric)")
    if args.dt_study:
        return dt_study(args, pnet)
    runs = {
        "ground_truth": ("explicit", args.ground_truth_dt),
        "explicit_cfl": ("explicit", None),
        "plasticitynet": ("plasticitynet", args.implicit_dt),
    }
    jobs = []
    for angle in args.angles:
        for aspect in args.aspects:
            folder = args.work / f"phi{angle:g}_a{aspect:g}"
            folder.mkdir(parents=True, exist_ok=True)
            scene_file = folder / "scene.json"
            mu = floor_friction(args.floor, angle)
            scene_file.write_text(json.dumps(scene_for(angle, aspect, args.dx, args.frames, args.sticky_floor_cells, mu,
                                                       args.flip_relaxation_time), indent=2))
            for name, (integrator, dt) in runs.items():
                jobs.append((angle, aspect, name, scene_file, folder / name, integrator, dt))
    # The longest first (tall columns, small steps), so that the pool ends together.
    jobs.sort(key=lambda j: -(j[1] * (50.0 if j[2] == "ground_truth" else 1.0)))
    def run_one(job) -> dict:
        angle, aspect, name, scene_file, out, integrator, dt = job
        extra = (args.newton_tolerance, args.time_integrator) if integrator == "plasticitynet" else ()
        wall = simulate(pnet, scene_file, out, integrator, dt, *extra)
        L = runout(out)
        return {"angle": angle, "aspect": aspect, "integrator": name, "L_inf": L,
                "runout": (L - HALF_WIDTH) / HALF_WIDTH, "wall_seconds": wall}

    def report(done: int, total: int, key, row: dict) -> None:
        print(f"[{done}/{total}] phi {row['angle']:g} a {row['aspect']:g} {row['integrator']}: run-out "
              f"{row['runout']:.3f} ({row['wall_seconds']:.0f} s)", flush=True)

    rows = list(launch.run_all([(j[:3], lambda j=j: run_one(j)) for j in jobs], args.jobs, report).values())
    rows.sort(key=lambda r: (r["angle"], r["aspect"], r["integrator"]))
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "runout.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    table = {(r["angle"], r["aspect"], r["integrator"]): r for r in rows}
    tolerance = "the default (1e-3 m/s)" if args.newton_tolerance is None else f"{args.newton_tolerance:g} m/s"
    lines = [
        "# Granular column collapse with one parametric model (scripts/granular_collapse.py)", "",
        f"Run-out (L_inf - L0) / L0, L0 = {HALF_WIDTH} m, L_inf = L0 + e(last) - e(first), e the {PERCENTILE}th "
        f"percentile of |x - x_c| on a frame ({args.frames} frames of 0.02 s), dx = {args.dx:g} m. Ground truth: explicit at "
        f"{args.ground_truth_dt:g} s; floor: |explicit at CFL - ground truth|; plasticitynet at {args.implicit_dt:g} s "
        f"({args.time_integrator or 'backward_euler'}) with "
        f"{MODEL.name} bound to each angle, Newton tolerance {tolerance}. Floor: {floor_description(args.floor)}; "
        "transfers: "
        f"{'AFLIP, relaxation time %g s' % args.flip_relaxation_time if args.flip_relaxation_time > 0 else 'APIC'} "
        f"(docs/methods.md).", "",
        "| friction angle | a = H / L0 | ground truth | explicit CFL | plasticitynet | plasticitynet error | floor | "
        "within floor | plasticitynet vs explicit CFL | wall s (GT / CFL / pnet) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    within, to_cfl = [], []
    for angle in args.angles:
        for aspect in args.aspects:
            gt, cfl, pn = (table[(angle, aspect, k)] for k in runs)
            err, floor = abs(pn["runout"] - gt["runout"]), abs(cfl["runout"] - gt["runout"])
            within.append(err <= floor)
            to_cfl.append((pn["runout"] - cfl["runout"]) / cfl["runout"])
            lines.append(f"| {angle:g} | {aspect:g} | {gt['runout']:.3f} | {cfl['runout']:.3f} | {pn['runout']:.3f} | "
                         f"{err:.3f} | {floor:.3f} | {'yes' if err <= floor else 'no'} | {100 * to_cfl[-1]:+.1f}% | "
                         f"{gt['wall_seconds']:.0f} / {cfl['wall_seconds']:.0f} / {pn['wall_seconds']:.0f} |")
    gaps = sorted(abs(g) for g in to_cfl)
    lines += ["", f"plasticitynet within the floor in {sum(within)} of {len(within)} cases; its run-out differs from "
              f"explicit at CFL by {100 * gaps[len(gaps) // 2]:.1f}% (median) and at most {100 * gaps[-1]:.1f}%."]
    (args.out / "runout.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for k, angle in enumerate(args.angles):
        color = plt.cm.viridis(k / max(1, len(args.angles) - 1))
        labels = {"ground_truth": f"explicit {args.ground_truth_dt:g}", "explicit_cfl": "explicit CFL",
                  "plasticitynet": f"plasticitynet {args.implicit_dt:g}"}
        for name, style in (("ground_truth", "-o"), ("explicit_cfl", ":+"), ("plasticitynet", "--x")):
            ax.plot(args.aspects, [table[(angle, a, name)]["runout"] for a in args.aspects], style, color=color,
                    label=f"{angle:g} deg, {labels[name]}")
    a = np.array(args.aspects)
    ax.plot(a, 1.2 * a, ":", color="gray", label="~a")
    ax.plot(a, 1.9 * a ** (2 / 3), "-.", color="gray", label="~a^(2/3)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("aspect ratio a = H / L0")
    ax.set_ylabel("run-out (L_inf - L0) / L0")
    ax.legend(fontsize=5, ncol=3)
    fig.tight_layout()
    fig.savefig(args.out / "runout.png", dpi=130)
    return 0


if __name__ == "__main__":
    sys.exit(main())
