#!/usr/bin/env bash
# The main job of the README: set-up, then the full pipeline on the built-in simulated paper
# experiment and the realistic experiment (scripts/main_job.sh says what it runs; results in
# $OUT, default out/). JOBS=N sets how many processes work side by side (default: the cores).
# Extra arguments go to 'trainer compare', e.g. scripts/pipeline.sh --iterations 100 --cycles 50
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"  # the project environment
exec scripts/main_job.sh "$@"
