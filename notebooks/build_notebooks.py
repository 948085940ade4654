"""Writes the notebooks of notebooks/ from the cells below (one place to review and edit them as
Python), then, with --execute, runs each one in place with `jupyter nbconvert --execute` so that the
committed notebooks carry their full-size outputs.

    /usr/bin/python3 notebooks/build_notebooks.py [--execute] [NAME ...]

Every notebook reads results written by the project's scripts and names the command that
regenerates them; none of them simulates or trains, so each runs in seconds. With
PNET_NOTEBOOK_TINY=1 (the test suite) the elastic-region plots use fewer samples.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

# The first cell of every notebook: the repository root (the notebook may run from anywhere) and
# the tiny switch.
PREAMBLE = '''import csv, json, os, re
from pathlib import Path
import matplotlib
import matplotlib.pyplot as plt
from IPython.display import Image, Markdown, display

ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "models" / "MANIFEST").exists())
# PNET_RESULTS: another results folder (the workflow's, scripts/reproduce.sh --config results=...).
RESULTS = Path(os.environ.get("PNET_RESULTS") or ROOT / "notebooks" / "results")
TINY = os.environ.get("PNET_NOTEBOOK_TINY") == "1"
plt.rcParams.update({"figure.dpi": 100, "axes.grid": True, "grid.alpha": 0.3})


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def require(path):
    """A result file, or an error naming the command that writes it."""
    if not path.exists():
        raise FileNotFoundError(f"{path} is missing: run the command named above this cell")
    return path
'''

NOTEBOOKS = {}

NOTEBOOKS["fig04_training_curves"] = [
    new_markdown_cell("""# Training curves of every shipped model (paper Fig. 4)

The loss of each model in `models/MANIFEST` per training step (`models/<model>.csv`, written by
`train.py`), and the held-out error measured during training (`models/<model>_eval.csv`: relative RMS
of the learned stress against the return-mapped target on the paper's sampling and on the "near"
sampling around F0). Regenerate: `scripts/train_shipped_models.sh` (the exact command of each model
is in the MANIFEST and printed below)."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''manifest = json.loads((ROOT / "models" / "MANIFEST").read_text())
models = manifest["models"]
rows = ["| model | kind | steps x batch | training s | held-out error (paper / near, 1x) | command |", "|---|---|---|---|---|---|"]
for m in models:
    e = m["errors"]
    if m["kind"] == "energy":
        err = f'{100 * e["rel_rms"]["paper"]["1x"]:.2f}% / {100 * e["rel_rms"]["near"]["1x"]:.2f}%'
    else:
        err = f'mean relative yield residual {e["mean_abs_y_rel"]:.4f}'
    rows.append(f'| {m["file"]} | {m["kind"]} | {m["epochs"]} x {m["batch"]} | {m["wall_seconds"]:.0f} | {err} | `{m["command"]}` |')
display(Markdown("\\n".join(rows)))'''),
    new_code_cell('''fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
for ax, dim in zip(axes, (2, 3)):
    for m in models:
        if m["dim"] != dim:
            continue
        log = read_csv(require(ROOT / "models" / m["loss_log"]))
        step = [int(r["step"]) for r in log]
        loss = [float(r["loss"]) for r in log]
        # A running mean over 100 steps: the per-step loss is noisy (a new batch every step).
        k = 100
        smooth = [sum(loss[max(0, i - k + 1):i + 1]) / (i + 1 - max(0, i - k + 1)) for i in range(len(loss))]
        ax.semilogy(step, smooth, label=m["file"].removesuffix(".pt"))
    ax.set(title=f"{dim}D models: training loss (mean of 100 steps)", xlabel="step", ylabel="loss")
    ax.legend()
plt.tight_layout()
plt.show()'''),
    new_code_cell('''fig, ax = plt.subplots(figsize=(7, 4.5))
for m in models:
    if m["kind"] != "energy":
        continue
    path = ROOT / "models" / m["loss_log"].replace(".csv", "_eval.csv")
    ev = read_csv(require(path))
    ax.semilogy([int(r["step"]) for r in ev], [100 * float(r["paper"]) for r in ev], label=m["file"].removesuffix(".pt"))
ax.set(title="held-out stress error during training (paper sampling)", xlabel="step", ylabel="relative RMS error (%)")
ax.legend()
plt.show()'''),
]

NOTEBOOKS["fig05_accuracy"] = [
    new_markdown_cell("""# Accuracy against the explicit ground truth (paper Fig. 5)

(a), (b): the Jaccard index (soft IoU of the B-spline mass fields on the MPM grid, docs/metrics.md) of
each run against explicit MPM at dt = 1e-5 s, per frame, for the sand column and the snowball, beside
the noise floor (explicit at 2e-5 s and at its CFL step). (c): the mean FEM nodal distance from the
ground truth on the 2D metal frame, in % of the bounding-box diagonal. Regenerate:
`scripts/reproduce.sh fig05` (docs/workflow.md; results in `notebooks/results/implicit_eval/` and
`notebooks/results/fem_eval/`)."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''STYLE = {"explicit_2e-5": ("k", ":"), "explicit_cfl": ("0.5", "--"), "plasticitynet_1e-3": ("C0", "-"),
         "plasticitynet_1e-4": ("C2", "-"), "lagged_1e-3": ("C3", "-")}
fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
for ax, scene in zip(axes, ("sand_column_2d", "snowball_2d")):
    rows = read_csv(require(RESULTS / "implicit_eval" / scene / "iou.csv"))
    t = [float(r["time_s"]) for r in rows]
    for run in rows[0]:
        if run in ("frame", "time_s"):
            continue
        colour, line = STYLE.get(run, (None, "-"))
        ax.plot(t, [float(r[run]) for r in rows], color=colour, linestyle=line, label=run)
    ax.set(title=f"({'ab'[scene != 'sand_column_2d']}) {scene}: Jaccard vs explicit 1e-5", xlabel="time (s)",
           ylabel="soft IoU", ylim=(0, 1.02))
    ax.legend(fontsize=8)
nodal = read_csv(require(RESULTS / "fem_eval" / "metal_frame_2d" / "nodal_error.csv"))
runs = sorted({r["run"] for r in nodal}, key=lambda r: list(STYLE).index(r) if r in STYLE else 99)
for run in runs:
    pts = [r for r in nodal if r["run"] == run]
    axes[2].plot([float(r["time_s"]) for r in pts], [float(r["mean_pct_diagonal"]) for r in pts], label=run)
axes[2].set(title="(c) metal_frame_2d: mean nodal error", xlabel="time (s)", ylabel="% of bounding-box diagonal")
axes[2].legend(fontsize=8)
plt.tight_layout()
plt.show()'''),
    new_code_cell('''display(Markdown((RESULTS / "implicit_eval" / "summary.md").read_text()))'''),
    new_code_cell('''display(Markdown((RESULTS / "fem_eval" / "summary.md").read_text()))'''),
]

NOTEBOOKS["table1_timings"] = [
    new_markdown_cell("""# Table 1: seconds per frame and speed-ups

The tables written by `bench_table1` (C++, `cpp/bench/bench_table1.cpp`): every integrator runs the
same simulated interval from the scene's initial state, in one process, and each speed-up is a ratio
of two timings of that run. Besides the paper's comparison (explicit at its 1e-5 s ground-truth step)
every row is compared with explicit at its own CFL step. Regenerate on a quiet machine with
`scripts/reproduce.sh table1` (docs/workflow.md), which runs

    build/cpp/bench/bench_table1 --no-fem --frames 10 --with-lagged --threads N   # table1/mpm.md: MPM and stiff rows
    build/cpp/bench/bench_table1 --only metal_frame_2d --with-lagged --threads N    # table1/fem.md
    build/cpp/bench/bench_table1 --only sand_fem_coupling_2d --threads N            # table1/coupling.md
"""),
    new_code_cell(PREAMBLE),
    new_code_cell('''def table_rows(path):
    """The Markdown table rows of a bench_table1 output, as dicts."""
    lines = [l for l in require(path).read_text().splitlines() if l.startswith("|")]
    header = [h.strip() for h in lines[0].strip("|").split("|")]
    rows = []
    for line in lines[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == len(header) and not set(line) <= set("|-: "):
            rows.append(dict(zip(header, cells)))
    return header, rows


sources = {"MPM (and stiff MPM)": RESULTS / "table1" / "mpm.md",
           "FEM metal": RESULTS / "table1" / "fem.md",
           "MPM-FEM coupling": RESULTS / "table1" / "coupling.md"}
for title, path in sources.items():
    header, rows = table_rows(path)
    keep = [h for h in header if h in ("scene", "integrator", "dt (s)", "s/frame", "Newton/step", "CG/step") or h.startswith("speed-up") or h.startswith("paper")]
    text = [f"**{title}** (`{path.relative_to(RESULTS)}`)", "", "| " + " | ".join(keep) + " |", "|" + "---|" * len(keep)]
    text += ["| " + " | ".join(r.get(h, "") for h in keep) + " |" for r in rows]
    display(Markdown("\\n".join(text)))'''),
    new_code_cell('''# Seconds per frame of the implicit integrator against explicit at 1e-5 (1e-6 for the stiff rows) and at CFL.
header, rows = table_rows(sources["MPM (and stiff MPM)"])
scenes = sorted({r["scene"] for r in rows}, key=[r["scene"] for r in rows].index)
fig, ax = plt.subplots(figsize=(9, 4))
width = 0.27
for k, (label, pick) in enumerate([("plasticitynet 1e-3", lambda r: r["integrator"] == "plasticitynet"),
                                    ("explicit, paper step", lambda r: r["integrator"] == "explicit" and not r["dt (s)"].startswith("CFL")),
                                    ("explicit at CFL", lambda r: r["integrator"] == "explicit" and r["dt (s)"].startswith("CFL"))]):
    values = [next(float(r["s/frame"]) for r in rows if r["scene"] == s and pick(r)) for s in scenes]
    ax.bar([i + (k - 1) * width for i in range(len(scenes))], values, width, label=label)
ax.set_xticks(range(len(scenes)), scenes, rotation=10)
ax.set(ylabel="s / frame (log)", yscale="log", title="MPM: seconds per frame, 2 threads")
ax.legend()
plt.show()'''),
]

NOTEBOOKS["fig11_energy_representations"] = [
    new_markdown_cell("""# Energy representations (paper Fig. 11, sec. 5.2)

Why eq. 8: the 2D sand energy trained in four forms with one recipe (the paper's raw `[F, F0]` input,
the loss of eq. 9, batch 8192, 15000 steps), only the form differing:

| form | energy | what it gets right by construction |
|---|---|---|
| `global` | Psi = N(F) | nothing: one energy for a stress field that has none (not integrable in the plastic region) |
| `global_identity` | Psi = N(F) - grad N(I) : F | zero stress at rest (F = I) |
| `local_identity` | Psi = N(F, F0) - grad N(I, F0) : F | zero stress at rest, a family of energies |
| `eq8` | Psi = N(F, F0) - (grad N(F0, F0) - Ptilde(F0)) : F | the exact stress at F = F0 |

Regenerate: `scripts/train_ablation_models.sh` (models/ablation/, ~35 min on one core) and
`scripts/reproduce.sh fig11` (docs/workflow.md)
(plasticitynet at dt = 1e-3 s with each model, `pnet simulate --model`, against the explicit ground
truth at 1e-5 s; `plasticitynet_1e-3` is the shipped model, trained with the recipe of
`scripts/train_shipped_models.sh`)."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''FORMS = ["global", "global_identity", "local_identity", "eq8"]
manifest = {e["file"]: e for e in json.loads(require(ROOT / "models" / "ablation" / "MANIFEST").read_text())["models"]}
rows = ["| form | rel. RMS error of grad Psi, paper sampling 0.5x / 1x / 2x | at F = F0 (max relative) | training |",
        "|---|---|---|---|"]
fig, ax = plt.subplots(figsize=(7, 4))
for form in FORMS:
    e = manifest[f"sand_2d_{form}.pt"]
    rms = e["errors"]["rel_rms"]["paper"]
    rows.append(f"| {form} | {rms['0.5x']:.2%} / {rms['1x']:.2%} / {rms['2x']:.2%} | "
                f"{e['errors']['at_F0_max_rel']:.1e} | {e['epochs']} x {e['batch']}, {e['wall_seconds'] / 60:.1f} min |")
    curve = read_csv(require(ROOT / "models" / "ablation" / f"sand_2d_{form}_eval.csv"))
    ax.semilogy([int(r["step"]) for r in curve], [float(r["paper"]) for r in curve], marker=".", label=form)
ax.set(title="held-out relative RMS error of grad Psi (paper sampling)", xlabel="training step", ylabel="error (log)")
ax.legend()
plt.show()
display(Markdown("\\n".join(rows)))'''),
    new_code_cell('''sand = RESULTS / "representation_ablation" / "sand_column_2d"
RUNS = [f"form_{f}_1e-3" for f in FORMS] + ["plasticitynet_1e-3", "explicit_cfl"]
iou = read_csv(require(sand / "iou.csv"))
fig, ax = plt.subplots(figsize=(8, 4.5))
for run in RUNS:
    ts = [float(r["time_s"]) for r in iou if r.get(run)]
    ax.plot(ts, [float(r[run]) for r in iou if r.get(run)], label=run)
ax.set(title="sand_column_2d: Jaccard index vs explicit 1e-5 s", xlabel="time (s)", ylabel="soft IoU", ylim=(0, 1))
ax.legend(fontsize=8)
plt.show()
summary = require(RESULTS / "representation_ablation" / "summary.md").read_text().splitlines()
display(Markdown("\\n".join(summary[:2] + [l for l in summary[2:] if any(f"| {r} |" in l for r in ["gt"] + RUNS)])))'''),
    new_code_cell('''# Frames 1, 5, 10, 25 and 50 (t = 0.02 ... 1 s) of each run beside the ground truth.
FRAMES = [1, 5, 10, 25, 50]
shown = ["gt"] + [f"form_{f}_1e-3" for f in FORMS]
fig, axes = plt.subplots(len(shown), len(FRAMES), figsize=(3.2 * len(FRAMES), 1.6 * len(shown)))
for i, run in enumerate(shown):
    for j, frame in enumerate(FRAMES):
        ax = axes[i, j]
        ax.axis("off")
        path = sand / f"{run}_frame_{frame:05d}.png"
        if path.exists():
            ax.imshow(plt.imread(path))
        else:
            ax.text(0.5, 0.5, "(run stopped)", ha="center", va="center")
        if j == 0:
            ax.set_title(run, loc="left", fontsize=9)
plt.tight_layout()
plt.show()'''),
    new_markdown_cell("""What the committed runs show, as the paper found: the two global energies keep the column
standing like an elastic body (spread far below, height far above the ground truth), and `global`,
with no correction at F = I, already moves at the first frame; `local_identity` follows the first
slump, then deviates and throws the sand apart, at many Newton iterations per step; eq. 8 trained
with the same recipe matches the ground truth as closely as the shipped model and explicit MPM at
its CFL step. Fitting the stress field is not enough (`local_identity`'s held-out error is as low as
eq. 8's): the energy must be exact at F = F0, where every solve of the fixed point starts. Videos:
`notebooks/results/videos/sand_column_2d_form_*_1e-3.mp4`."""),
]

NOTEBOOKS["fig12_regularizer"] = [
    new_markdown_cell("""# The stability regularizer (paper Fig. 12, eq. 11)

The simulations with the regularizer weight w of eq. 11 set to 0 against the default, on the
2D metal frame (FEM) and the sand column (MPM). Regenerate:
`scripts/reproduce.sh fig12` (docs/workflow.md: the FEM evaluation's `plasticitynet_1e-2_w0` run, 30
frames, and the regularizer ablation on sand)."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''fem = RESULTS / "fem_eval" / "metal_frame_2d"
nodal = read_csv(require(fem / "nodal_error.csv"))
fig, ax = plt.subplots(figsize=(7, 4))
for run in ("plasticitynet_1e-2", "plasticitynet_1e-2_w0"):
    pts = [r for r in nodal if r["run"] == run]
    ax.semilogy([float(r["time_s"]) for r in pts], [float(r["mean_pct_diagonal"]) for r in pts], label=run)
ax.set(title="metal_frame_2d: mean nodal error vs explicit ground truth", xlabel="time (s)", ylabel="% of diagonal (log)")
ax.legend()
plt.show()
for run in ("plasticitynet_1e-2", "plasticitynet_1e-2_w0"):
    display(Markdown(f"**{run}**, last frame"), Image(filename=str(require(fem / f"{run}_final.png")), width=300))
# The run without the regularizer stops where its solve fails ("(failed)" in the frames column).
lines = require(RESULTS / "fem_eval" / "summary.md").read_text().splitlines()
table = [l for l in lines if l.startswith("|")][:2] + [l for l in lines if "| metal_frame_2d | plasticitynet_1e-2" in l]
display(Markdown("\\n".join(table)))'''),
    new_code_cell('''sand = RESULTS / "regularizer_ablation" / "sand_column_2d"
rows = read_csv(require(sand / "iou.csv"))
fig, ax = plt.subplots(figsize=(7, 4))
for run in ("plasticitynet_1e-3", "plasticitynet_1e-3_w0"):
    ax.plot([float(r["time_s"]) for r in rows], [float(r[run]) for r in rows], label=run)
ax.set(title="sand_column_2d: Jaccard vs explicit 1e-5", xlabel="time (s)", ylabel="soft IoU")
ax.legend()
plt.show()
for run in ("plasticitynet_1e-3", "plasticitynet_1e-3_w0"):
    display(Markdown(f"**{run}**, last frame"), Image(filename=str(require(sand / f"{run}_final.png")), width=300))
display(Markdown((RESULTS / "regularizer_ablation" / "summary.md").read_text()))'''),
]

NOTEBOOKS["fig13_gallery_3d"] = [
    new_markdown_cell("""# 3D gallery (paper Fig. 13)

The last frames of the 3D scenes: sand and snow (MPM, `plasticitynet` at dt = 1e-3 s) beside their
explicit ground truth, and the 3D metal frame (FEM, dt = 1e-2 s). Regenerate:
`scripts/reproduce.sh fig13` (docs/workflow.md)."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''for scene in ("sand_column_3d", "snowball_3d"):
    folder = RESULTS / "implicit_eval" / scene
    display(Markdown(f"### {scene}: ground truth (explicit 1e-5) | plasticitynet 1e-3"))
    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    for ax, run in zip(axes, ("gt", "plasticitynet_1e-3")):
        ax.imshow(plt.imread(require(folder / f"{run}_final.png")))
        ax.set_title(run)
        ax.axis("off")
    plt.show()
    summary = json.loads(require(folder / "summary.json").read_text()) if (folder / "summary.json").exists() else None
folder = RESULTS / "fem_eval" / "metal_frame_3d"
images = sorted(folder.glob("*_final.png"))
display(Markdown("### metal_frame_3d"))
fig, axes = plt.subplots(1, len(images), figsize=(5 * len(images), 5), squeeze=False)
for ax, path in zip(axes[0], images):
    ax.imshow(plt.imread(path))
    ax.set_title(path.stem.removesuffix("_final"))
    ax.axis("off")
plt.show()'''),
]

NOTEBOOKS["fig14_16_elastic_regions"] = [
    new_markdown_cell("""# Elastic regions in principal-stress space (paper Figs. 14-16)

Random trial states (grey: inside the elastic region; coloured: their return-mapped stress, by
branch) for Drucker-Prager sand (Fig. 14), Cam-Clay snow (Fig. 15) and von Mises metal (Fig. 16),
drawn by `plasticitynet.report` (`.venv/bin/python -m plasticitynet.report --out DIR` writes the same
figures and a table of the return mapping on sample deformations). The projected states trace the
yield surface: a cone, an ellipse, a circle."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''import sys, tempfile
sys.path.insert(0, str(ROOT / "python"))
from plasticitynet.materials import Material
from plasticitynet import report

out = Path(tempfile.mkdtemp())
for name, figure in (("sand", 14), ("snow", 15), ("metal", 16)):
    material = Material.preset(name, dim=2)
    path = out / f"{name}_2d.png"
    info = report.plot_elastic_region(material, name, path)
    display(Markdown(f"**Fig. {figure}: {name}** — {info}"), Image(filename=str(path), width=520))'''),
]


NOTEBOOKS["fig06_10_scenes_2d"] = [
    new_markdown_cell("""# The 2D scenes (paper Figs. 6-10)

The last frame of each 2D scene: sand (Fig. 6), snow with hardening (Fig. 7), metal with hardening
(Fig. 8), metal with the learned return mapping and neo-Hookean elasticity (Fig. 9) and the FEM-MPM
coupling (Fig. 10), by the explicit ground truth (or, for FEM, explicit at 2e-5 s), `plasticitynet`
and the lagged baseline. Regenerate: `scripts/reproduce.sh fig06_10` (docs/workflow.md); each run's
frames stay in `out/workflow/runs/<key>/frames/` (`python -m plasticitynet.workflow list` names the
keys), and `build/cpp/pnet video out/workflow/runs/<key>/frames` makes its video."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''SCENES = [
    ("Fig. 6: sand", RESULTS / "implicit_eval" / "sand_column_2d", ["gt", "plasticitynet_1e-3", "lagged_1e-3"]),
    ("Fig. 7: snow", RESULTS / "implicit_eval" / "snowball_2d", ["gt", "plasticitynet_1e-3", "lagged_1e-3"]),
    ("Fig. 8: metal (von Mises)", RESULTS / "fem_eval" / "metal_frame_2d", ["explicit_2e-5", "plasticitynet_1e-2", "lagged_1e-2"]),
    ("Fig. 9: metal, learned return mapping", RESULTS / "fem_eval" / "metal_nh_frame_2d",
     ["explicit_2e-5", "plasticitynet_1e-2", "plasticitynet_1e-2_exact_rm"]),
    ("Fig. 10: FEM-MPM coupling", RESULTS / "coupling_eval", ["explicit_1e-6", "plasticitynet_1e-3", "lagged_1e-3"]),
]
for title, folder, runs in SCENES:
    fig, axes = plt.subplots(1, len(runs), figsize=(4.5 * len(runs), 4.5))
    for ax, run in zip(axes, runs):
        ax.imshow(plt.imread(require(folder / f"{run}_final.png")))
        ax.set_title(run)
        ax.axis("off")
    fig.suptitle(title)
    plt.tight_layout()
    plt.show()'''),
]


NOTEBOOKS["inverse_identification"] = [
    new_markdown_cell("""# Identifying a material from an observed run (issue 57; docs/adjoint.md)

Young's modulus of an elastic box bouncing on the ground (FEM, observed by the fit's implicit step), the
yield stress of a clamped metal cantilever sagging under gravity (FEM, observed by explicit FEM at 1e-5 s,
fitted by the classical implicit step at 5e-4 s), Young's modulus of the MPM elastic ball bouncing on the
floor (observed by explicit MPM at 1e-5 s, fitted at 2.5e-4 s), and the friction angle of the collapsing
sand column (MPM, observed by explicit MPM at 1e-5 s at 27 degrees, fitted from 35 by the classical implicit
step at 1e-3 s, on the particles' positions and, without particle correspondence, on the deposit's height
profile; on the shipped column's Coulomb floor with AFLIP transfers, and, `*_slip_floor`, on a slip floor with
APIC transfers), each fitted to frames of the observed run by L-BFGS on the log of the parameter.
Each evaluation is a forward rollout and its adjoint. Regenerate:
`python3 scripts/identify.py youngs_modulus --out notebooks/results/identify`,
`python3 scripts/identify.py yield_stress --out notebooks/results/identify`,
`python3 scripts/identify.py ball_youngs_modulus --out notebooks/results/identify`,
`python3 scripts/identify.py friction_angle --out notebooks/results/identify` and
`python3 scripts/identify.py friction_angle --loss profile --out notebooks/results/identify`, each of the two
also with `--floor slip` (the JSON and PNG files; the observed runs' folders are not kept)."""),
    new_code_cell(PREAMBLE),
    new_code_cell('''cases = {"youngs_modulus": ("E", "Pa"), "yield_stress": ("h0", ""), "ball_youngs_modulus": ("E", "Pa"),
         "friction_angle": ("phi", "deg"), "friction_angle_profile": ("phi", "deg"),
         "friction_angle_slip_floor": ("phi", "deg"), "friction_angle_profile_slip_floor": ("phi", "deg")}
fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
rows = ["| case | true | start | identified | relative error | evaluations |", "|---|---|---|---|---|---|"]
for name, (symbol, unit) in cases.items():
    run = json.loads(require(RESULTS / "identify" / f"{name}.json").read_text())
    path = run["path"]
    axes[0].semilogy(range(1, len(path) + 1), [p["loss_mm2"] for p in path], "o-", label=name)
    axes[1].plot(range(1, len(path) + 1), [p["value"] / run["true"] for p in path], "o-", label=name)
    rows.append(f"| {name} | {run['true']:.6g} {unit} | {run['start']:.6g} {unit} | {run['identified']:.6g} {unit} "
                f"| {run['relative_error']:.2g} | {len(path)} |")
axes[0].set(title="loss along the optimizer's path", xlabel="evaluation (forward + backward)", ylabel="mm$^2$ (log)")
axes[1].set(title="parameter / true value", xlabel="evaluation", ylabel="ratio")
axes[1].axhline(1.0, color="k", lw=0.8)
for ax in axes:
    ax.legend()
plt.show()
display(Markdown("\\n".join(rows)))'''),
]


def build(execute: bool, names=()) -> None:
    unknown = set(names) - set(NOTEBOOKS)
    if unknown:
        sys.exit(f"no notebook named {', '.join(sorted(unknown))} (known: {', '.join(NOTEBOOKS)})")
    for name, cells in NOTEBOOKS.items():
        if names and name not in names:
            continue
        nb = new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}})
        path = HERE / f"{name}.ipynb"
        nbformat.write(nb, path)
        if execute:
            subprocess.run([sys.executable, "-m", "jupyter", "nbconvert", "--to", "notebook", "--execute", "--inplace",
                            "--ExecutePreprocessor.timeout=600", str(path)], check=True)
        print(f"{'executed' if execute else 'wrote'} {path.relative_to(HERE.parent)}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--execute", action="store_true", help="run each notebook in place (full-size outputs)")
    parser.add_argument("names", nargs="*", help="only these notebooks (default: all)")
    args = parser.parse_args()
    build(args.execute, args.names)
