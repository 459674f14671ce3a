#!/usr/bin/env bash
# The test command of the README (and of CI): set-up, then the whole suite on both cores.
# Extra arguments go to pytest, e.g. scripts/test.sh --runslow  or  scripts/test.sh tests/test_allan.py
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh test
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MPLBACKEND=Agg
exec "${PYTHON:-python3}" -m pytest -n 2 "$@"
