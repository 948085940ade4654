#!/usr/bin/env bash
# Trains the models shipped in models/ with the CPU recipes recorded in
# models/MANIFEST (float32 network, OpenBLAS, the principal input, "mixed"
# sampling: half the paper's (F, F0) pairs, half F near F0, Hessian loss weight 0.1):
#   every energy: batch 512, 40000 Adam steps, lr 0.01 with 1000 linear warm-up
#   steps then cosine to 1e-4 (issue 32: the error falls with the number of
#   optimizer steps, not with samples; notebooks/results/model_eval/recipe/),
#   one thread: 25-45 min each on one core (two queues side by side with --threads 1);
#   except snow_2d: batch 8192, 15000 steps, x0.95 every 300 (the small batch gave
#   12.3% against 9.8%: snow's targets are far from a gradient field, and its
#   gradient noise calls for the larger batch);
#   metal_nh_rm_2d (learned return mapping): batch 4096, 20000 steps, x0.95 every 400;
#   sand_3d and metal_3d: twice Table 2's width (128 128 128), sand_3d batch 512 x 20000 steps on one
#   CPU thread, metal_3d batch 4096 x 11100 steps on a GPU (issue 32, third pass);
#   the parametric energies (<material>_param_<dim>d, --parametric: the material's parameters as
#   inputs, docs/physics.md): 64 wide in 2D, batch 512 x 40000 cosine steps.
# The paper's full recipe (batch 2^16, 20000 steps, x0.95 every 1000) remains
# the default of train.py for a GPU.
# Usage: scripts/train_shipped_models.sh [--threads N] [MODEL ...]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
py=.venv/bin/python
threads=1  # the recorded recipes ran on one thread each
if [[ "${1:-}" == --threads ]]; then threads=$2; shift 2; fi
common=(--lr 0.01 --seed 0 --threads "$threads" --no-progress)
models=("$@")
((${#models[@]})) || models=(sand_2d snow_2d metal_2d metal_nh_rm_2d metal_nh_2d sand_3d snow_3d metal_3d
                             sand_param_2d snow_param_2d metal_param_2d)
for model in "${models[@]}"; do
  material=${model%_*d}; dim=${model##*_}; dim=${dim%d}
  parametric=()
  if [[ $material == *_param ]]; then material=${material%_param}; parametric=(--parametric); fi
  case "$model" in
    *_param_2d)    schedule=(--hidden 64 64 64 --batch 512 --epochs 40000 --schedule cosine --warmup 1000
                             --sampling mixed --eval-every 2000 --representation principal --hessian-weight 0.1
                             --checkpoint-every 1000) ;;
    metal_nh_rm_*) schedule=(--batch 4096 --epochs 20000 --decay-steps 400 --lr-decay 0.95 --eval-every 5000) ;;
    snow_2d)       schedule=(--batch 8192 --epochs 15000 --decay-steps 300 --lr-decay 0.95 --sampling mixed
                             --eval-every 1000 --representation principal --hessian-weight 0.1) ;;
    sand_3d|metal_3d)  # twice Table 2's width, 50000 steps: ~47 min each on one thread
                   schedule=(--hidden 128 128 128 --batch 512 --epochs 50000 --schedule cosine --warmup 1000
                             --sampling mixed --eval-every 2500 --representation principal --hessian-weight 0.1
                             --checkpoint-every 1000) ;;
    *)             schedule=(--batch 512 --epochs 40000 --schedule cosine --warmup 1000 --sampling mixed
                             --eval-every 1600 --representation principal --hessian-weight 0.1) ;;
  esac
  echo "=== $model ($(date -u +%H:%M:%S))"
  $py train.py --material "$material" --dim "$dim" "${parametric[@]}" "${schedule[@]}" "${common[@]}"
done
