"""Cost of a DLSTM channel in the one-module IMU export on a Cortex-M4 (docs/imu-module.md).

Six channels (accel0_x .. gyro0_z) of a synthetic 200 Hz recording (seed 1, 2 min): the module with
every channel a cubic against the same module with accel0_z a recursive DLSTM of the trainer's
default size (10 hidden units, 2 layers; random weights in the trainer's layout, tests/testmodels.py:
the size and the instruction count do not depend on the weight values), and that DLSTM exported alone.
Flash: ``arm-none-eabi-size`` text + data of NAME.o (firmware_c/Makefile ``module``, -O2); RAM: the
caller-owned ``sizeof(NAME_state_t)`` on the target (an object of that size, read with ``nm -S``);
instructions per ``NAME_step`` call: ``codegen verify --cortex-m4`` (QEMU -icount shift=0, SysTick,
the harness's loop subtracted), over the first 60 s; every run also checks bit-exactness.

    python bench/bench_imu_dlstm.py
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from codegen import cortex_m as cm  # noqa: E402
from codegen.export import export  # noqa: E402
from codegen.imu import export_imu  # noqa: E402
from codegen.imu_verify import verify_imu  # noqa: E402
from tests import testmodels as tm  # noqa: E402
from trainer import methods as registry  # noqa: E402
from trainer.data.recording import Recording  # noqa: E402
from trainer.data.recording_io import write_recording  # noqa: E402
from trainer.dlstm.compensators import RecursiveDLSTM  # noqa: E402

RATE_HZ = 200.0
SECONDS = 120
CHANNELS = ("accel0_x", "accel0_y", "accel0_z", "gyro0_x", "gyro0_y", "gyro0_z")


def recording() -> Recording:
    rng = np.random.default_rng(1)
    n = int(SECONDS * RATE_HZ)
    temp = np.linspace(-10.0, 50.0, n)
    u = (temp - 20.0) / 30.0
    columns = {"time_s": np.arange(n) / RATE_HZ, "temp_c": temp}
    for k, name in enumerate(CHANNELS):
        unit = "dps" if name.startswith("gyro") else "mg"
        scale = 0.05 if unit == "dps" else 1.0
        columns[f"{name}_{unit}"] = scale * (k + 2.0 * u - u**2 + 0.5 * u**3) + rng.normal(0, 0.05 * scale, n)
    columns["accel_mg"] = columns["accel0_z_mg"]
    return Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}", "channel": "accel0_z"}, "bench-imu")


def checkpoints(rec: Recording, root: Path, dlstm: str | None) -> list[Path]:
    paths = []
    for name in CHANNELS:
        column = next(c for c in rec.columns if c.startswith(f"{name}_"))
        view = Recording(
            {"time_s": rec.time_s, "temp_c": rec.temp_c, "accel_mg": rec.columns[column]},
            {"sample_rate_hz": f"{RATE_HZ:g}"},
            name,
        )
        method = registry.name_of(RecursiveDLSTM) if name == dlstm else registry.CUBIC
        checkpoint = tm.checkpoint_for(method, view, seed=0)
        unit = "dps" if name.startswith("gyro") else "mg"
        checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": name, "unit": unit}
        paths.append(root / f"{name}.{method}.pt")
        tm.save_checkpoint(checkpoint, paths[-1])
    return paths


def target_sizes(out_dir: Path, name: str, work: Path) -> tuple[int, int]:
    """(flash text + data of NAME.o, sizeof(NAME_state_t)) on the Cortex-M4."""
    build = cm.Build(out_dir, name, work / f"build-{out_dir.name}-{name}")  # one build folder per module
    build.make("module")
    (size,) = cm.sizes(build.out / f"{name}.o")
    probe = work / f"{name}_probe.c"
    probe.write_text(f'#include "{name}.h"\nchar {name}_probe[sizeof({name}_state_t)];\n')
    obj = work / f"{name}_probe.o"
    subprocess.run(
        ["arm-none-eabi-gcc", "-mcpu=cortex-m4", "-mthumb", "-O2", "-fno-common", f"-I{out_dir}", "-c",
         str(probe), "-o", str(obj)],
        check=True,
    )  # fmt: skip
    nm = subprocess.run(["arm-none-eabi-nm", "-S", str(obj)], capture_output=True, text=True, check=True)
    state = next(
        int(line.split()[1], 16) for line in nm.stdout.splitlines() if line.endswith(f"{name}_probe")
    )
    return size.text + size.data, state


def main() -> None:
    reason = cm.ensure_toolchain()
    if reason is not None:
        sys.exit(f"bench_imu_dlstm: {reason}")
    with tempfile.TemporaryDirectory(prefix="bench-imu-dlstm-") as tmp:
        root = Path(tmp)
        rec = recording()
        write_recording(rec, root / "rec.npz")
        part = rec.slice(0, int(60 * RATE_HZ))
        rows = []
        for label, dlstm in (("6 x poly3", None), ("accel0_z dlstm + 5 x poly3", "accel0_z")):
            paths = checkpoints(rec, root, dlstm)
            out = root / label.replace(" ", "_")
            export_imu(paths, out, name="imu_tdc")
            flash, state = target_sizes(out, "imu_tdc", root)
            result = verify_imu(paths, out, part, cortex_m4=True)
            assert result.ok, result.runs
            cost = next(r.instructions_per_step for r in result.runs if r.target == "cortex-m4")
            rows.append((label, flash, state, cost))
            if dlstm:
                alone = root / "alone"
                export(paths[CHANNELS.index(dlstm)], alone, name="tdc_dlstm")
                rows.append(
                    ("the DLSTM alone (one-channel module)", *target_sizes(alone, "tdc_dlstm", root), None)
                )
    print(f"{cm.build_env_note()}; {part.sample_rate_hz:g} Hz, instructions over {len(part)} samples")
    print("| module | code + tables (flash) | state (RAM) | instructions per step |")
    print("|---|---|---|---|")
    for label, flash, state, cost in rows:
        print(f"| {label} | {flash:,} B | {state:,} B | {'-' if cost is None else f'{cost:,.0f}'} |")


if __name__ == "__main__":
    main()
