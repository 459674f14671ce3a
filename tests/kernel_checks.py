"""Shared checks of the hand-written C kernel headers (codegen/kernels/) and the Cortex-M4 driver."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

from codegen.hostbuild import FIRMWARE_WARNINGS, STRICT_FLAGS

ROOT = Path(__file__).resolve().parents[1]
KERNELS = ROOT / "codegen" / "kernels"


def cortex_m_driver() -> ModuleType:
    """firmware_c/cortex_m.py (firmware_c/ is no package: imported by path)."""
    spec = importlib.util.spec_from_file_location("cortex_m", ROOT / "firmware_c" / "cortex_m.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("cortex_m", module)
    spec.loader.exec_module(module)
    return module


def assert_header_warning_free(compiler: str, header: str, harness: Path, work: Path) -> None:
    """``header`` alone in a unit, and its test harness, compile silently at -O0 and -O2."""
    unit = work / "unit.c"
    unit.write_text(f'#include "{header}"\nint unit_marker(void);\nint unit_marker(void) {{ return 0; }}\n')
    for opt in ("-O0", "-O2"):
        for source in (unit, harness):
            cmd = [compiler, *STRICT_FLAGS, *FIRMWARE_WARNINGS, opt, f"-I{KERNELS}", "-c", str(source)]
            cmd += ["-o", str(work / "x.o")]
            result = subprocess.run(cmd, capture_output=True, text=True, check=False)
            assert result.returncode == 0 and not result.stderr, f"{source.name} {opt}: {result.stderr}"
