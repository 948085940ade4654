"""Material report: how each material's return mapping behaves, in numbers and pictures.

    python -m plasticitynet.report [--out DIR] [--materials sand snow ...] [--dims 2 3]

For every material of docs/physics.md (sand, snow, metal, metal_nh) in 2D and 3D it prints a table of
the return mapping Z(Sigma, h) on named sample deformations (branch taken, projected singular
values, hardening update, distance of the result to the yield surface) and writes a PNG of the
elastic region in principal Kirchhoff-stress space, like the paper's figures 14-16: the projected
states trace the yield surface (a cone for Drucker-Prager, an ellipse/ellipsoid for Cam-Clay, a
cylinder for von Mises). It also measures how far the "paper" Cam-Clay variant (eq. 20) lands from
the yield surface, against the "exact" default.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import torch

from .materials import BRANCH_NAMES, PRESETS, Material

MATERIALS = ("sand", "snow", "metal", "metal_nh")

#: Log-strain radius of the trial states drawn in the figures, per material (chosen so that the
#: elastic region and the projection onto its boundary are both visible at the preset hardening).
PLOT_STRAIN = {"sand": 0.03, "snow": 0.08, "metal": 0.12, "metal_nh": 0.12}

# Colours per branch (elastic points grey, each plastic branch its own colour).
BRANCH_COLOURS = {
    "elastic": "#9e9e9e", "apex": "#d62728", "cone": "#1f77b4", "compression_tip": "#d62728",
    "tension_tip": "#ff7f0e", "ellipse": "#1f77b4", "yield": "#1f77b4",
}


def sample_deformations(dim: int) -> list[tuple[str, torch.Tensor]]:
    """Named deformation gradients F (float64), from small to large."""
    eye = torch.eye(dim, dtype=torch.float64)

    def diag(*values):
        v = list(values) + [1.0] * (dim - len(values))
        return torch.diag(torch.tensor(v[:dim], dtype=torch.float64))

    shear = eye.clone()
    shear[0, 1] = 0.2
    rotation = torch.tensor([[math.cos(0.7), -math.sin(0.7)], [math.sin(0.7), math.cos(0.7)]], dtype=torch.float64)
    if dim == 3:
        rotation = torch.block_diag(rotation, torch.ones(1, 1, dtype=torch.float64))
    return [
        ("identity", eye),
        ("uniaxial compression 2%", diag(0.98)),
        ("uniaxial stretch 2%", diag(1.02)),
        ("hydrostatic compression 5%", 0.95 * eye),
        ("hydrostatic expansion 5%", 1.05 * eye),
        ("pure shear 5%", diag(1.05, 1 / 1.05)),
        ("simple shear 0.2", shear),
        ("rotated pure shear 5%", rotation @ diag(1.05, 1 / 1.05)),
        ("large compression 50%", diag(0.5)),
        ("large stretch x e", diag(math.e)),
        ("reflected (det < 0)", diag(-1.0)),
    ]


def fmt_vec(v: torch.Tensor) -> str:
    return "(" + ", ".join(f"{x:.4f}" for x in v.tolist()) + ")"


def table(material: Material) -> str:
    """Markdown table of the return mapping on the sample deformations."""
    rows = [
        "| deformation | Sigma | branch | Z | h -> h_new | y(Z)/scale | ||Ptilde||/E |",
        "|---|---|---|---|---|---|---|",
    ]
    E = material.elasticity.params.E
    for name, F in sample_deformations(material.dim):
        out = material.evaluate(F, quantities=("Z_Sigma", "Ptilde"))
        h = material.initial_hardening
        Z = out["Z_Sigma"]
        # Signed relative distance to the yield surface: < 0 inside, ~1e-15 on it.
        residual = material.yield_function(Z, h) / (material.yield_scale(Z, h) + 1e-12 * E)
        branch = BRANCH_NAMES[int(out["branch"])]
        rows.append(
            f"| {name} | {fmt_vec(out['Sigma'])} | {branch} | {fmt_vec(Z)} | {h:+.4f} -> {float(out['hardening_new']):+.4f}"
            f" | {float(residual):+.1e} | {float(out['Ptilde'].norm()) / E:.3e} |"
        )
    return "\n".join(rows)


def trial_states(dim: int, radius: float, n: int, generator: torch.Generator) -> torch.Tensor:
    """Trial singular values exp(eps): a regular grid in 2D, random directions and radii in 3D."""
    if dim == 2:
        axis = torch.linspace(-radius, radius, n, dtype=torch.float64)
        eps = torch.cartesian_prod(axis, axis)
    else:
        directions = torch.randn(n * n, 3, dtype=torch.float64, generator=generator)
        directions /= directions.norm(dim=1, keepdim=True)
        radii = radius * torch.rand(n * n, 1, dtype=torch.float64, generator=generator) ** (1 / 3)
        eps = directions * radii
    return eps.exp()


def principal_stress(material: Material, Sigma: torch.Tensor) -> torch.Tensor:
    """Kirchhoff stress tau(Sigma) in kPa."""
    return material.tau(Sigma) / 1e3


def meridian(tau: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(p, q): pressure -tr(tau)/d (compression positive) and deviatoric norm ||dev tau||."""
    d = tau.shape[1]
    p = -tau.sum(dim=1) / d
    q = (tau - tau.mean(dim=1, keepdim=True)).norm(dim=1)
    return p, q


def plot_elastic_region(material: Material, name: str, path: Path, seed: int = 0) -> dict:
    """Writes the figure; returns the branch counts of the trial states drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    generator = torch.Generator().manual_seed(seed)
    dim = material.dim
    Sigma = trial_states(dim, PLOT_STRAIN[name], 121 if dim == 2 else 110, generator)
    Z, _, branch = material.return_map(Sigma)
    tau_trial = principal_stress(material, Sigma)
    tau_proj = principal_stress(material, Z)
    plastic = branch != 0
    names = [BRANCH_NAMES[int(b)] for b in branch]
    counts = {b: names.count(b) for b in sorted(set(names))}

    fig = plt.figure(figsize=(11, 5))
    title = (f"{name} ({dim}D): {material.elasticity.name} + {material.plasticity.name}, "
             f"h = {material.initial_hardening:g}")
    fig.suptitle(title)
    if dim == 2:
        ax = fig.add_subplot(1, 2, 1)
        for b in counts:
            mask = torch.tensor([n == b for n in names])
            ax.scatter(tau_trial[mask, 0], tau_trial[mask, 1], s=2, c=BRANCH_COLOURS[b], label=f"trial: {b}", alpha=0.5)
        ax.scatter(tau_proj[plastic, 0], tau_proj[plastic, 1], s=3, c="k", label="projected Z")
        step = max(1, int(plastic.sum()) // 150)
        idx = torch.nonzero(plastic).flatten()[::step]
        for i in idx.tolist():
            ax.plot([tau_trial[i, 0], tau_proj[i, 0]], [tau_trial[i, 1], tau_proj[i, 1]], c="k", lw=0.3, alpha=0.4)
        ax.set_xlabel("tau_1 (kPa)")
        ax.set_ylabel("tau_2 (kPa)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title("principal stress plane: trial states and their projection")
    else:
        ax = fig.add_subplot(1, 2, 1, projection="3d")
        proj = tau_proj[plastic]
        ax.scatter(proj[:, 0], proj[:, 1], proj[:, 2], s=1, c=meridian(proj)[0], cmap="viridis")
        lo, hi = float(proj.min()), float(proj.max())
        ax.plot([lo, hi], [lo, hi], [lo, hi], c="r", lw=1, label="hydrostatic axis")
        for set_lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):  # equal axes: true shape of the surface
            set_lim(lo, hi)
        ax.set_xlabel("tau_1 (kPa)")
        ax.set_ylabel("tau_2 (kPa)")
        ax.set_zlabel("tau_3 (kPa)")
        ax.view_init(elev=20, azim=-60)
        ax.set_title("yield surface: projected states Z")
    ax.legend(loc="best", fontsize=7, markerscale=4)

    ax = fig.add_subplot(1, 2, 2)
    p_t, q_t = meridian(tau_trial)
    p_z, q_z = meridian(tau_proj)
    for b in counts:
        mask = torch.tensor([n == b for n in names])
        ax.scatter(p_t[mask], q_t[mask], s=1, c=BRANCH_COLOURS[b], alpha=0.3, label=f"trial: {b}")
    ax.scatter(p_z[plastic], q_z[plastic], s=2, c="k", label="projected Z")
    ax.set_xlabel("p = -tr(tau)/d (kPa, compression > 0)")
    ax.set_ylabel("q = ||dev tau|| (kPa)")
    ax.set_title("meridian plane")
    ax.legend(loc="best", fontsize=7, markerscale=4)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)  # never leave a half-written figure under the final name
    return counts


def cam_clay_variant_drift(dim: int, strain: float, n: int = 2000, seed: int = 1) -> dict:
    """Relative distance |y|/scale to the yield surface after one projection, and the relative change
    of Z after re-projecting it 100 times (what an explicit integrator does each step), for the
    "exact" and "paper" Cam-Clay variants on trial log-strains of the given magnitude."""
    generator = torch.Generator().manual_seed(seed)
    eps = (2 * torch.rand(n, dim, dtype=torch.float64, generator=generator) - 1) * strain
    out = {}
    for variant in ("exact", "paper"):
        description = dict(PRESETS["snow"], plasticity=dict(PRESETS["snow"]["plasticity"], variant=variant))
        material = Material.from_dict(description, dim)
        Z, _, branch = material.return_map(eps.exp())
        mask = branch == 5  # ellipse: the only branch where the variants differ
        Z = Z[mask]
        h = material.initial_hardening
        y = material.yield_function(Z, h)
        surface = (y.abs() / material.yield_scale(Z, h)).max()
        # Relative error of the deviatoric stress q against the surface's q at the same pressure:
        # y = A q^2 + B(p), and B(p) is y at the hydrostatic state of the same volume.
        J = Z.prod(dim=1, keepdim=True)
        B = material.yield_function(J.pow(1.0 / dim).expand(-1, dim), h)
        # B >= 0 means the projection moved the pressure outside the tips [-beta p0, p0].
        inside = B < 0
        q_error = ((y - B)[inside] / -B[inside]).sqrt().sub(1).abs()
        q_error = (float(q_error.median()), float(q_error.max()))
        outside = int((~inside).sum())
        again = Z
        for _ in range(100):
            again = material.return_map(again, h)[0]
        creep = ((again - Z).norm(dim=1) / Z.norm(dim=1)).max()
        out[variant] = (int(mask.sum()), float(surface), q_error, outside, float(creep))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out/material_report"), help="output folder")
    parser.add_argument("--materials", nargs="+", default=list(MATERIALS), choices=MATERIALS)
    parser.add_argument("--dims", nargs="+", type=int, default=[2, 3], choices=[2, 3])
    args = parser.parse_args(argv)

    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    lines = ["# PlasticityNet material report", ""]
    figures = []
    for name in args.materials:
        for dim in args.dims:
            material = Material.preset(name, dim)
            header = f"## {name}, {dim}D: {material.elasticity.name} + {material.plasticity.name}"
            params = PRESETS[name]
            body = table(material)
            figure = args.out / f"{name}_{dim}d_elastic_region.png"
            counts = plot_elastic_region(material, name, figure)
            figures.append(figure)
            summary = (f"E = {params['elasticity']['E']:g} Pa, nu = {params['elasticity']['nu']:g}, "
                       f"plasticity {params['plasticity']}, initial hardening {material.initial_hardening:g}")
            block = [header, "", summary, "", body, "",
                     f"figure: {figure.name} (trial states by branch: {counts})", ""]
            print("\n".join(block), flush=True)
            lines += block

    drift_lines = ["## Cam-Clay: exact vs paper variant (eq. 20) on the ellipse branch", "",
                   "| dim | log-strain | variant | ellipse cases | max |y|/scale after projection "
                   "| |q/q_surface - 1| median, max | pressure pushed past a tip | max rel. change of Z after 100 re-projections |",
                   "|---|---|---|---|---|---|---|---|"]
    for dim in args.dims:
        for strain in (0.1, 0.3):
            for variant, (n, surface, q_error, outside, creep) in cam_clay_variant_drift(dim, strain).items():
                drift_lines.append(f"| {dim} | {strain} | {variant} | {n} | {surface:.2e} | {q_error[0]:.2e}, {q_error[1]:.2e} | {outside} "
                                   f"| {creep:.2e} |")
    print("\n".join(drift_lines), flush=True)
    lines += drift_lines + [""]

    report = args.out / "report.md"
    tmp = report.with_suffix(".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(report)
    print(f"\nwrote {report} and {len(figures)} figures to {args.out}/ in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
