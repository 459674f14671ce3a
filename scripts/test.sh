#!/usr/bin/env bash
# The test command of the README (and of CI): set-up into .venv, the linters and the type checker
# (a finding fails the run), then the whole suite on both cores.
# Extra arguments go to pytest, e.g. scripts/test.sh --runslow  or  scripts/test.sh tests/scoring/test_allan.py
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh test
BIN=.venv/bin
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MPLBACKEND=Agg
"$BIN/ruff" check trainer codegen tests bench firmware_c
"$BIN/ruff" format --check --quiet trainer codegen tests bench firmware_c
"$BIN/mypy"  # configured in pyproject.toml: trainer, codegen, bench
# worksteal: an idle worker takes tests queued on the busy one (the long fold and finder tests no longer end the run on one core)
exec "$BIN/python" -m pytest -n 2 --dist worksteal "$@"
