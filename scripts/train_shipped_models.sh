#!/usr/bin/env bash
# Trains the models shipped in models/ with the CPU schedule recorded in
# models/MANIFEST (2 cores, OpenBLAS): batch 8192, 5000 steps, Adam lr 0.01
# decayed x0.95 every 100 steps, the paper's (F, F0) sampling. The paper's
# full recipe (batch 2^16, 20000 steps, x0.95 every 1000) remains the default
# of train.py for a GPU. Usage: scripts/train_shipped_models.sh [MODEL ...]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
py=.venv/bin/python
schedule=(--batch 8192 --epochs 5000 --lr 0.01 --lr-decay 0.95 --decay-steps 100 --seed 0
          --sampling paper --eval-every 1000 --threads 2 --no-progress)
# The learned return mapping is a smaller problem: more, smaller steps.
rm_schedule=(--batch 4096 --epochs 20000 --lr 0.01 --lr-decay 0.95 --decay-steps 400 --seed 0
             --eval-every 5000 --threads 2 --no-progress)
models=("$@")
((${#models[@]})) || models=(sand_2d snow_2d metal_2d metal_nh_rm_2d metal_nh_2d sand_3d snow_3d metal_3d)
for model in "${models[@]}"; do
  material=${model%_*d}; dim=${model##*_}; dim=${dim%d}
  echo "=== $model ($(date -u +%H:%M:%S))"
  if [[ $material == metal_nh_rm ]]; then
    $py train.py --material "$material" --dim "$dim" "${rm_schedule[@]}"
  else
    $py train.py --material "$material" --dim "$dim" "${schedule[@]}"
  fi
done
