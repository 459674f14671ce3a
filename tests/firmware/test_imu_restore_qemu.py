"""``NAME_restore`` of the one-IMU module on the Cortex-M4 (QEMU mps2-an386; docs/imu-module.md,
"Save/restore").

Two modules, the layouts of the docs' cost table: one physics channel (a rate term and a branch
offset) beside two cubics, and two physics channels (a lag and three branch offsets started from
room temperature; a rate term and one branch offset) beside a cubic. Built by firmware_c/Makefile's
``imu-restore-app`` (harness/imu_restore_app.c, strict warnings, -Werror), each runs the temperature
history of tests/export/test_codegen_instances.py (every play operator dragged both ways): NAME_init,
the samples before the cut, the whole state copied byte for byte into a buffer, NAME_restore into a
never-initialised state under a copy of the calibration at another address, the rest. Its outputs,
flags and sample counter must equal, bit for bit, the same run of the module built for the host
(cffi) and each channel's golden model run without interruption. A copy with a bit of its
``restore_id`` flipped, with a physics word beyond its bound or erased (0xFF) is refused (0): the
run goes on as after NAME_init, equal to the host's and to the golden models started afresh at the
cut. Skipped, with the reason, only when the toolchain cannot be installed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from codegen import cortex_m as cm
from codegen.cli import main as codegen_main
from codegen.imu import ImuModel, imu_golden, load_imu
from codegen.imu_record import KIND_CUBIC, KIND_PHYSICS
from codegen.imu_verify import load_host_module
from tests.export.test_codegen_instances import EFFECTS, ONE, history_c, physics_model, save_physics
from tests.export.test_imu_restore import cubic_checkpoint

NAME = "imu0"
ROOM_C = 25.0  # the three-play channel's play operators start here at power-on
CUT = 4_700  # on the cooling ramp after the 80 degC peak: every play operator off its start
I32_MAX = 2**31 - 1
MODES = {0: "kept", 1: "restore_id bit flipped", 2: "temp_prev beyond its bound", 3: "erased (0xFF)"}


@dataclass(frozen=True)
class Module:
    out: Path
    imu: ImuModel
    build: cm.Build
    ffi: Any
    lib: Any


@pytest.fixture(scope="module", autouse=True)
def toolchain() -> None:
    reason = cm.ensure_toolchain()
    if reason is not None:
        pytest.skip(f"Cortex-M toolchain unavailable: {reason}")


def layout_paths(layout: str, root: Path) -> list[Path]:
    """The docs' two modules: 1 physics (rate, branch) + 2 cubics; 2 physics + 1 cubic."""
    if layout == "1 physics + 2 cubic":
        return [
            save_physics(physics_model(ONE, None), root / "accel0_x.pt", "accel0_x"),
            cubic_checkpoint(root / "accel0_y.pt", "accel0_y"),
            cubic_checkpoint(root / "accel0_z.pt", "accel0_z", c0_mg=-2.0),
        ]
    return [
        save_physics(physics_model(EFFECTS, ROOM_C), root / "accel0_x.pt", "accel0_x"),
        save_physics(physics_model(ONE, None), root / "accel0_y.pt", "accel0_y"),
        cubic_checkpoint(root / "accel0_z.pt", "accel0_z"),
    ]


@pytest.fixture(scope="module", params=["1 physics + 2 cubic", "2 physics + 1 cubic"])
def module(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Module:
    root = tmp_path_factory.mktemp("imu-restore-m4")
    paths = layout_paths(request.param, root)
    out = root / "c"
    assert codegen_main(["export", *map(str, paths), "-o", str(out), "--name", NAME]) == 0
    imu = load_imu(paths)
    physics = 1 if request.param.startswith("1") else 2
    assert [c.kind for c in imu.channels] == [KIND_PHYSICS] * physics + [KIND_CUBIC] * (3 - physics)
    build = cm.Build(out, NAME, root / "build")
    build.make("imu-restore-app")  # strict warnings, -Werror
    ffi, lib = load_host_module(out, NAME)
    return Module(out, imu, build, ffi, lib)


def inputs() -> tuple[np.ndarray, np.ndarray]:
    temp = np.round(1000 * history_c()).astype(np.int64)[:, None]
    raw = np.random.default_rng(13).integers(-(2**24), 2**24, (temp.shape[0], 3))
    return raw, temp


def on_target(m: Module, raw: np.ndarray, temp: np.ndarray, mode: int, work: Path) -> tuple[Any, ...]:
    """(outputs, flags, samples, restore's result) of imu_restore_app under QEMU."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "vectors.bin").write_bytes(np.concatenate([raw, temp], axis=1).astype("<i4").tobytes())
    args = ["vectors.bin", "outputs.bin", "state.bin", str(CUT), str(mode)]
    stdout = cm.run_qemu(m.build.elf("imu_restore_app"), args, cwd=work)
    info = dict(line.split(" ", 1) for line in stdout.splitlines() if " " in line)
    assert int(info["records"]) == len(raw), stdout
    out = np.fromfile(work / "outputs.bin", dtype="<i4").reshape(raw.shape).astype(np.int64)
    state = np.fromfile(work / "state.bin", dtype="<u4")
    return out, [int(v) for v in state[:-1]], int(state[-1]), int(info["restore"])


def on_host(m: Module, raw: np.ndarray, temp: np.ndarray, mode: int) -> tuple[Any, ...]:
    """The same run of the module built for the host (cffi): the copy changed as the harness does."""
    ffi, lib = m.ffi, m.lib
    raw_c = np.ascontiguousarray(raw, dtype=np.int32)
    temp_c = np.ascontiguousarray(temp, dtype=np.int32)
    out = np.empty_like(raw_c)
    r, t, o = (ffi.from_buffer("int32_t[]", a) for a in (raw_c, temp_c, out))
    first = ffi.new(f"{NAME}_state_t *")
    lib.imu0_init(first, lib.imu0_builtin())
    for k in range(CUT):
        lib.imu0_step(first, r + 3 * k, t + k, o + 3 * k)
    saved = ffi.from_buffer(f"{NAME}_state_t *", bytearray(bytes(ffi.buffer(first))))
    if mode == 1:
        saved.restore_id ^= 1
    elif mode == 2:
        saved.physics[0].temp_prev = I32_MAX
    elif mode == 3:
        ffi.memmove(saved, b"\xff" * ffi.sizeof(saved[0]), ffi.sizeof(saved[0]))
    size = ffi.sizeof(f"{NAME}_state_t")
    resumed = ffi.from_buffer(f"{NAME}_state_t *", bytearray(b"\x5a" * size))
    cal = ffi.new(f"{NAME}_calibration_t *")
    ffi.memmove(cal, lib.imu0_builtin(), ffi.sizeof(f"{NAME}_calibration_t"))
    status = lib.imu0_restore(resumed, cal, saved)
    for k in range(CUT, len(raw_c)):
        lib.imu0_step(resumed, r + 3 * k, t + k, o + 3 * k)
    return out.astype(np.int64), [int(v) for v in resumed.flags], int(resumed.samples), int(status)


@pytest.mark.parametrize("mode", list(MODES), ids=list(MODES.values()))
def test_a_state_saved_and_restored_on_the_m4_continues_as_on_the_host_and_a_damaged_copy_is_refused(
    module: Module, mode: int, tmp_path: Path
) -> None:
    raw, temp = inputs()
    target = on_target(module, raw, temp, mode, tmp_path)
    host = on_host(module, raw, temp, mode)
    # the M4 and the host: the same outputs bit for bit, flags, samples and restore result
    np.testing.assert_array_equal(target[0], host[0])
    assert target[1:] == host[1:]
    # and what the contract says, from each channel's golden model (numpy integers, not the C)
    uninterrupted, flags, samples = imu_golden(module.imu, raw, temp)
    afresh, fresh_flags, fresh_samples = imu_golden(module.imu, raw[CUT:], temp[CUT:])
    np.testing.assert_array_equal(target[0][:CUT], uninterrupted[:CUT])
    if mode == 0:
        assert target[3] == 1
        np.testing.assert_array_equal(target[0][CUT:], uninterrupted[CUT:])
        assert target[1:3] == (flags, samples)
    else:
        assert target[3] == 0, MODES[mode]
        np.testing.assert_array_equal(target[0][CUT:], afresh)  # as after imu0_init at the cut
        assert target[1:3] == (fresh_flags, fresh_samples)
    # the restore is worth checking: a fresh start at the cut is off on the physics channels
    lost = np.max(np.abs(afresh - uninterrupted[CUT:]), axis=0)
    kinds = [c.kind for c in module.imu.channels]
    assert all((lost[k] > 0) == (kind == KIND_PHYSICS) for k, kind in enumerate(kinds)), lost
