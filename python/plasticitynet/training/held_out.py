"""Accuracy of a trained model on held-out samples (docs/metrics.md; issue 3 item 5).

    python -m plasticitynet.model_errors MODEL [--samples N] [--seed S] [--json]

Energy models: the relative RMS gradient error
    e = sqrt( E||grad_F Psi(F, F0, h) - Ptilde(F, h)||^2 / E||Ptilde(F, h)||^2 )
on `samples` held-out triples (the "eval" random stream, disjoint from every training batch), for
"paper" and "near" sampling at 0.5x, 1x and 2x the training perturbation deps; Ptilde comes from the
library through its polar SVD (not the SVD-free path used in training). Also the error exactly at
F = F0, max ||grad Psi(F0, F0, h) - Ptilde(F0, h)|| / max(||Ptilde(F0, h)||, 1e-3 mu) in float64,
which the correction of eq. 8 makes round-off (~1e-12 or less; the floor 1e-3 mu only matters where
Ptilde(F0) = 0, the sand apex). An energy trained with a learned return mapping is measured against
the stress of that mapping (its training target) and, in addition, against the library's root find.

Return-map models, on Sigma = e^eps, eps ~ U[-1, 1]^d, h ~ U[0, 1], yielding samples only:
mean |y(Z_theta, h)| / (2 mu h)^2 over the samples with h >= 0.05 (the ratio is unbounded as h -> 0,
where the yield surface shrinks to the diagonal), its median over all; the fraction of projected
points within 1e-3 of the surface, |y(Z_theta)| / (||dev tau(Z_theta)||^2 + (2 mu h)^2) <= 1e-3 (the
library's relative surface distance, = |y| / (2 (2 mu h)^2) on the surface); and mean/max
|dgamma_theta - dgamma_exact| against the library's root find.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time

import torch

from ..materials import Material
from . import return_map_net
from .sampling import sample_batch, sample_return_map_states, sampling_spec
from .targets import ElastoplasticStress

#: Seed of the held-out samples (with the "eval" stream: disjoint from training whatever its seed).
EVAL_SEED = 20240
DEPS_SCALES = (0.5, 1.0, 2.0)
SAMPLINGS = ("paper", "near")
CHUNK = 1 << 14


def _scale_key(scale: float) -> str:
    return f"{scale:g}x"


def relative_rms_error(model, sampling: str, deps_scale: float, samples: int, seed: int, stress=None) -> float:
    """sqrt(sum ||grad Psi - Ptilde||^2 / sum ||Ptilde||^2) over `samples` held-out triples (chunked)."""
    return gradient_errors(model, sampling, deps_scale, samples, seed, stress)[0]


def gradient_errors(model, sampling: str, deps_scale: float, samples: int, seed: int, stress=None) -> tuple:
    """(relative RMS error, worst sample's relative error) over `samples` held-out triples: the second is
    max ||grad Psi - Ptilde|| / sqrt(mean ||Ptilde||^2), which finds the few samples where a network
    extrapolates wildly and that an RMS over many samples averages away."""
    spec = sampling_spec(model.training_material, sampling, deps_scale)
    stress = stress or model.stress_nd
    num = den = worst = 0.0
    for k, start in enumerate(range(0, samples, CHUNK)):
        b = sample_batch(spec, min(CHUNK, samples - start), seed, step=k, stream="eval")
        g = model.gradient(b.F, b.F0, b.h) / model.E
        with torch.no_grad():
            P = stress(b.F, b.h)
        err = ((g - P) ** 2).flatten(1).sum(1)
        num += float(err.sum())
        den += float((P**2).sum())
        worst = max(worst, float(err.max()))
    return (num / den) ** 0.5, (worst * samples / den) ** 0.5


def error_at_F0(model, samples: int, seed: int) -> float:
    """max ||grad Psi(F0, F0, h) - Ptilde(F0, h)|| / max(||Ptilde(F0, h)||, 1e-3 mu) (float64)."""
    spec = sampling_spec(model.training_material, "paper")
    worst = 0.0
    floor = 1e-3 * model.training_material.mu
    for k, start in enumerate(range(0, samples, CHUNK)):
        b = sample_batch(spec, min(CHUNK, samples - start), seed, step=k, stream="eval")
        g = model.gradient(b.F0, b.F0, b.h) / model.E
        with torch.no_grad():
            P0 = model.stress_nd(b.F0, b.h)
        err = torch.linalg.matrix_norm(g - P0) / torch.clamp(torch.linalg.matrix_norm(P0), min=floor)
        worst = max(worst, float(err.max()))
    return worst


#: Samples of the Hessian error (d^2 backward passes each, and 2 d^2 stress evaluations for the target).
HESSIAN_SAMPLES = 2000


def hessian_error(model, samples: int, seed: int, sampling: str = "near") -> float:
    """sqrt(sum ||Hess_F Psi - sym(d Ptilde/dF)||^2 / sum ||sym(d Ptilde/dF)||^2) at w = 0, the Jacobian of
    the training target by central differences (float64). "near" sampling: the states a Newton solve visits."""
    spec = sampling_spec(model.training_material, sampling)
    b = sample_batch(spec, samples, seed, step=0, stream="eval")
    H = model.hessian(b.F, b.F0, b.h) / model.E
    n, d = b.F.shape[0], model.dim
    columns = []
    with torch.no_grad():
        for k in range(d * d):
            E = torch.zeros(d * d, dtype=torch.float64)
            E[k] = 1e-6
            E = E.reshape(d, d)
            columns.append(((model.stress_nd(b.F + E, b.h) - model.stress_nd(b.F - E, b.h)) / 2e-6).reshape(n, -1))
    J = torch.stack(columns, -1)
    S = 0.5 * (J + J.transpose(1, 2))
    return float(((H - S) ** 2).sum() / (S**2).sum()) ** 0.5


#: The error map of a parametric model: bin centres per parameter (fewer with more parameters, so that the
#: grid stays ~25-81 points), held-out samples per point.
MAP_BINS = {1: 9, 2: 5, 3: 4, 4: 3}
MAP_SAMPLES = 8192


def parameter_error_map(model, seed: int = EVAL_SEED, samples: int = MAP_SAMPLES, bins: int | None = None) -> dict:
    """The relative RMS gradient error (paper sampling 1x) of a parametric model at the centre of each bin of
    a regular grid over its parameter box: {"fields", "bins", "samples", "points": [{"values", "paper_1x"}],
    "mean", "max", "max_over_mean"}; the same held-out samples at every point."""
    space = model.parameters
    n = bins or MAP_BINS.get(len(space), 3)
    axes = [[r.lo + (r.hi - r.lo) * (k + 0.5) / n for k in range(n)] for r in space.ranges]
    points = []
    for values in itertools.product(*axes):
        bound = model.at(space.description_at(values))
        points.append({"values": [round(v, 6) for v in values],
                       "paper_1x": relative_rms_error(bound, "paper", 1.0, samples, seed)})
    errors = [p["paper_1x"] for p in points]
    mean = sum(errors) / len(errors)
    return {"fields": list(space.fields), "bins": n, "samples": samples, "points": points,
            "mean": mean, "max": max(errors), "max_over_mean": max(errors) / mean}


def evaluate_energy(model, samples: int = 100_000, seed: int = EVAL_SEED) -> dict:
    """The errors of an energy model (a LearnedEnergy) as a JSON-ready dict."""
    t0 = time.perf_counter()
    out = {"samples": samples, "seed": seed, "target": "library return mapping"}
    errors = {(s, c): gradient_errors(model, s, c, samples, seed) for s in SAMPLINGS for c in DEPS_SCALES}
    out["rel_rms"] = {s: {_scale_key(c): errors[s, c][0] for c in DEPS_SCALES} for s in SAMPLINGS}
    out["worst_sample_rel"] = {s: {_scale_key(c): errors[s, c][1] for c in DEPS_SCALES} for s in SAMPLINGS}
    if model.return_map is not None:
        out["target"] = "learned return mapping (the training target)"
        exact = ElastoplasticStress(model.training_material)
        out["rel_rms_vs_exact_return_map"] = {
            s: {_scale_key(1.0): relative_rms_error(model, s, 1.0, samples, seed, stress=exact)} for s in SAMPLINGS
        }
    out["at_F0_max_rel"] = error_at_F0(model, samples, seed)
    out["hessian_rel_rms_near"] = hessian_error(model, min(samples, HESSIAN_SAMPLES), seed)
    if getattr(model, "parameters", None) is not None:
        out["parameter_values"] = list(model.parameter_values)
        out["parameter_map"] = parameter_error_map(model, seed=seed, samples=min(samples, MAP_SAMPLES))
    out["wall_seconds"] = round(time.perf_counter() - t0, 2)
    return out


def evaluate_return_map(model, samples: int = 100_000, seed: int = EVAL_SEED) -> dict:
    """The errors of a learned return mapping (a LearnedReturnMap) as a JSON-ready dict."""
    t0 = time.perf_counter()
    material: Material = model.material
    Sigma, h = sample_return_map_states(model.dim, samples, seed, stream="eval")
    with torch.no_grad():
        mask = return_map_net.yielding(material, Sigma, h)
        Sigma, h = Sigma[mask], h[mask]
        Z = model.project(Sigma, h)
        y = material.yield_function(Z, h)
        rel_y = y.abs() / (2.0 * material.mu * h) ** 2
        surface = y.abs() / material.yield_scale(Z, h)
        eps, _, n = return_map_net.flow_path(Sigma)
        Z_exact = material.return_map(Sigma, h)[0]
        dg_exact = ((eps - torch.log(Z_exact)) * n).sum(-1)
        dg_err = (model.dgamma(Sigma, h) - dg_exact).abs()
    big_h = h >= 0.05
    return {
        "samples": samples,
        "seed": seed,
        "yielding": int(mask.sum()),
        "mean_abs_y_rel": float(rel_y[big_h].mean()),
        "median_abs_y_rel": float(rel_y.median()),
        "frac_within_1e-3": float((surface <= 1e-3).double().mean()),
        "mean_abs_dgamma_error": float(dg_err.mean()),
        "max_abs_dgamma_error": float(dg_err.max()),
        "wall_seconds": round(time.perf_counter() - t0, 2),
    }


def evaluate(model, samples: int = 100_000, seed: int = EVAL_SEED) -> dict:
    """evaluate_energy or evaluate_return_map, by the model's kind."""
    if model.metadata["kind"] == "return_map":
        return evaluate_return_map(model, samples, seed)
    return evaluate_energy(model, samples, seed)


def format_errors(errors: dict, title: str = "") -> str:
    """A plain-text table of `evaluate`'s result."""
    lines = [title] if title else []
    if "rel_rms" in errors:
        lines.append(f"relative RMS gradient error on {errors['samples']} held-out samples ({errors['target']}):")
        lines.append(f"  {'sampling':<10}" + "".join(f"{'deps x' + k[:-1]:>12}" for k in errors["rel_rms"]["paper"]))
        for s, row in errors["rel_rms"].items():
            lines.append(f"  {s:<10}" + "".join(f"{100 * v:>11.3f}%" for v in row.values()))
        if "worst_sample_rel" in errors:
            lines.append("  worst sample, max ||grad Psi - Ptilde|| / RMS ||Ptilde||:")
            for s, row in errors["worst_sample_rel"].items():
                lines.append(f"  {s:<10}" + "".join(f"{v:>12.3f}" for v in row.values()))
        if "rel_rms_vs_exact_return_map" in errors:
            vs = errors["rel_rms_vs_exact_return_map"]
            lines.append(
                "  against the library's root-find return mapping (deps x1): "
                + ", ".join(f"{s} {100 * v['1x']:.3f}%" for s, v in vs.items())
            )
        lines.append(f"  at F = F0 (max relative, float64): {errors['at_F0_max_rel']:.3e}")
        if "parameter_map" in errors:
            m = errors["parameter_map"]
            lines.append(
                f"  at the reference material ({', '.join(f'{f} = {v:g}' for f, v in zip(m['fields'], errors['parameter_values']))}); "
                f"over the parameter box ({m['bins']} bins per parameter, {len(m['points'])} points, paper 1x): "
                f"mean {100 * m['mean']:.3f}%, worst {100 * m['max']:.3f}% ({m['max_over_mean']:.2f}x the mean)"
            )
        if "hessian_rel_rms_near" in errors:
            lines.append(
                f"  Hessian vs sym(d Ptilde/dF), near sampling (relative RMS): {100 * errors['hessian_rel_rms_near']:.3f}%"
            )
    else:
        lines.append(f"learned return mapping on {errors['yielding']} yielding of {errors['samples']} samples:")
        lines.append(f"  mean |y(Z)| / (2 mu h)^2 (h >= 0.05):   {errors['mean_abs_y_rel']:.3e}")
        lines.append(f"  median |y(Z)| / (2 mu h)^2:            {errors['median_abs_y_rel']:.3e}")
        lines.append(f"  fraction within 1e-3 of the surface:   {errors['frac_within_1e-3']:.4f}")
        lines.append(
            f"  |dgamma - dgamma_exact| mean / max:    {errors['mean_abs_dgamma_error']:.3e} / "
            f"{errors['max_abs_dgamma_error']:.3e}"
        )
    lines.append(f"  ({errors['wall_seconds']} s)")
    return "\n".join(lines)


def main(argv=None) -> int:
    from ..model import load_model

    parser = argparse.ArgumentParser(prog="python -m plasticitynet.model_errors", description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="model file (.pt)")
    parser.add_argument("--samples", type=int, default=100_000, help="held-out samples (default 1e5)")
    parser.add_argument("--seed", type=int, default=EVAL_SEED, help=f"held-out seed (default {EVAL_SEED})")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--threads", type=int, default=None, help="torch threads")
    args = parser.parse_args(argv)
    if args.samples <= 0:
        parser.error(f"--samples {args.samples}: must be > 0")
    if args.threads:
        torch.set_num_threads(args.threads)
    try:
        model = load_model(args.model)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    errors = evaluate(model, args.samples, args.seed)
    print(json.dumps(errors, indent=2) if args.json else format_errors(errors, title=args.model))
    return 0


if __name__ == "__main__":
    sys.exit(main())
