"""Writing a study's or a sweep's results folder from its metrics (docs/workflow.md).

Studies keep the layout the notebooks read (notebooks/results/<study>/):
  mpm       summary.md, summary.csv; <scene>/iou.csv, iou.png, <run>_stats.csv, <run>_steps.csv (implicit
            runs), <run>_final.png, summary.json
  fem       summary.md, summary.csv; <scene>/nodal_error.csv, nodal_error.png, <run>_stats.csv, <run>_final.png
  coupling  summary.md, summary.csv, per_frame.csv, iou_<run>.png, <run>_final.png
Sweeps (notebooks/results/sweeps/<scene>_dt, <scene>_dx): summary.md, summary.csv, <name>.png.
"""
from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

from .metrics import run_figures
from .plan import Plan, StudyJob, SweepJob


def _fmt_dt(dt: float) -> str:
    return "CFL" if dt == 0 else f"{dt:g}"


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _copy(src: Path, dst: Path) -> None:
    if src.exists():
        shutil.copyfile(src, dst)


def _last_picture(run: Path) -> Path | None:
    pictures = sorted((run / "frames").glob("frame_*.png"))
    return pictures[-1] if pictures else None


def _write_csv(path: Path, keys: list[str], rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r.get(k), float) else r.get(k, "")) for k in keys})


def _record(path: Path, what: dict) -> None:
    """The work folder's record of a study or sweep: the runs and metrics it was made from."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(what, indent=1))
    tmp.replace(path)


def write_study(plan: Plan, name: str) -> None:
    job = plan.studies[name]
    folder = plan.results / name
    folder.mkdir(parents=True, exist_ok=True)
    {"mpm": _mpm_study, "fem": _fem_study, "coupling": _coupling_study}[job.study.family](plan, job, folder)
    _record(plan.study_record(name), {"runs": job.runs, "metrics": job.metrics})


def _metric(plan: Plan, key: str) -> dict:
    return json.loads(plan.metric_file(key).read_text())


def _rows(plan: Plan, job: StudyJob, scene: str) -> list[tuple[str, Path, dict | None]]:
    """(run name, run folder, metric or None for the ground truth) of a scene, in the catalogue's order."""
    out = []
    for name, key in job.runs[scene].items():
        metric = _metric(plan, job.metrics[scene][name]) if name in job.metrics[scene] else None
        out.append((name, plan.run_dir(key), metric))
    return out


# --- MPM -------------------------------------------------------------------------------------------------
MPM_KEYS = ["scene", "run", "integrator", "dt", "frames", "compared_frames", "seconds_per_frame", "steps_per_frame",
            "newton_per_step", "cg_per_step", "fixed_point_per_step", "line_search_per_step", "energy_seconds_share",
            "cg_seconds_share", "unconverged_steps", "soft_iou_min", "soft_iou_mean", "binary_iou_min",
            "binary_iou_mean", "soft_iou_coarse_min", "soft_iou_coarse_mean", "spread_m", "spread_gt_m",
            "spread_error", "height_m", "height_gt_m", "height_error"]


def mpm_row(plan: Plan, scene: str, name: str, run: Path, metric: dict | None) -> dict:
    key = run.name
    job = plan.runs[key]
    row = {"scene": scene, "run": name, "integrator": job.integrator, "dt": job.dt, **run_figures(run)}
    if metric:
        row.update({k: v for k, v in metric.items() if k in MPM_KEYS})
    return row


def mpm_table(rows: list[dict]) -> str:
    lines = ["| scene | run | dt (s) | frames | s/frame | Newton/step | line search/step | fixed-point/step | "
             "unconverged steps | J min / mean | J(4dx) min / mean | spread vs GT | height vs GT |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "soft_iou_coarse_min" in r:
            metrics = (f"{r['soft_iou_min']:.3f} / {r['soft_iou_mean']:.3f} | {r['soft_iou_coarse_min']:.3f} / "
                       f"{r['soft_iou_coarse_mean']:.3f} | {100 * r['spread_error']:+.1f}% | "
                       f"{100 * r['height_error']:+.1f}%")
        else:
            metrics = "(reference) | (reference) | (reference) | (reference)"
        solver = (f"{r['newton_per_step']:.2f} | {r['line_search_per_step']:.2f} | {r['fixed_point_per_step']:.2f} | "
                  f"{r['unconverged_steps']}") if r["integrator"] != "explicit" else "- | - | - | -"
        lines.append(f"| {r['scene']} | {r['run']} | {_fmt_dt(r['dt'])} | {r['frames']} | {r['seconds_per_frame']:.2f} | "
                     f"{solver} | {metrics} |")
    return "\n".join(lines) + "\n"


def _mpm_study(plan: Plan, job: StudyJob, folder: Path) -> None:
    summary = []
    for scene in job.runs:
        out = folder / scene.replace("/", "_")  # stiff/x -> stiff_x
        out.mkdir(parents=True, exist_ok=True)
        curves, scene_rows = {}, []
        for name, run, metric in _rows(plan, job, scene):
            explicit = plan.runs[run.name].integrator == "explicit"
            for f in ("stats.csv",) if explicit else ("stats.csv", "steps.csv"):
                _copy(run / "frames" / f, out / f"{name}_{f}")
            picture = _last_picture(run)
            if picture:
                _copy(picture, out / f"{name}_final.png")
            for frame in job.study.keep_frames:  # a run that stopped early has fewer
                _copy(run / "frames" / f"frame_{frame:05d}.png", out / f"{name}_frame_{frame:05d}.png")
            if metric is not None:
                curves[name] = metric["rows"]
            scene_rows.append(mpm_row(plan, scene, name, run, metric))
        if curves:
            frame_dt = float(plan.scene(scene).content.get("frame_dt", 0.02))
            frames = sorted({int(r["frame"]) for rows in curves.values() for r in rows})
            with open(out / "iou.csv", "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["frame", "time_s"] + list(curves))
                for frame in frames:
                    values = []
                    for rows in curves.values():
                        match = [r["soft_iou"] for r in rows if int(r["frame"]) == frame]
                        values.append(f"{match[0]:.6f}" if match else "")
                    w.writerow([frame, f"{frame * frame_dt:.4f}"] + values)
            _plot_iou(scene, curves, out / "iou.png")
        (out / "summary.json").write_text(json.dumps(scene_rows, indent=1))
        summary += scene_rows
    _write_csv(folder / "summary.csv", MPM_KEYS, summary)
    (folder / "summary.md").write_text(mpm_table(summary))


def _plot_iou(scene: str, curves: dict, path: Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    for name, rows in curves.items():
        ax.plot([r["time_s"] for r in rows], [r["soft_iou"] for r in rows], label=name,
                linestyle="--" if "explicit" in name else "-")
    target = 0.9 if "sand" in scene else 0.85
    ax.axhline(target, color="grey", linewidth=0.8, linestyle=":", label=f"target {target}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("soft IoU vs the explicit ground truth")
    ax.set_title(scene)
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# --- FEM -------------------------------------------------------------------------------------------------
FEM_KEYS = ["scene", "run", "integrator", "dt", "frames", "failed", "seconds_per_frame", "steps_per_frame",
            "newton_per_step", "solves_per_step", "kinematic_stages_per_step", "unconverged_steps",
            "min_contact_distance_m", "last_frame", "final_mean_pct", "final_max_pct", "worst_mean_pct",
            "ref_mean_pct", "ref_max_pct"]


def _fem_study(plan: Plan, job: StudyJob, folder: Path) -> None:
    summary = []
    for scene in job.runs:
        out = folder / scene
        out.mkdir(parents=True, exist_ok=True)
        curves = {}
        for name, run, metric in _rows(plan, job, scene):
            figures = run_figures(run)
            r = plan.runs[run.name]
            row = {"scene": scene, "run": name, "integrator": r.integrator, "dt": r.dt, **figures,
                   "solves_per_step": figures["fixed_point_per_step"]}
            if metric is not None:
                curves[name] = metric["curve"]
                row.update({k: metric[k] for k in ("last_frame", "final_mean_pct", "final_max_pct", "worst_mean_pct",
                                                   "ref_mean_pct", "ref_max_pct") if k in metric})
                picture = _last_picture(run)
                if picture and figures["frames"] > 0:
                    _copy(picture, out / f"{name}_final.png")
            _copy(run / "frames" / "stats.csv", out / f"{name}_stats.csv")
            summary.append(row)
        with open(out / "nodal_error.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["run", "frame", "time_s", "mean_m", "max_m", "mean_pct_diagonal", "max_pct_diagonal"])
            for name, curve in curves.items():
                for c in curve:
                    w.writerow([name, c["frame"], c["time_s"], f"{c['mean_m']:.6g}", f"{c['max_m']:.6g}",
                                f"{c['mean_pct']:.5f}", f"{c['max_pct']:.5f}"])
        _plot_nodal(scene, curves, out / "nodal_error.png")
    _write_csv(folder / "summary.csv", FEM_KEYS, summary)

    def fmt(r, k, spec=".3f"):
        v = r.get(k)
        return "-" if v in (None, "") or v != v else format(float(v), spec)

    lines = ["| scene | run | dt (s) | frames | s/frame | Newton/step | solves/step | unconverged | "
             "mean / max nodal error at the last frame (% diag) | worst mean over frames (% diag) | "
             "to the same-dt reference, mean / max (% diag) | min contact distance (m) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in summary:
        lines.append(f"| {r['scene']} | {r['run']} | {float(r['dt']):g}{' (CFL)' if float(r['dt']) == 0 else ''} | "
                     f"{r['frames']}{' (failed)' if r['failed'] else ''} | {fmt(r, 'seconds_per_frame')} | "
                     f"{fmt(r, 'newton_per_step', '.1f')} | {fmt(r, 'solves_per_step', '.1f')} | "
                     f"{r['unconverged_steps']} | {fmt(r, 'final_mean_pct', '.4f')} / "
                     f"{fmt(r, 'final_max_pct', '.4f')} | {fmt(r, 'worst_mean_pct', '.4f')} | "
                     f"{fmt(r, 'ref_mean_pct', '.4f')} / {fmt(r, 'ref_max_pct', '.4f')} | "
                     f"{fmt(r, 'min_contact_distance_m', '.3g')} |")
    (folder / "summary.md").write_text("\n".join(lines) + "\n")


def _plot_nodal(scene: str, curves: dict, path: Path) -> None:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), dpi=100)
    for name, rows in curves.items():
        t = [r["time_s"] for r in rows]
        axes[0].plot(t, [r["mean_pct"] for r in rows], label=name)
        axes[1].plot(t, [r["max_pct"] for r in rows], label=name)
    for ax, what in zip(axes, ("mean", "max")):
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{what} nodal distance to the ground truth (% of diagonal)")
        ax.grid(alpha=0.3)
    axes[0].axhline(0.5, color="grey", linestyle=":", linewidth=1)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{scene}: nodal error against the ground truth")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# --- coupling --------------------------------------------------------------------------------------------
def _coupling_study(plan: Plan, job: StudyJob, folder: Path) -> None:
    (scene,) = job.runs  # one scene per coupling study
    gt_job = plan.runs[job.runs[scene]["gt"]]
    gt_name = f"explicit_{gt_job.dt:.0e}".replace("e-0", "e-")  # the committed tables' name: explicit_1e-6
    per_frame, summary, size = [], [], None
    for name, run, metric in _rows(plan, job, scene):
        label = gt_name if name == "gt" else name
        figures = run_figures(run)
        picture = _last_picture(run)
        if picture:
            _copy(picture, folder / f"{label}_final.png")
        if metric is None:  # the ground truth: its cost only
            rows = [{"run": label, "frame": f} for f in range(1, figures["frames"] + 1)]
            metric = {"jaccard_min": 1.0, "jaccard_mean": 1.0, "jaccard_4dx_min": 1.0, "jaccard_4dx_mean": 1.0,
                      "disk_mean_pct_last": 0.0, "disk_mean_pct_worst": 0.0, "disk_max_pct_worst": 0.0,
                      "penetrations": None, "rows": []}
        else:
            size = metric["body_size_m"]
            _copy(plan.compare_dir(job.metrics[scene][name]) / "iou.png", folder / f"iou_{label}.png")
            rows = [{"run": label, **r} for r in metric["rows"]]
        per_frame += [r for r in rows if len(r) > 2]
        r = plan.runs[run.name]
        summary.append({"run": label, "integrator": r.integrator, "dt": r.dt, "frames": figures["frames"],
                        "s_per_frame": figures["seconds_per_frame"],
                        **{k: metric.get(k) for k in ("jaccard_min", "jaccard_mean", "jaccard_4dx_min",
                                                      "jaccard_4dx_mean", "disk_mean_pct_last", "disk_mean_pct_worst",
                                                      "disk_max_pct_worst", "penetrations")}})
    if per_frame:
        _write_csv(folder / "per_frame.csv", list(per_frame[0]), per_frame)
    _write_csv(folder / "summary.csv", list(summary[0]), summary)
    lines = [f"# {scene} against explicit coupling at {gt_job.dt:g} s ({gt_name})", "",
             f"The body (disk, 3D: sphere) size (bounding-box diagonal at rest): {size or float('nan'):.4f} m. Frames "
             "compared: those of each run that the ground truth has. Seconds per frame: each run's own stats.csv "
             "(the runs may have shared the machine; speed ratios: bench_table1).", "",
             "| run | dt (s) | frames | s/frame | sand J min / mean | sand J(4dx) min / mean | disk mean error last / "
             "worst (% size) | disk max error worst (% size) | particles inside the disk (worst frame) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        inside = "-" if s["penetrations"] is None else s["penetrations"]
        lines.append(f"| {s['run']} | {_fmt_dt(s['dt'])} | {s['frames']} | {s['s_per_frame']:.3f} | "
                     f"{s['jaccard_min']:.4f} / {s['jaccard_mean']:.4f} | {s['jaccard_4dx_min']:.4f} / "
                     f"{s['jaccard_4dx_mean']:.4f} | {s['disk_mean_pct_last']:.3f} / {s['disk_mean_pct_worst']:.3f} | "
                     f"{s['disk_max_pct_worst']:.3f} | {inside} |")
    (folder / "summary.md").write_text("\n".join(lines) + "\n")


# --- sweeps ----------------------------------------------------------------------------------------------
def accuracy_of(metric: dict) -> tuple[str, float]:
    """The sweep's accuracy figure of a comparison: J(4dx) min (MPM, coupling sand) or the worst mean
    nodal error (FEM, % of the diagonal)."""
    if "soft_iou_coarse_min" in metric:
        return "J(4dx) min", metric["soft_iou_coarse_min"]
    if "jaccard_4dx_min" in metric:
        return "J(4dx) min", metric["jaccard_4dx_min"]
    return "worst mean nodal error (% diag)", metric.get("worst_mean_pct", float("nan"))


def write_sweep(plan: Plan, name: str) -> None:
    sweep: SweepJob = plan.sweeps[name]
    folder = plan.results / "sweeps" / name
    folder.mkdir(parents=True, exist_ok=True)
    rows, label = [], None
    for p in sweep.points:
        run = plan.run_dir(p["run_key"])
        figures = run_figures(run)
        # The sweep rule runs once every run has; written by hand (`python -m plasticitynet.workflow sweep
        # NAME`) after stopping a workflow, a run that never finished is listed as not run.
        finished = (run / "done.json").exists()
        run_json = run / "frames" / "run.json"
        info = json.loads(run_json.read_text()) if run_json.exists() else {}
        row = {"scene": sweep.scene, "run": p["label"], "integrator": p["integrator"], "dt": p["dt"],
               "refinement": p["refinement"], "dx_m": plan.runs[p["run_key"]].scene_content.get("dx", ""),
               "capped": p.get("capped", ""), "particles": info.get("particles", ""),
               "frames": figures["frames"], "failed": figures["failed"],
               "seconds_per_frame": figures["seconds_per_frame"], "steps_per_frame": figures["steps_per_frame"],
               "newton_per_step": figures["newton_per_step"], "krylov_per_step": figures["cg_per_step"],
               "unconverged_steps": figures["unconverged_steps"], "not_run": not finished}
        if p["metric_key"] and finished:
            metric = _metric(plan, p["metric_key"])
            label, row["accuracy"] = accuracy_of(metric)
            row["spread_error"] = metric.get("spread_error", "")
            row["height_error"] = metric.get("height_error", "")
        rows.append(row)
    # Speed against explicit at its CFL step on the same grid (the scale study's comparison).
    cfl = {r["refinement"]: r["seconds_per_frame"] for r in rows if r["integrator"] == "explicit" and r["dt"] == 0}
    for r in rows:
        base = cfl.get(r["refinement"])
        r["speedup_vs_explicit_cfl"] = base / r["seconds_per_frame"] if base and r["seconds_per_frame"] > 0 else ""
    keys = ["scene", "run", "integrator", "dt", "refinement", "dx_m", "capped", "particles", "frames", "failed",
            "not_run", "seconds_per_frame", "speedup_vs_explicit_cfl", "steps_per_frame", "newton_per_step",
            "krylov_per_step", "unconverged_steps"] + (["accuracy", "spread_error", "height_error"] if label else [])
    _write_csv(folder / "summary.csv", keys, rows)
    note = ("Seconds per frame: each run's own wall clock (the workflow may run several at once; speed ratios "
            "from one quiet run: bench_table1, or this sweep with --jobs equal to threads, one run at a time). A run "
            "marked (failed) stopped with a simulation error; its accuracy is over the frames it has.")
    if sweep.kind == "dt":
        head = ("| run | dt (s) | refinement | frames | s/frame | steps/frame | Newton/step |"
                + (f" {label} |" if label else ""))
        lines = [f"# {sweep.scene}: time-step sweep", "", note, "", head, "|---" * (head.count("|") - 1) + "|"]
        for r in rows:
            if r["not_run"]:
                lines.append(f"| {r['run']} | {_fmt_dt(r['dt'])} | dx/{r['refinement']} | not run |" + " - |" * (
                    4 if label else 3))
                continue
            acc = f" {r['accuracy']:.3f} |" if label else ""
            lines.append(f"| {r['run']} | {_fmt_dt(r['dt'])} | dx/{r['refinement']} | {r['frames']}"
                         f"{' (failed)' if r['failed'] else ''} | {r['seconds_per_frame']:.3f} | "
                         f"{r['steps_per_frame']:.1f} | {r['newton_per_step']:.2f} |{acc}")
    else:
        lines = [f"# {sweep.scene}: resolution sweep (the scale study)", "",
                 "The scene with its grid spacing divided by k. At each resolution: its own ground truth (explicit "
                 "at the ground-truth step), explicit at its CFL step (the noise floor, and the speed every ratio "
                 "is taken against), and each implicit integrator at 1e-3 s within the default advection limit "
                 "(capped: what a user's run does) and without it (uncapped: the step alone). Per step: Newton "
                 "iterations and Krylov products (Hessian-vector products, `cg_iterations`). Accuracy against "
                 f"the same resolution's ground truth ({label or 'none'}; spread and height of the deposit at the "
                 "last frame).", "", note, "",
                 f"| run | refinement | particles | frames | s/frame | x explicit at CFL | steps/frame | Newton/step | "
                 f"Krylov/step | unconverged steps | {label or 'accuracy'} | spread | height |",
                 "|---" * 13 + "|"]

        def pct(v):
            return f"{100 * v:+.1f}%" if isinstance(v, float) else "-"

        for r in rows:
            if r["not_run"]:
                lines.append(f"| {r['run']} | dx/{r['refinement']} | - | not run |" + " - |" * 9)
                continue
            speed = r["speedup_vs_explicit_cfl"]
            acc = r.get("accuracy")
            lines.append(f"| {r['run']} | dx/{r['refinement']} | {r['particles']} | {r['frames']}"
                         f"{' (failed)' if r['failed'] else ''} | {r['seconds_per_frame']:.3f} | "
                         f"{f'{speed:.2f}x' if isinstance(speed, float) else '-'} | {r['steps_per_frame']:.1f} | "
                         f"{r['newton_per_step']:.2f} | {r['krylov_per_step']:.1f} | {r['unconverged_steps']} | "
                         f"{f'{acc:.4f}' if isinstance(acc, float) else '-'} | {pct(r.get('spread_error'))} | "
                         f"{pct(r.get('height_error'))} |")
    (folder / "summary.md").write_text("\n".join(lines) + "\n")
    plotted = [r for r in rows if not r["not_run"]]
    if plotted:
        _plot_sweep(sweep, plotted, label, folder / f"{name}.png")
    _record(plan.sweep_record(name), {"points": sweep.points})


def _plot_sweep(sweep: SweepJob, rows: list[dict], label: str | None, path: Path) -> None:
    plt = _plt()
    dx = sweep.kind == "dx"
    fig, axes = plt.subplots(1, 3 if dx else 2, figsize=(17 if dx else 12, 4.5), dpi=100)
    explicit = [r for r in rows if r["integrator"] == "explicit"]

    def series(r):  # one line per integrator, and per advection limit in the scale study
        return r["integrator"] + (" (uncapped)" if dx and r["capped"] is False else "")

    integrators = list(dict.fromkeys(r["integrator"] for r in rows if r["integrator"] != "explicit"))
    for name in dict.fromkeys(series(r) for r in rows if r["integrator"] != "explicit"):
        mine = [r for r in rows if series(r) == name and not r["failed"]]
        x = [r["refinement"] if dx else r["dt"] for r in mine]
        style = "o--" if name.endswith("(uncapped)") else "o-"
        colour = f"C{integrators.index(name.split(' ')[0])}"  # one colour per integrator, capped or not
        if label:
            line, = axes[0].plot(x, [r["accuracy"] for r in mine], style, color=colour, label=name)
            failed = [r for r in rows if series(r) == name and r["failed"]]
            if failed:  # a run that stopped with a simulation error: its frames until then, marked
                axes[0].plot([r["refinement"] if dx else r["dt"] for r in failed], [r["accuracy"] for r in failed],
                             "x", color=line.get_color(), markersize=10, label=f"{name}, stopped early")
        if dx:
            axes[1].plot(x, [r["newton_per_step"] for r in mine], style, color=colour, label=f"{name}: Newton")
            axes[1].plot(x, [r["krylov_per_step"] for r in mine], style.replace("o", "^"), color=colour, alpha=0.5,
                         label=f"{name}: Krylov")
        axes[-1].plot(x, [r["seconds_per_frame"] for r in mine], style, color=colour, label=name)
    if dx:
        x = [r["refinement"] for r in explicit]
        if label:
            axes[0].plot(x, [r["accuracy"] for r in explicit], "s--", color="grey", label="explicit at CFL (floor)")
        axes[-1].plot(x, [r["seconds_per_frame"] for r in explicit], "s--", color="grey", label="explicit at CFL")
        ks = sorted({r["refinement"] for r in rows})
        for ax in axes:
            ax.set_xlabel("resolution")
            ax.set_xscale("log", base=2)
            ax.set_xticks(ks, [f"dx/{k}" if k != 1 else "dx" for k in ks])
            ax.minorticks_off()
        axes[1].set_ylabel("per step")
        axes[1].set_yscale("log")
    else:
        for r in explicit:
            if label:
                axes[0].axhline(r["accuracy"], color="grey", linestyle="--", label="explicit at CFL")
            axes[1].axhline(r["seconds_per_frame"], color="grey", linestyle="--", label="explicit at CFL")
        for ax in axes:
            ax.set_xscale("log")
            ax.set_xlabel("time step (s)")
    axes[0].set_ylabel(label or "accuracy")
    axes[-1].set_ylabel("seconds per frame")
    axes[-1].set_yscale("log")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    what = "accuracy, solver work and cost against the resolution" if dx else "accuracy and cost against the time step"
    fig.suptitle(f"{sweep.scene}: {what}")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
