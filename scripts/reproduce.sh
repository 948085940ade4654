#!/usr/bin/env bash
# Reproduces a figure, a table or everything through the evaluation workflow (workflow/Snakefile,
# docs/workflow.md): only what is missing or out of date runs.
#
#   scripts/reproduce.sh TARGET [TARGET ...] [--dry-run] [--jobs N] [--profile DIR] [--config KEY=VALUE ...]
#                        [-- SNAKEMAKE OPTIONS]
#
# TARGET: fig04 fig05 fig06_10 fig11 fig12 fig13 fig14_16 table1 time_integrator coupling_3d integrators
#         (its slices integrators_sand, integrators_metal, integrators_snow, integrators_stiff,
#         integrators_stiff_snow, integrators_3d, integrators_snow_3d, integrators_metal_3d, integrators_coupling)
#         sweep_dt sweep_dx
#         all, or one study (results folder): implicit_eval fem_eval ... (--list prints them).
# --dry-run      list the jobs that would run, and why, without running them
# --jobs N       jobs at once (default: every core; each simulation uses `threads` cores, 1 by default)
# --profile DIR  a Snakemake profile, e.g. workflow/profiles/slurm to submit every job to SLURM
# --config K=V   override workflow/config.yaml (scenes, results, work, frames, threads, sweep_scenes, ...)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

known="fig04 fig05 fig06_10 fig11 fig12 fig13 fig14_16 table1 time_integrator coupling_3d integrators integrators_sand integrators_metal integrators_snow integrators_stiff integrators_stiff_snow integrators_3d integrators_snow_3d integrators_metal_3d integrators_coupling sweep_dt sweep_dx all
implicit_eval implicit_eval_2d representation_ablation regularizer_ablation time_integrator_mpm fem_eval fem_eval_2d coupling_eval coupling_eval_3d
integrator_study integrator_study_fem integrator_study_sand integrator_study_metal integrator_study_snow
integrator_study_stiff integrator_study_stiff_snow integrator_study_3d integrator_study_snow_3d integrator_study_metal_3d integrator_study_coupling"
known="${known//$'\n'/ }"
targets=() ; config=() ; extra=() ; dry=0 ; jobs="$(nproc)" ; profile=""
while (($#)); do
  case "$1" in
    --dry-run|-n) dry=1 ;;
    --jobs|-j) jobs="$2"; shift ;;
    --profile) profile="$2"; shift ;;
    --config) shift; while (($#)) && [[ "$1" != --* ]]; do config+=("$1"); shift; done; continue ;;
    --list) echo "$known"; exit 0 ;;
    --help|-h) sed -n '2,13p' "$0" | sed -E 's/^# ?//'; exit 0 ;;
    --) shift; extra=("$@"); break ;;
    -*) echo "reproduce.sh: unknown option $1 (--help)" >&2; exit 2 ;;
    *) targets+=("$1") ;;
  esac
  shift
done
((${#targets[@]})) || { echo "reproduce.sh: name a target (--list), e.g. scripts/reproduce.sh fig05" >&2; exit 2; }
for t in "${targets[@]}"; do
  [[ " $known " == *" $t "* ]] || { echo "reproduce.sh: unknown target \"$t\"; known: $known" >&2; exit 2; }
done

# The environment: the build and .venv (scripts/setup.sh installs snakemake with the rest). The build
# folder is $PNET_BUILD_DIR (default build), as for setup.sh and test.sh.
build_dir="${PNET_BUILD_DIR:-build}"
if [[ ! -x .venv/bin/python || ! -x "$build_dir/cpp/pnet" ]] || ! .venv/bin/python -c 'import snakemake' 2>/dev/null; then
  ./scripts/setup.sh
fi

joined="$(IFS=,; echo "${targets[*]}")"
binaries=("pnet=$build_dir/cpp/pnet" "bench=$build_dir/cpp/bench/bench_table1")
args=(--snakefile workflow/Snakefile --directory "$root" --config "targets=$joined" "${binaries[@]}" "${config[@]}"
      --rerun-triggers mtime input --keep-going --printshellcmds)
if [[ -n "$profile" ]]; then
  args+=(--profile "$profile")
else
  args+=(--cores "$jobs")
fi
if ((dry)); then
  exec .venv/bin/python -m snakemake "${args[@]}" --dry-run --reason "${extra[@]}"
fi
exec .venv/bin/python -m snakemake "${args[@]}" "${extra[@]}"
