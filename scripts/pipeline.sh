#!/usr/bin/env bash
# The main job of the README: the full pipeline on the built-in simulated paper experiment.
# 1. simulates the paper's oven test twice (2 h at 200 Hz each; seeds 1 and 2: training and
#    validation) and two input-test runs with a true acceleration (a tilt sequence, manoeuvres);
# 2. trains every method with the paper's settings (DLSTM, DLSTM+SSA, DLSTM+ISSA, PLA, the PX4-style
#    cubic, the temperature-input DLSTM, the persistence predictor) and scores them like the paper's
#    Table 1 plus the honest metrics (drift left, true input kept): report, figures and models in
#    $OUT/comparison/ (default OUT=out);
# Extra arguments go to 'trainer compare', e.g. scripts/pipeline.sh --iterations 100 --cycles 50
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"  # the project environment
OUT=${OUT:-out}
mkdir -p "$OUT"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MPLBACKEND=Agg
trainer simulate --protocol paper-oven --seed 1 -o "$OUT/train.npz"
trainer simulate --protocol paper-oven --seed 2 -o "$OUT/valid.npz"
trainer simulate --protocol paper-oven --seed 3 --input steps -o "$OUT/input-steps.npz"
trainer simulate --protocol paper-oven --seed 4 --input motion -o "$OUT/input-motion.npz"
trainer compare "$OUT/train.npz" "$OUT/valid.npz" \
  --input-test "$OUT/input-steps.npz" --input-test "$OUT/input-motion.npz" \
  --out-dir "$OUT/comparison" "$@"
# 3. the realistic experiment (trainer/physics/realistic.toml): a sensor with the lag, rate and
#    branch-offset terms measured on the bundled real run, trained on one chamber cycle and
#    validated on another with other ramp rates and the range in another order; every method,
#    including the physics compensator. Report in $OUT/realistic/.
REALISTIC=trainer/physics/realistic.toml
trainer simulate --config "$REALISTIC" --seed 11 -o "$OUT/realistic-train.npz"
trainer simulate --config "$REALISTIC" --protocol realistic-valid --seed 12 -o "$OUT/realistic-valid.npz"
trainer simulate --config "$REALISTIC" --protocol realistic-valid --seed 13 --input steps \
  -o "$OUT/realistic-input-steps.npz"
trainer simulate --config "$REALISTIC" --protocol realistic-valid --seed 14 --input motion \
  -o "$OUT/realistic-input-motion.npz"
trainer compare "$OUT/realistic-train.npz" "$OUT/realistic-valid.npz" \
  --input-test "$OUT/realistic-input-steps.npz" --input-test "$OUT/realistic-input-motion.npz" \
  --out-dir "$OUT/realistic" "$@"
# 4. the same experiment's gyroscope channel (gyro0_x in realistic.toml: the lag, rate and branch
#    offset measured on the real run's gyro x, in deg/s): the cubic against the physics
#    compensator on it (about 20 s). Report in $OUT/realistic-gyro/gyro0_x/.
trainer compare "$OUT/realistic-train.npz" "$OUT/realistic-valid.npz" --channels gyro0_x \
  --methods pla,poly3,physics --out-dir "$OUT/realistic-gyro"
echo "pipeline done: open $OUT/comparison/report.md, $OUT/realistic/report.md and $OUT/realistic-gyro/gyro0_x/report.md"
