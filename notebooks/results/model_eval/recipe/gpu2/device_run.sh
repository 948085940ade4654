#!/usr/bin/env bash
# The one device call of issue 32's third pass: a training step's speed on the GPU (bench.log), then the
# runs of runs.txt side by side for the rest of BUDGET seconds (runs/). Usage: device_run.sh OUTDIR [BUDGET]
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../../../../.."
out="${1:?usage: device_run.sh OUTDIR [BUDGET]}"; budget="${2:-560}"
export PYTHONPATH="$PWD/python" PYTHONUNBUFFERED=1
python3 -c 'import torch; print("torch", torch.__version__, torch.cuda.get_device_name(0))'
nproc
for hidden in "64 64 64" "128 128 128"; do
  python3 scripts/bench_training.py --device cuda --threads 1 --batches 13 --steps 32 --materials metal snow \
      --dims 3 --hidden $hidden --hessian-weight 0.1 2>&1 | tee -a "$out/bench.log" | tail -n 5
done
left=$((budget - SECONDS))
echo "training budget ${left} s"
python3 scripts/train_in_budget.py notebooks/results/model_eval/recipe/gpu2/runs.txt --budget "$left" \
    --out "$out/runs" --report 60 --tail 25
# One archive: the device tool brings back only a few files per call (the first call of this pass got 8 of
# 50: one run's). TorchScript files of the device's torch stay behind: weights travel as checkpoints.
tar czf "$out/runs.tgz" -C "$out" --exclude='*.pt' --exclude='probe/*.ckpt' runs && rm -rf "$out/runs"
