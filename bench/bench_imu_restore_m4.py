"""Cost of ``NAME_init`` and ``NAME_restore`` of the one-IMU module on a Cortex-M4 (docs/imu-module.md,
"Save/restore").

Both compute a bitwise CRC-32 over the calibration (the state's ``restore_id``), once at power-up.
The modules are the docs' (and tests/firmware/test_imu_restore_qemu.py's): one physics channel (rate
term, branch offset) beside two cubics, and two physics channels (a lag and three branch offsets
started from room temperature; a rate term and one branch offset) beside a cubic.

Instructions: firmware_c/Makefile ``imu-restore-app`` (harness/imu_restore_app.c) under QEMU
mps2-an386 with ``-icount shift=0`` (1 ns per instruction; SysTick at 25 MHz ticks once per 40,
checked by a loop of known length): 64 calls of each, timed as one loop, minus the same loop with an
empty function of the same signature (call and return included). ``NAME_restore`` of the copy kept
(returns 1) and of a copy with one bit of ``restore_id`` flipped (refused: the calibration's id, then
``NAME_init``). ``NAME_step``: ``codegen verify``'s target run (codegen.imu_verify.target_run), per
call over the temperature history, the harness's loop subtracted; both runs check the outputs
against the golden models. Flash: ``arm-none-eabi-size`` text + data of NAME.o (-O2), the functions'
sizes from ``arm-none-eabi-nm -S``; RAM: ``sizeof(NAME_state_t)`` on the target.

    python bench/bench_imu_restore_m4.py
"""

from __future__ import annotations

import importlib
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from codegen import cortex_m as cm  # noqa: E402
from codegen.cli import main as codegen_main  # noqa: E402
from codegen.imu import imu_golden, load_imu  # noqa: E402
from codegen.imu_verify import target_run  # noqa: E402

# The modules and the temperature history are the QEMU test's (one definition of what is measured and
# checked); imported by name, so that mypy's scope (trainer, codegen, bench) does not take in the tests.
QEMU_TEST = importlib.import_module("tests.firmware.test_imu_restore_qemu")
NAME: str = QEMU_TEST.NAME
CUT: int = QEMU_TEST.CUT

LAYOUTS = ("1 physics + 2 cubic", "2 physics + 1 cubic")
FUNCTIONS = ("init", "restore", "calibration_id", "saved_ok", "physics_saved_ok", "step", "load")


def function_sizes(obj: Path) -> dict[str, int]:
    """Code bytes of the module's functions (``nm -S``; static ones included)."""
    out = subprocess.run(["arm-none-eabi-nm", "-S", str(obj)], capture_output=True, text=True, check=True)
    sizes = {}
    for line in out.stdout.splitlines():
        fields = line.split()
        if len(fields) == 4 and fields[2] in "tT" and fields[3].startswith(f"{NAME}_"):
            sizes[fields[3][len(NAME) + 1 :]] = int(fields[1], 16)
    return sizes


def measure(layout: str, root: Path) -> dict[str, float]:
    folder = root / layout.replace(" ", "_").replace("+", "")
    folder.mkdir()
    paths = QEMU_TEST.layout_paths(layout, folder)
    out = folder / "c"
    assert codegen_main(["export", *map(str, paths), "-o", str(out), "--name", NAME]) == 0
    imu = load_imu(paths)
    build = cm.Build(out, NAME, folder / "build")
    build.make("module", "imu-restore-app")
    raw, temp = QEMU_TEST.inputs()
    golden, _, _ = imu_golden(imu, raw, temp)
    work = folder / "run"
    work.mkdir()
    (work / "vectors.bin").write_bytes(np.concatenate([raw, temp], axis=1).astype("<i4").tobytes())
    args = ["vectors.bin", "outputs.bin", "state.bin", str(CUT), "0"]
    stdout = cm.run_qemu(build.elf("imu_restore_app"), args, cwd=work, icount=True)
    target = np.fromfile(work / "outputs.bin", dtype="<i4").reshape(raw.shape)
    if not np.array_equal(target, golden):
        raise SystemExit(f"{layout}: the restored run differs from the golden models on the target")
    lines = {tuple(line.split()[:2]): line.split() for line in stdout.splitlines()}
    fields = {line[0]: line[1:] for line in lines.values()}
    instructions, ticks = (int(v) for v in fields["calibration"])
    per_tick = instructions / ticks
    if abs(per_tick - 1e9 / cm.SYSCLK_HZ) > 0.01:
        raise SystemExit(f"SysTick calibration: {instructions} instructions in {ticks} ticks (-icount off?)")
    result: dict[str, float] = {"restore_result": int(fields["restore"][0])}
    for what in ("init", "restore", "refused"):
        calls, real, null, ones = (int(v) for v in lines[("cost", what)][2:])
        result[what] = (real - null) * per_tick / calls
        result[f"{what}_returned_1"] = ones
    result["state_bytes"] = int(fields["state_bytes"][0])
    step_out, _, _, per_step = target_run(out, NAME, imu, raw, temp, None, folder / "verify", True)
    if not np.array_equal(step_out, golden):
        raise SystemExit(f"{layout}: NAME_step differs from the golden models on the target")
    result["step"] = per_step
    (size,) = cm.sizes(build.out / f"{NAME}.o")
    result["flash"] = size.flash
    for name, value in function_sizes(build.out / f"{NAME}.o").items():
        if name in FUNCTIONS:
            result[f"{name}_bytes"] = value
    return result


def main() -> int:
    reason = cm.ensure_toolchain()
    if reason is not None:
        print(f"skipped: {reason}")
        return 1
    print(f"Cortex-M4 under QEMU mps2-an386, -icount shift=0 ({cm.build_env_note()}); arm-none-eabi-gcc -O2")
    with tempfile.TemporaryDirectory(prefix="bench-imu-restore-") as tmp:
        for layout in LAYOUTS:
            r = measure(layout, Path(tmp))
            print(f"{layout}:")
            print(
                f"  instructions per call: {NAME}_init {r['init']:.1f}, {NAME}_restore kept "
                f"{r['restore']:.1f} (returned 1 in {r['restore_returned_1']:.0f} of 64), refused "
                f"{r['refused']:.1f} (returned 1 in {r['refused_returned_1']:.0f}), {NAME}_step {r['step']:.1f} "
                f"(all channels, over {len(QEMU_TEST.inputs()[0])} samples)"
            )
            sizes = ", ".join(f"{f} {int(r[f + '_bytes'])}" for f in FUNCTIONS if f + "_bytes" in r)
            print(f"  flash {int(r['flash'])} B ({sizes} B); state {int(r['state_bytes'])} B")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
