#!/usr/bin/env bash
# The training checks that need a CUDA GPU, as one script for a machine that has one (it needs python3
# with torch, numpy, matplotlib, tqdm and pytest; the C++ side is not built): the device tests, one
# training step's parts and its profile, and a short training on the GPU with its error curve.
#
#   scripts/gpu_training_check.sh OUTDIR [STEPS]
#
# OUTDIR receives gpu_tests.log, bench.log, profile.log and the short run's curves (train/); the run stops
# after TRAIN_SECONDS (300) with its checkpoint and curve so far.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:?usage: gpu_training_check.sh OUTDIR [STEPS]}"
steps="${2:-3000}"
mkdir -p "$out/train"
export PYTHONPATH="$root/python${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
cd "$root"
python3 -c 'import torch; print("torch", torch.__version__, "cuda", torch.cuda.is_available(), torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")'
echo "[gpu] device tests"
python3 -m pytest -q -p no:cacheprovider tests/python/test_training_parallel.py tests/python/test_training_trainer.py \
    -k "not end_to_end" -rs 2>&1 | tee "$out/gpu_tests.log" | tail -n 15
echo "[gpu] one training step: parts and steps per second"
python3 scripts/bench_training.py --device cuda --threads 4 --batches 11 13 16 --steps 10 --materials metal snow \
    --dims 3 2 2>&1 | tee "$out/bench.log" | grep -v '^ *$'
python3 scripts/bench_training.py --device cuda --threads 4 --batches 13 --steps 3 --materials metal --dims 3 \
    --profile > "$out/profile.log" 2>&1
echo "[gpu] a short training on the GPU: metal 3D, batch 8192, cosine, $steps steps"
timeout "${TRAIN_SECONDS:-300}" python3 train.py --material metal --dim 3 --device cuda --batch 8192 --epochs "$steps" --schedule cosine \
    --warmup 200 --sampling mixed --hessian-weight 0.1 --eval-every $((steps / 10)) --eval-samples 100000 \
    --no-progress --out "$out/train/metal_3d_gpu.pt" 2>&1 | tail -n 12
