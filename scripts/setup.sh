#!/usr/bin/env bash
# Installs mems-tdc and its Python dependencies into the project environment .venv (made with
# `python3 -m venv`; the system's Python packages are never touched). torch comes from PyPI: the
# first install takes minutes. Scripts run the tools from .venv/bin; `source .venv/bin/activate`
# puts `trainer` and `codegen` on your PATH.
# Usage: scripts/setup.sh [test]   -- "test" adds the test tools (pytest, hypothesis, ruff, mypy).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
BASE_PYTHON=${PYTHON:-python3}
if [ ! -x "$VENV/bin/python" ]; then
  "$BASE_PYTHON" -m venv "$VENV"
fi
PY="$VENV/bin/python"
extra=""
[ "${1:-}" = "test" ] && extra="[test]"
stamp="$VENV/.setup-stamp${extra:+-test}"
# Reinstall only when pyproject.toml, the pins or the version it reads (trainer/__init__.py) changed since the
# last successful install, or when the environment's package is another checkout's (an editable
# install elsewhere).
installed_here() {
  "$PY" -c 'import os, sys, trainer, codegen
sys.exit(os.path.dirname(os.path.dirname(os.path.abspath(trainer.__file__))) != os.getcwd())' 2>/dev/null
}
# The versions are pinned by scripts/constraints.txt (the ones the docs' numbers were measured with).
constraints=scripts/constraints.txt
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ trainer/__init__.py -nt "$stamp" ] \
  || [ "$constraints" -nt "$stamp" ] || ! installed_here; then
  "$PY" -m pip install --quiet --disable-pip-version-check -c "$constraints" -e ".${extra}"
  touch "$stamp"
fi
# The tests also need C tools beyond gcc (clang, valgrind; the Arm toolchain and QEMU for the
# firmware tests). Each installer is idempotent, fast when everything is present, and never fails.
if [ "${1:-}" = "test" ]; then
  for installer in scripts/install_c_tools.sh scripts/install_arm_tools.sh; do
    [ -x "$installer" ] && "$installer"
  done
fi
exit 0
