#!/usr/bin/env bash
# Trains the models of the energy-representation ablation (paper sec. 5.2,
# Fig. 11) into models/ablation/: the 2D sand energy in eq. 8's form and in the
# three forms the paper tried first and rejected (train.py --energy-form):
#   sand_2d_eq8              Psi = N(F, F0) - (grad N(F0, F0) - Ptilde(F0)) : F
#   sand_2d_local_identity   Psi = N(F, F0) - grad N(I, F0) : F
#   sand_2d_global_identity  Psi = N(F) - grad N(I) : F
#   sand_2d_global           Psi = N(F)
# All four with one recipe, the paper's (raw [F, F0] input, the loss of eq. 9
# alone, the paper's (F, F0) sampling) at the CPU schedule of the shipped 2D
# sand model (batch 8192, 15000 steps, x0.95 every 300): only the form
# differs. 6-10 min each on one thread (two at a time on 2 cores); then writes
# models/ablation/MANIFEST.
# Usage: scripts/train_ablation_models.sh [--threads N] [FORM ...]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
py=.venv/bin/python
threads=1
if [[ "${1:-}" == --threads ]]; then threads=$2; shift 2; fi
forms=("$@")
((${#forms[@]})) || forms=(eq8 local_identity global_identity global)
for form in "${forms[@]}"; do
  echo "=== sand_2d_$form ($(date -u +%H:%M:%S))"
  $py train.py --material sand --dim 2 --energy-form "$form" --representation raw --sampling paper \
    --hessian-weight 0 --batch 8192 --epochs 15000 --decay-steps 300 --eval-every 1000 \
    --lr 0.01 --lr-decay 0.95 --seed 0 --threads "$threads" --no-progress \
    --out "models/ablation/sand_2d_$form.pt"
done
$py scripts/make_manifest.py --models models/ablation --all
