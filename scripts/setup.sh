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
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || ! "$PYTHON" -c "import trainer, codegen" 2>/dev/null; then
  "$PYTHON" -m pip install --quiet --disable-pip-version-check -e ".${extra}"
  touch "$stamp"
fi
