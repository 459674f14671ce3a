#!/usr/bin/env bash
# The main job of the README: the full pipeline on the built-in simulated paper experiment.
# Simulates a training and a validation run of the paper's oven test (2 h at 200 Hz each, seeds 1
# and 2), fits the baselines and scores them; everything lands in OUT (default out/).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
OUT=${OUT:-out}
mkdir -p "$OUT"
trainer simulate --protocol paper-oven --seed 1 -o "$OUT/train.npz"
trainer simulate --protocol paper-oven --seed 2 -o "$OUT/valid.npz"
for method in pla poly3; do
  trainer fit --method "$method" "$OUT/train.npz" -o "$OUT/$method.pt"
  trainer evaluate "$OUT/$method.pt" "$OUT/valid.npz" --out-dir "$OUT/eval-$method"
done
echo "pipeline done: reports and figures in $OUT/"
