#!/usr/bin/python3
"""Accuracy and speed of the implicit MPM integrators against the explicit ground truth (issue 6).

For each scene it runs `pnet simulate` with
  gt                 explicit, dt = 1e-5 s (the paper's ground truth; 1e-6 s for the stiff variants
                     scenes/stiff/, whose CFL step is 10x smaller)
  explicit_cfl       explicit at its CFL step
  plasticitynet_1e-3, plasticitynet_1e-4, lagged_1e-3
and, for sand_column_2d (group "ablation"), plasticitynet at 1e-3 with the
regularizer off (w = 0) and with 1, 2, 4 and converged fixed-point iterations on
F0, and (group "representation") the energy forms of the paper's Fig. 11 (scripts/train_ablation_models.sh).
Every run is compared with the ground truth frame by frame (`pnet compare`:
soft IoU = sum min / sum max of the B-spline mass fields, and binary IoU).

Outputs (under --results, default notebooks/results/implicit_eval):
  summary.csv, summary.md        per scene and run: dt, seconds per frame, mean Newton /
                                 CG / fixed-point iterations per step, min and mean IoU
  <scene>/iou.csv, iou.png       per-frame soft IoU of every run (one curve each)
  <scene>/<run>_stats.csv, <run>_steps.csv (implicit runs), <run>_final.png (and with --keep-frames,
                                 <run>_frame_NNNNN.png)
The full runs (PLY of every frame) stay in --work (default out/eval); a run whose
directory holds all its frames from the same command and scene file is reused, not
re-run (pass --force after changing the simulator; command.json records the commit).
Each invocation rewrites the results of the scenes it runs; summary.csv/md gather
every scene under --results.

    /usr/bin/python3 scripts/evaluate_implicit.py [--scenes sand_column_2d snowball_2d]
        [--groups main ablation] [--frames N] [--threads 2] [--force]
"""
import argparse
import csv
import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PNET = ROOT / "build" / "cpp" / "pnet"

# The stiff variants (scenes/stiff/, issue 19: E x100) have a CFL step 10x smaller than the canonical
# scenes; their ground truth and noise-floor runs are 10x finer too.
SOFT = {"sand_column_2d", "snowball_2d", "sand_column_3d", "snowball_3d"}
STIFF = {"stiff/sand_column_2d", "stiff/snowball_2d"}

# name: (integrator, dt, extra pnet options, group, scenes it applies to (None: all)); the ground
# truth's dt (None) is gt_step(scene).
RUNS = {
    "gt": ("explicit", None, [], "main", None),
    "explicit_2e-5": ("explicit", 2e-5, [], "floor", SOFT),
    "explicit_2e-6": ("explicit", 2e-6, [], "floor", STIFF),
    "explicit_cfl": ("explicit", 0.0, [], "main", None),
    "plasticitynet_1e-3": ("plasticitynet", 1e-3, [], "main", None),
    "plasticitynet_1e-4": ("plasticitynet", 1e-4, [], "main", None),
    "lagged_1e-3": ("lagged", 1e-3, [], "main", None),
    # BDF2 (issue 34) beside backward Euler.
    "plasticitynet_1e-3_bdf2": ("plasticitynet", 1e-3, ["--time-integrator", "bdf2"], "time_integrator", None),
    "lagged_1e-3_bdf2": ("lagged", 1e-3, ["--time-integrator", "bdf2"], "time_integrator", None),
    "plasticitynet_1e-3_w0": ("plasticitynet", 1e-3, ["--regularizer", "0"], "ablation", {"sand_column_2d"}),
    "plasticitynet_1e-3_fp1": ("plasticitynet", 1e-3, ["--fixed-point-iterations", "1"], "ablation", None),
    "plasticitynet_1e-3_fp2": ("plasticitynet", 1e-3, ["--fixed-point-iterations", "2", "--fixed-point-tol", "0"],
                               "ablation", {"sand_column_2d"}),
    "plasticitynet_1e-3_fp4": ("plasticitynet", 1e-3, ["--fixed-point-iterations", "4", "--fixed-point-tol", "0"],
                               "ablation", {"sand_column_2d"}),
    "plasticitynet_1e-3_fp8_tol1e-3": ("plasticitynet", 1e-3,
                                       ["--fixed-point-iterations", "8", "--fixed-point-tol", "1e-3"], "ablation", None),
    "plasticitynet_1e-3_fp8_tol1e-4": ("plasticitynet", 1e-3,
                                       ["--fixed-point-iterations", "8", "--fixed-point-tol", "1e-4"], "ablation", None),
    # Issue 19: the converged fixed point's cost (solves after the first start from the kept Hessian;
    # Anderson acceleration of the outer loop over 3 iterates) against today's default.
    "plasticitynet_1e-3_plain": ("plasticitynet", 1e-3,
                                 ["--fixed-point-anderson", "0", "--fixed-point-keep-hessian", "no"], "fixed_point",
                                 None),
    "plasticitynet_1e-3_keep": ("plasticitynet", 1e-3,
                                ["--fixed-point-anderson", "0", "--fixed-point-keep-hessian", "yes"], "fixed_point",
                                None),
    "plasticitynet_1e-3_anderson3": ("plasticitynet", 1e-3,
                                     ["--fixed-point-anderson", "3", "--fixed-point-keep-hessian", "no"],
                                     "fixed_point", None),
    "plasticitynet_1e-3_keep_anderson3": ("plasticitynet", 1e-3,
                                          ["--fixed-point-anderson", "3", "--fixed-point-keep-hessian", "yes"],
                                          "fixed_point", None),
    "plasticitynet_1e-3_fpconv": ("plasticitynet", 1e-3,
                                  ["--fixed-point-iterations", "100", "--fixed-point-tol", "1e-5"], "ablation",
                                  {"sand_column_2d"}),
}

# The energy-representation ablation (paper sec. 5.2, Fig. 11; group "representation"): the 2D sand energy
# in eq. 8's form and in the three forms the paper rejected, all four trained with one recipe
# (scripts/train_ablation_models.sh), each replacing the scene's model (pnet simulate --model).
ENERGY_FORMS = ("eq8", "local_identity", "global_identity", "global")
for _form in ENERGY_FORMS:
    RUNS[f"form_{_form}_1e-3"] = ("plasticitynet", 1e-3, ["--model", str(ROOT / "models" / "ablation" / f"sand_2d_{_form}.pt")],
                                  "representation", {"sand_column_2d"})


def gt_step(scene: str) -> float:
    """The ground truth's step: the paper's 1e-5 s, 1e-6 s for the stiff variants."""
    return 1e-6 if scene in STIFF else 1e-5


def run_step(scene: str, name: str) -> float:
    return gt_step(scene) if name == "gt" else RUNS[name][1]


def without_threads(command: list) -> list:
    """The command without --threads N: frames are bit-identical at 1 and 2 threads (the C++ tests
    OneAndTwoThreads...), so the thread count is not part of what a run computes."""
    if "--threads" not in command:
        return command
    t = command.index("--threads")
    return command[:t] + command[t + 2:]


def run_marker(scene: str, command: list, explicit: bool) -> dict:
    """What a run's result depends on besides the simulator: the command and the scene file (for an
    explicit run without its "integrator" block, which only sets the implicit solvers)."""
    scene_json = json.loads((ROOT / "scenes" / f"{scene}.json").read_text())
    scene_json.pop("description", None)  # prose
    if explicit:
        scene_json.pop("integrator", None)
    scene_sha = hashlib.sha256(json.dumps(scene_json, sort_keys=True).encode()).hexdigest()
    # The binary and the output folder are not part of what a run computes (a run may be reused from
    # another work folder through a link, or made by an older binary when only the implicit code changed).
    i = command.index("--out")
    command = without_threads(command[2:i] + command[i + 2:])
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    marker = {"command": command, "scene_sha256": scene_sha, "commit": commit}  # commit: for the record only
    if not explicit:  # an implicit run also depends on its model files (retrained models are re-run)
        scene_dir = (ROOT / "scenes" / f"{scene}.json").parent  # model paths are relative to the scene file
        if "--model" in command:  # one model replaces the scene's
            model = Path(command[command.index("--model") + 1])
            files = {model.name: model}
        else:
            files = {o["model"]: scene_dir / o["model"]
                     for o in scene_json.get("objects", []) + scene_json.get("meshes", []) if "model" in o}
        marker["models"] = {key: hashlib.sha256(path.read_bytes()).hexdigest() for key, path in files.items()}
    return marker


def run_dir_complete(out: Path, marker: dict, frames: int) -> bool:
    path = out / "command.json"
    if not path.exists() or not (out / f"frame_{frames:05d}.ply").exists():
        return False
    old = json.loads(path.read_text())
    if isinstance(old, dict) and isinstance(old.get("command"), list):  # markers written before threads were dropped
        old["command"] = without_threads(old["command"])
    return isinstance(old, dict) and all(old.get(k) == marker.get(k) for k in ("command", "scene_sha256", "models"))


def simulate(scene: str, name: str, frames: int, threads: int, work: Path, force: bool, pnet: Path = None) -> Path:
    integrator, _, extra, _, _ = RUNS[name]
    dt = run_step(scene, name)
    out = work / scene / name
    command = [str(pnet or PNET), "simulate", str(ROOT / "scenes" / f"{scene}.json"), "--integrator", integrator,
               "--dt", repr(dt), "--frames", str(frames), "--threads", str(threads), "--out", str(out)] + extra
    marker = run_marker(scene, command, integrator == "explicit")
    if not force and run_dir_complete(out, marker, frames):
        print(f"[{scene}/{name}] reusing {out}", flush=True)
        return out
    if out.is_symlink():
        sys.exit(f"{out} links to an incomplete or outdated run ({out.resolve()}); remove the link to re-run it here")
    if out.exists():
        shutil.rmtree(out)
    print(f"[{scene}/{name}] " + " ".join(command), flush=True)
    result = subprocess.run(command)
    if result.returncode != 0:
        print(f"[{scene}/{name}] pnet simulate exited with {result.returncode}; the frames it wrote are compared",
              flush=True)
    else:
        (out / "command.json").write_text(json.dumps(marker))
    return out


def compare(gt: Path, run: Path, dx: float, pnet: Path = PNET) -> list:
    out = run / "compare_gt"
    subprocess.run([str(pnet), "compare", str(gt), str(run), "--out", str(out), "--dx", repr(dx)], check=True,
                   stdout=subprocess.DEVNULL)
    with open(out / "iou.csv") as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def read_csv(path: Path) -> list:
    with open(path) as f:
        return list(csv.DictReader(f))


def run_figures(run: Path) -> dict:
    frames = read_csv(run / "stats.csv")
    steps = read_csv(run / "steps.csv")
    n_steps = max(len(steps), 1)
    mean = lambda key: sum(float(s[key]) for s in steps) / n_steps
    return {
        "frames": len(frames),
        "seconds_per_frame": sum(float(f["wall_s"]) for f in frames) / max(len(frames), 1),
        "steps_per_frame": n_steps / max(len(frames), 1),
        "newton_per_step": mean("newton_iterations"),
        "cg_per_step": mean("cg_iterations"),
        "fixed_point_per_step": mean("fixed_point_iterations"),
        "line_search_per_step": mean("line_search_steps"),
        "energy_seconds_share": sum(float(s["energy_s"]) for s in steps) / max(sum(float(s["wall_s"]) for s in steps), 1e-300),
        "cg_seconds_share": sum(float(s["cg_s"]) for s in steps) / max(sum(float(s["wall_s"]) for s in steps), 1e-300),
        "unconverged_steps": sum(1 for s in steps if s["converged"] == "0"),
    }


def plot_scene(scene: str, curves: dict, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    for name, rows in curves.items():
        ax.plot([r["time_s"] for r in rows], [r["soft_iou"] for r in rows], label=name,
                linestyle="--" if "explicit" in name else "-")
    target = 0.9 if "sand" in scene else 0.85
    ax.axhline(target, color="grey", linewidth=0.8, linestyle=":", label=f"target {target}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"soft IoU vs explicit dt {gt_step(scene):g}")
    ax.set_title(scene)
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=["sand_column_2d", "snowball_2d"],
                        help="scene names under scenes/ (stiff/sand_column_2d: a stiff variant)")
    parser.add_argument("--groups", nargs="+", default=["main", "floor"], choices=["main", "floor", "ablation", "fixed_point", "representation", "time_integrator"])
    parser.add_argument("--runs", nargs="+", help="only these runs (names as in the summary; gt is always run)")
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "eval")
    parser.add_argument("--results", type=Path, default=ROOT / "notebooks" / "results" / "implicit_eval")
    parser.add_argument("--force", action="store_true", help="re-run even when a complete run exists")
    parser.add_argument("--pnet", type=Path, default=PNET, help="the pnet binary that simulates and compares (default: the build's; a copy lets "
                             "the build relink while an evaluation runs)")
    parser.add_argument("--simulate-only", action="store_true", help="run the simulations, compare nothing")
    parser.add_argument("--keep-frames", nargs="+", type=int, default=[],
                        help="also copy these frames' pictures of every run into --results (<run>_frame_NNNNN.png)")
    args = parser.parse_args()
    if not args.pnet.exists():
        sys.exit(f"{args.pnet} not found: build first (./scripts/setup.sh)")

    args.results.mkdir(parents=True, exist_ok=True)
    summary = []
    for scene in args.scenes:
        scene_json = json.loads((ROOT / "scenes" / f"{scene}.json").read_text())
        dx = scene_json["dx"]
        names = [n for n, (_, _, _, group, only) in RUNS.items()
                 if group in args.groups and (only is None or scene in only)
                 and (n == "gt" or not args.runs or n in args.runs)]
        gt = simulate(scene, "gt", args.frames, args.threads, args.work, args.force, args.pnet)
        if args.simulate_only:
            for name in names:
                if name != "gt":
                    simulate(scene, name, args.frames, args.threads, args.work, args.force, args.pnet)
            continue
        curves = {}
        results = args.results / scene.replace("/", "_")  # stiff/x -> stiff_x
        results.mkdir(parents=True, exist_ok=True)
        for name in names:
            run = gt if name == "gt" else simulate(scene, name, args.frames, args.threads, args.work, args.force,
                                                   args.pnet)
            figures = run_figures(run)
            # Per-step rows of an explicit run hold only timings (100k rows for the ground
            # truth); its per-frame stats.csv is kept, steps.csv stays in --work.
            explicit = RUNS[name][0] == "explicit"
            for f in ("stats.csv",) if explicit else ("stats.csv", "steps.csv"):
                shutil.copyfile(run / f, results / f"{name}_{f}")
            last = sorted(run.glob("frame_*.png"))[-1]
            shutil.copyfile(last, results / f"{name}_final.png")
            for frame in args.keep_frames:  # a run that stopped early has fewer
                picture = run / f"frame_{frame:05d}.png"
                if picture.exists():
                    shutil.copyfile(picture, results / f"{name}_{picture.name}")
            row = {"scene": scene, "run": name, "integrator": RUNS[name][0], "dt": run_step(scene, name),
                   **figures}
            if name != "gt":
                rows = compare(gt, run, dx, args.pnet)
                curves[name] = rows
                soft = [r["soft_iou"] for r in rows]
                binary = [r["binary_iou"] for r in rows]
                coarse = [r["soft_iou_coarse"] for r in rows]
                last = rows[-1]  # the deposit at the last common frame (docs/metrics.md)
                row.update({"soft_iou_min": min(soft), "soft_iou_mean": sum(soft) / len(soft),
                            "binary_iou_min": min(binary), "binary_iou_mean": sum(binary) / len(binary),
                            "soft_iou_coarse_min": min(coarse), "soft_iou_coarse_mean": sum(coarse) / len(coarse),
                            "spread_m": last["spread_b_m"], "spread_gt_m": last["spread_a_m"],
                            "spread_error": last["spread_b_m"] / last["spread_a_m"] - 1.0,
                            "height_m": last["height_b_m"], "height_gt_m": last["height_a_m"],
                            "height_error": last["height_b_m"] / last["height_a_m"] - 1.0,
                            "compared_frames": len(rows)})
            summary.append(row)
            print(json.dumps(row), flush=True)
        if curves:
            frames = sorted({int(r["frame"]) for rows in curves.values() for r in rows})
            with open(results / "iou.csv", "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["frame", "time_s"] + list(curves))
                for frame in frames:
                    values = []
                    for rows in curves.values():
                        match = [r["soft_iou"] for r in rows if int(r["frame"]) == frame]
                        values.append(f"{match[0]:.6f}" if match else "")
                    w.writerow([frame, f"{frame * scene_json.get('frame_dt', 0.02):.4f}"] + values)
            plot_scene(scene, curves, results / "iou.png")
        (results / "summary.json").write_text(json.dumps([r for r in summary if r["scene"] == scene], indent=1))

    # Every scene evaluated so far (this invocation or an earlier one, e.g. 3D with fewer frames).
    summary = [r for path in sorted(args.results.glob("*/summary.json")) for r in json.loads(path.read_text())]

    keys = ["scene", "run", "integrator", "dt", "frames", "compared_frames", "seconds_per_frame", "steps_per_frame",
            "newton_per_step", "cg_per_step", "fixed_point_per_step", "line_search_per_step",
            "energy_seconds_share", "cg_seconds_share", "unconverged_steps", "soft_iou_min", "soft_iou_mean",
            "binary_iou_min", "binary_iou_mean", "soft_iou_coarse_min", "soft_iou_coarse_mean", "spread_m",
            "spread_gt_m", "spread_error", "height_m", "height_gt_m", "height_error"]
    with open(args.results / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for row in summary:
            w.writerow(row)
    lines = ["| scene | run | dt (s) | frames | s/frame | Newton/step | line search/step | fixed-point/step | "
             "unconverged steps | J min / mean | J(4dx) min / mean | spread vs GT | height vs GT |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in summary:
        if "soft_iou_coarse_min" in r:
            metrics = (f"{r['soft_iou_min']:.3f} / {r['soft_iou_mean']:.3f} | {r['soft_iou_coarse_min']:.3f} / "
                       f"{r['soft_iou_coarse_mean']:.3f} | {100 * r['spread_error']:+.1f}% | "
                       f"{100 * r['height_error']:+.1f}%")
        else:
            metrics = "(reference) | (reference) | (reference) | (reference)"
        dt = "CFL" if r["dt"] == 0 else f"{r['dt']:g}"
        implicit = r["integrator"] != "explicit"
        solver = (f"{r['newton_per_step']:.2f} | {r['line_search_per_step']:.2f} | {r['fixed_point_per_step']:.2f} | "
                  f"{r['unconverged_steps']}") if implicit else "- | - | - | -"
        lines.append(f"| {r['scene']} | {r['run']} | {dt} | {r['frames']} | {r['seconds_per_frame']:.2f} | "
                     f"{solver} | {metrics} |")
    (args.results / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
