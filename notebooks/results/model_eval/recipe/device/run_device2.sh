#!/usr/bin/env bash
# Issue 32/36, stop 47, second lease: a second fine-tuning of the two models still short of their targets
# (snow_3d and sand_param_3d, each from its first fine-tuning, carried in out/ft_init/), four variants each
# side by side on the 16 cores, about three minutes each. Results: $OUT/runs2.tgz.
set -u
PY=${PY:-python3}
R=/tmp/runs2; mkdir -p $R
LIMIT=${LIMIT:-215}
common="--no-progress --sampling mixed --representation principal --hessian-weight 0 --seed 0 --checkpoint-every 500 --eval-samples 0 --schedule cosine --warmup 200"
job() { name=$1; thr=$2; n=$3; shift 3
  ( timeout -s INT $LIMIT $PY train.py "$@" $common --epochs $n --eval-every $n --threads $thr --out $R/$name.pt > $R/$name.log 2>&1
    echo "$name exit $? $(grep -o 'trained.*' $R/$name.log)" ) & }
snow="--material snow --dim 3 --hidden 128 128 128 --init-from out/ft_init/snow_3d_a.pt"
sand="--material sand --dim 3 --parametric --hidden 128 128 128 --init-from out/ft_init/sand_param_3d_a.pt"
job snow_3d_b2048 2 2900 $snow --batch 2048 --lr 5e-4
job snow_3d_b4096 2 1500 $snow --batch 4096 --lr 5e-4
job snow_3d_b8192 4 1100 $snow --batch 8192 --lr 3e-4
job snow_3d_b1024 1 3800 $snow --batch 1024 --lr 5e-4
job sand_param_3d_b512 1 5000 $sand --batch 512 --lr 5e-4
job sand_param_3d_b2048 2 1700 $sand --batch 2048 --lr 5e-4
job sand_param_3d_b1024 2 2500 $sand --batch 1024 --lr 5e-4
job sand_param_3d_b4096 2 850 $sand --batch 4096 --lr 5e-4
wait
tar czf $OUT/runs2.tgz -C /tmp runs2
