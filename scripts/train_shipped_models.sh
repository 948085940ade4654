#!/usr/bin/env bash
# Trains the models shipped in models/ with the CPU schedules recorded in
# models/MANIFEST (2 cores, OpenBLAS, float32, the paper's (F, F0) sampling,
# Adam from lr 0.01 decayed x0.95 per period down to 7.7e-4 at the end):
#   sand_2d, snow_2d: batch 8192, 15000 steps, decay every 300 steps (~14 min each);
#   metal_2d, metal_nh_2d and the 3D energies: batch 8192, 5000 steps, decay
#   every 100 steps (~4.5 min in 2D, ~9 min in 3D);
#   metal_nh_rm_2d (learned return mapping): batch 4096, 20000 steps, every 400.
# Since issue 16 every energy takes the frame-indifferent "principal" input
# (--representation; the paper's raw [F, F0, h] was the input before, at the
# same schedules), trains on "mixed" batches (half the paper's (F, F0)
# sampling, half F near F0, where a Newton solve goes) and adds the Hessian
# loss with weight 0.1 (--hessian-weight): the ablations behind that choice are
# in notebooks/results/model_eval/. The Hessian loss doubles the time per step.
# The paper's full recipe (batch 2^16, 20000 steps, x0.95 every 1000) remains
# the default of train.py for a GPU.
# Usage: scripts/train_shipped_models.sh [--threads N] [MODEL ...]
# (two queues can run side by side with --threads 1 each).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
py=.venv/bin/python
threads=2
if [[ "${1:-}" == --threads ]]; then threads=$2; shift 2; fi
common=(--lr 0.01 --lr-decay 0.95 --seed 0 --threads "$threads" --no-progress)
models=("$@")
((${#models[@]})) || models=(sand_2d snow_2d metal_2d metal_nh_rm_2d metal_nh_2d sand_3d snow_3d metal_3d)
for model in "${models[@]}"; do
  material=${model%_*d}; dim=${model##*_}; dim=${dim%d}
  case "$model" in
    metal_nh_rm_*)   schedule=(--batch 4096 --epochs 20000 --decay-steps 400 --eval-every 5000) ;;
    sand_2d|snow_2d) schedule=(--batch 8192 --epochs 15000 --decay-steps 300 --sampling mixed --eval-every 1000
                               --representation principal --hessian-weight 0.1) ;;
    *)               schedule=(--batch 8192 --epochs 5000 --decay-steps 100 --sampling mixed --eval-every 1000
                               --representation principal --hessian-weight 0.1) ;;
  esac
  echo "=== $model ($(date -u +%H:%M:%S))"
  $py train.py --material "$material" --dim "$dim" "${schedule[@]}" "${common[@]}"
done
