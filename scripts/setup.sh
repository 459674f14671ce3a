#!/usr/bin/env bash
# Installs mems-tdc and its Python dependencies (torch from PyPI: the first install takes minutes).
# Usage: scripts/setup.sh [test]   -- "test" adds the test tools (pytest, hypothesis, ruff).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
extra=""
[ "${1:-}" = "test" ] && extra="[test]"
stamp=".setup-stamp${extra:+-test}"
# Reinstall only when pyproject.toml changed since the last successful install.
# Reinstall also when the installed package is another checkout's (an editable install elsewhere).
installed_here() {
  "$PYTHON" -c 'import os, sys, trainer, codegen
sys.exit(os.path.dirname(os.path.dirname(os.path.abspath(trainer.__file__))) != os.getcwd())' 2>/dev/null
}
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || ! installed_here; then
  "$PYTHON" -m pip install --quiet --disable-pip-version-check --root-user-action=ignore -e ".${extra}"
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
