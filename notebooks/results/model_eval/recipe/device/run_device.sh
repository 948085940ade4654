#!/usr/bin/env bash
# Issue 32/36, stop 47: nine CPU trainings at once on the lent 16-core machine (its GPU unused: a training
# step of these small networks is launch-bound there). Two are the first part of from-scratch 100000-step
# runs, stopped at a time limit and resumed on the 2-core machine (train.py --resume); the rest fine-tune
# shipped models (train.py --init-from) for the step count measured to fit. Results: $OUT/runs.tgz.
set -u
PY=${PY:-python3}
R=/tmp/runs; mkdir -p $R
LIMIT=${LIMIT:-470}
common="--no-progress --sampling mixed --representation principal --hessian-weight 0 --seed 0 --checkpoint-every 500 --eval-samples 0"
job() { name=$1; thr=$2; shift 2
  ( timeout -s INT $LIMIT $PY train.py "$@" $common --threads $thr --out $R/$name.pt > $R/$name.log 2>&1
    echo "$name exit $? $(grep -o 'trained.*' $R/$name.log)" ) & }
lscpu | grep -i "model name"; $PY -c "import torch; print('torch', torch.__version__)"
# from scratch, 100000 steps (the shipped recipes but longer): the first part
job snow_3d_100k 1 --material snow --dim 3 --hidden 128 128 128 --batch 512 --epochs 100000 --schedule cosine --warmup 1000 --lr 0.01 --eval-every 2500
job sand_param_3d_100k 1 --material sand --dim 3 --parametric --hidden 128 128 128 --batch 512 --epochs 100000 --schedule cosine --warmup 1000 --lr 0.01 --eval-every 2500
# fine-tuning from the shipped models: lr 1e-3 cosine after 300 warm-up steps
ft="--schedule cosine --warmup 300 --lr 0.001"
job snow_3d_ft8192 4 --material snow --dim 3 --hidden 128 128 128 --batch 8192 --epochs 2000 --eval-every 500 $ft --init-from models/snow_3d.pt
job snow_3d_ft2048 2 --material snow --dim 3 --hidden 128 128 128 --batch 2048 --epochs 6000 --eval-every 1000 $ft --init-from models/snow_3d.pt
job sand_param_3d_ft2048 2 --material sand --dim 3 --parametric --hidden 128 128 128 --batch 2048 --epochs 3500 --eval-every 500 $ft --init-from models/sand_param_3d.pt
job sand_param_3d_ft512 1 --material sand --dim 3 --parametric --hidden 128 128 128 --batch 512 --epochs 12000 --eval-every 2000 $ft --init-from models/sand_param_3d.pt
job sand_2d_ft4096 2 --material sand --dim 2 --hidden 64 64 64 --batch 4096 --epochs 4500 --eval-every 500 $ft --init-from models/sand_2d.pt
job metal_3d_ft2048 2 --material metal --dim 3 --hidden 128 128 128 --batch 2048 --epochs 5500 --eval-every 1000 $ft --init-from models/metal_3d.pt
job metal_2d_ft2048 1 --material metal --dim 2 --batch 2048 --epochs 15000 --eval-every 2500 $ft --init-from models/metal_2d.pt
wait
tar czf $OUT/runs.tgz -C /tmp runs
ls -la $R | head -60
