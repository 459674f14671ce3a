#!/usr/bin/env bash
# The main job's steps (scripts/pipeline.sh = scripts/setup.sh + this), in the current environment:
# 1. simulates the paper's oven test twice (2 h at 200 Hz each; seeds 1 and 2: training and
#    validation) and two input-test runs with a true acceleration (a tilt sequence, manoeuvres),
#    and the same four runs of the realistic experiment (trainer/physics/realistic.toml: a sensor
#    with the lag, rate and branch-offset terms measured on the bundled real run, trained on one
#    chamber cycle, validated on another with other ramp rates and the range in another order);
# 2. three comparisons: the paper experiment (every method with the paper's settings, scored like
#    the paper's Table 1 plus the honest metrics: drift left, true input kept; $OUT/comparison/),
#    the realistic experiment ($OUT/realistic/) and its gyroscope channel gyro0_x, the cubic against
#    the physics compensator ($OUT/realistic-gyro/gyro0_x/).
# JOBS (default: the machine's cores) processes work side by side: the simulations, the three
# comparisons, and each comparison's fits (trainer compare --jobs); the tables are the same as
# with JOBS=1, which runs every step one after another. Each comparison's table is printed when
# all are done; their progress lines are prefixed with the comparison's name.
# Extra arguments go to 'trainer compare', e.g. scripts/main_job.sh --iterations 100 --cycles 50
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out}
JOBS=${JOBS:-$(nproc)}
mkdir -p "$OUT"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MPLBACKEND=Agg
pids=()
trap 'for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done' EXIT
# Runs "$@" in the background when JOBS > 1 (at most JOBS at a time), else now.
start() {
  if [ "$JOBS" -gt 1 ]; then
    while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do wait -n; done
    "$@" &
    pids+=($!)
  else
    "$@"
  fi
}
finish() {  # waits for every started step; a failed one fails the job
  for pid in "${pids[@]}"; do wait "$pid"; done
  pids=()
}
REALISTIC=trainer/physics/realistic.toml
start trainer simulate --config "$REALISTIC" --seed 11 -o "$OUT/realistic-train.npz"
start trainer simulate --config "$REALISTIC" --protocol realistic-valid --seed 12 -o "$OUT/realistic-valid.npz"
start trainer simulate --config "$REALISTIC" --protocol realistic-valid --seed 13 --input steps \
  -o "$OUT/realistic-input-steps.npz"
start trainer simulate --config "$REALISTIC" --protocol realistic-valid --seed 14 --input motion \
  -o "$OUT/realistic-input-motion.npz"
start trainer simulate --protocol paper-oven --seed 1 -o "$OUT/train.npz"
start trainer simulate --protocol paper-oven --seed 2 -o "$OUT/valid.npz"
start trainer simulate --protocol paper-oven --seed 3 --input steps -o "$OUT/input-steps.npz"
start trainer simulate --protocol paper-oven --seed 4 --input motion -o "$OUT/input-motion.npz"
finish
# The comparisons: one after another with JOBS=1; else side by side, each fitting with --jobs.
names=()
compare() {  # NAME ARGS...: the table goes to $OUT/NAME.txt, printed at the end
  local name=$1
  shift
  names+=("$name")
  if [ "$JOBS" -gt 1 ]; then
    trainer compare "$@" --jobs "$JOBS" >"$OUT/$name.txt" 2> >(sed -u "s/^/[$name] /" >&2) &
    pids+=($!)
  else
    trainer compare "$@" >"$OUT/$name.txt"
  fi
}
# the longest first
compare realistic "$OUT/realistic-train.npz" "$OUT/realistic-valid.npz" \
  --input-test "$OUT/realistic-input-steps.npz" --input-test "$OUT/realistic-input-motion.npz" \
  --out-dir "$OUT/realistic" "$@"
compare comparison "$OUT/train.npz" "$OUT/valid.npz" \
  --input-test "$OUT/input-steps.npz" --input-test "$OUT/input-motion.npz" \
  --out-dir "$OUT/comparison" "$@"
compare realistic-gyro "$OUT/realistic-train.npz" "$OUT/realistic-valid.npz" --channels gyro0_x \
  --methods pla,poly3,physics --out-dir "$OUT/realistic-gyro"
finish
for name in comparison realistic realistic-gyro; do
  echo "== $name"
  cat "$OUT/$name.txt"
done
echo "main job done: open $OUT/comparison/report.md, $OUT/realistic/report.md and $OUT/realistic-gyro/gyro0_x/report.md"
