"""The generated module on the target architecture: Cortex-M4F (arm-none-eabi-gcc, strict flags,
-Werror) running under QEMU's mps2-an386 board, compared with the golden model sample by sample.

Models are trained by the real ``trainer fit`` (small settings) on a simulated oven run; the
stream is another simulated run (5 min at 200 Hz, the whole temperature ramp) followed by a burst
of extreme inputs (int32 limits, full scale, maximum temperature slew) that drives the clamping and
saturation paths, with a reset and an init in between. Every output and the final state structs
must be identical to the golden model's. Skipped, with the reason, only when the toolchain cannot
be installed (scripts/install_arm_tools.sh).
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from codegen import cortex_m as cm
from codegen.export import LoadedModel, export
from codegen.family import QuantModel
from codegen.golden_select import golden_for
from codegen.hostbuild import CMD_INIT, CMD_RESET, load_module
from codegen.verify import to_step_units
from tests.golden_checks import replay
from tests.repo import REPO_ROOT
from trainer.cli import main as trainer_main
from trainer.data.recording_io import read_recording

ROOT = REPO_ROOT
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
STREAM_SAMPLES = 60_000  # 5 minutes at 200 Hz
FIT_SMALL = ["--population", "2", "--iterations", "5", "--cycles", "2"]
# method -> extra 'trainer fit' options; the recursive network is small and of odd width on purpose
MODELS: dict[str, list[str]] = {
    "pla": [],
    "poly3": [],
    "dlstm-issa": [*FIT_SMALL, "--hidden", "5", "--layers", "2"],
    "dlstm-temp": FIT_SMALL,  # the paper's 2 x 10
}


@pytest.fixture(scope="module", autouse=True)
def toolchain() -> None:
    reason = cm.ensure_toolchain()
    if reason is not None:
        pytest.skip(f"Cortex-M toolchain unavailable: {reason}")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Training run (10 min), stream (another seed, 5 min) and a wider run (extended protocol)."""
    folder = tmp_path_factory.mktemp("recordings")
    runs = {
        "train": ["--seed", "1", "--duration", "600"],
        "stream": ["--seed", "2", "--duration", "300"],
        "wide": ["--protocol", "extended", "--seed", "3", "--duration", "600"],
    }
    paths = {}
    for key, args in runs.items():
        paths[key] = folder / f"{key}.npz"
        assert trainer_main(["simulate", *args, "-o", str(paths[key])]) == 0
    return paths


@pytest.fixture(scope="module")
def exported(
    recordings: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
) -> Callable[..., tuple[LoadedModel, Path, str]]:
    """method -> (model, module directory, NAME), trained and exported once per test module."""
    cache: dict[tuple[str, str], tuple[LoadedModel, Path, str]] = {}

    def get(method: str, train: str = "train") -> tuple[LoadedModel, Path, str]:
        if (method, train) not in cache:
            folder = tmp_path_factory.mktemp(f"model-{method}-{train}")
            model_path = folder / "model.pt"
            args = ["fit", "--method", method, str(recordings[train]), "-o", str(model_path), *MODELS[method]]
            assert trainer_main([*args, "--quiet"]) == 0
            name = f"tdc_{method.replace('-', '_')}_{train}"
            model, _ = export(model_path, folder / "out", name=name)
            cache[(method, train)] = (model, folder / "out", name)
        return cache[(method, train)]

    return get


def extreme_burst(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Full scale and beyond on both signs, int32 limits, maximum temperature slew, big noise."""
    rng = np.random.default_rng(seed)
    accel = rng.integers(-(2**27), 2**27, n).astype(np.int64)
    temp = rng.integers(-60_000, 130_000, n).astype(np.int64)
    accel[: n // 4] = INT32_MAX
    accel[n // 4 : n // 2] = INT32_MIN
    temp[n // 2 : 3 * n // 4] = np.where(np.arange(3 * n // 4 - n // 2) % 2, INT32_MAX, INT32_MIN)
    return accel, temp


def golden_replay(
    model: QuantModel, accel: np.ndarray, temp: np.ndarray, commands: np.ndarray
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """What test_app must output: each instance's records through its own golden model."""
    out = np.empty(accel.size, dtype=np.int64)
    states = []
    for instance in (0, 1):
        golden = golden_for(model)
        index = np.flatnonzero(((commands & cm.CMD_INSTANCE_B) != 0) == bool(instance))
        out[index] = replay(golden, accel[index], temp[index], commands[index] & 3)
        states.append(golden.state())
    return out, states


def assert_bit_exact(target: np.ndarray, golden: np.ndarray, what: str) -> None:
    differ = np.flatnonzero(target.astype(np.int64) != golden)
    assert target.size == golden.size
    assert differ.size == 0, (
        f"{what}: {differ.size} of {golden.size} samples differ on Cortex-M4, first at {differ[0]} "
        f"(target {target[differ[0]]}, golden {golden[differ[0]]})"
    )


def assert_state_equal(module_dir: Path, name: str, raw: bytes, golden_state: dict[str, Any]) -> None:
    """The target's final state struct, decoded with the host's layout, equals the golden state."""
    host = load_module(module_dir, name, flags=("-O0",))
    assert host.sizeof_state() == len(raw), "the state struct has another size on the target than on the host"
    state = host.state_from_bytes(raw)
    assert state.keys() == golden_state.keys()
    for key in state:
        np.testing.assert_array_equal(np.asarray(state[key]), np.asarray(golden_state[key]), err_msg=key)


@pytest.mark.parametrize("method", list(MODELS))
def test_cortex_m4_equals_golden_on_a_recording(
    method: str, recordings: dict[str, Path], exported: Callable[..., Any], tmp_path: Path
) -> None:
    model, module_dir, name = exported(method)
    accel, temp = (v.astype(np.int64) for v in to_step_units(read_recording(recordings["stream"])))
    assert accel.size == STREAM_SAMPLES
    burst_accel, burst_temp = extreme_burst(4_000, seed=11)
    accel, temp = np.concatenate([accel, burst_accel]), np.concatenate([temp, burst_temp])
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[20_011] = CMD_RESET
    commands[41_234] = CMD_INIT
    commands[STREAM_SAMPLES + 1_500] = CMD_RESET

    build = cm.Build(module_dir, name, tmp_path / "build")
    log = build.make("module", "test-app")
    assert "warning" not in log.lower(), log
    result = cm.stream(build, accel, temp, commands, tmp_path / "run")

    assert result.model_id == f"sha256:{model.sha256}"
    expected, states = golden_replay(model.quantised, accel, temp, commands)
    assert_bit_exact(result.outputs, expected, f"{method}, {accel.size} samples")
    assert_state_equal(module_dir, name, result.states[0], states[0])


def test_cortex_m4_physics_equals_golden_on_a_recording(recordings: dict[str, Path], tmp_path: Path) -> None:
    """The grey-box physics module (every exported term; parameters of tests/testmodels.py, no fit)
    on the same stream, burst and commands: int64 filters and the play operator on the target."""
    from tests import testmodels as tm

    folder = tmp_path / "model"
    folder.mkdir()
    tm.save_checkpoint(tm.physics_checkpoint(read_recording(recordings["train"])), folder / "model.pt")
    model, _ = export(folder / "model.pt", folder / "out", name="tdc_physics_train")
    accel, temp = (v.astype(np.int64) for v in to_step_units(read_recording(recordings["stream"])))
    burst_accel, burst_temp = extreme_burst(4_000, seed=12)
    accel, temp = np.concatenate([accel, burst_accel]), np.concatenate([temp, burst_temp])
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[20_011] = CMD_RESET
    commands[41_234] = CMD_INIT
    commands[STREAM_SAMPLES + 1_500] = CMD_RESET
    build = cm.Build(folder / "out", "tdc_physics_train", tmp_path / "build")
    log = build.make("module", "test-app")
    assert "warning" not in log.lower(), log
    result = cm.stream(build, accel, temp, commands, tmp_path / "run")
    assert result.model_id == f"sha256:{model.sha256}"
    expected, states = golden_replay(model.quantised, accel, temp, commands)
    assert_bit_exact(result.outputs, expected, f"physics, {accel.size} samples")
    assert_state_equal(folder / "out", "tdc_physics_train", result.states[0], states[0])


def test_two_instances_side_by_side_equal_two_separate_runs(
    recordings: dict[str, Path], exported: Callable[..., Any], tmp_path: Path
) -> None:
    """Axis A and axis B interleaved sample by sample in one program, each with its own state."""
    model, module_dir, name = exported("dlstm-temp")
    accel, temp = (v.astype(np.int64) for v in to_step_units(read_recording(recordings["stream"])))
    n = 20_000
    a_accel, a_temp = accel[:n], temp[:n]
    b_accel, b_temp = -accel[30_000 : 30_000 + n], temp[30_000 : 30_000 + n]
    build = cm.Build(module_dir, name, tmp_path / "build")

    interleaved_accel = np.ravel(np.column_stack([a_accel, b_accel]))
    interleaved_temp = np.ravel(np.column_stack([a_temp, b_temp]))
    commands = np.tile([0, cm.CMD_INSTANCE_B], n)
    together = cm.stream(build, interleaved_accel, interleaved_temp, commands, tmp_path / "together")
    alone_a = cm.stream(build, a_accel, a_temp, np.zeros(n, dtype=np.int64), tmp_path / "a")
    alone_b = cm.stream(build, b_accel, b_temp, np.full(n, cm.CMD_INSTANCE_B), tmp_path / "b")

    np.testing.assert_array_equal(together.outputs[0::2], alone_a.outputs)
    np.testing.assert_array_equal(together.outputs[1::2], alone_b.outputs)
    assert together.states == (alone_a.states[0], alone_b.states[1])
    assert_bit_exact(alone_a.outputs, golden_for(model.quantised).run(a_accel, a_temp), "instance A")
    assert_bit_exact(alone_b.outputs, golden_for(model.quantised).run(b_accel, b_temp), "instance B")


def test_gnc_example_builds_warning_free_and_runs_the_same_on_host_and_target(
    exported: Callable[..., Any], tmp_path: Path
) -> None:
    """firmware_c/example: boot by model id, 200 Hz task (SysTick on the target), fallback outside
    the valid range, the cubic holding its edge beyond both ranges, switching by model id; host and
    Cortex-M4 print the same lines (tests/firmware/test_example_out_of_range.py checks the values)."""
    _, primary_dir, primary = exported("dlstm-issa")
    _, alt_dir, alt = exported("poly3", "wide")  # fitted over a wider temperature range
    build = cm.Build(primary_dir, primary, tmp_path / "build")
    variables = {"ALT_MODULE_DIR": str(alt_dir), "ALT_NAME": alt}
    log = build.make("example", "example-host", **variables)
    assert "warning" not in log.lower(), log
    host = subprocess.run(
        [str(tmp_path / "build" / "example_host")], capture_output=True, text=True, check=True
    )
    target = cm.run_qemu(build.elf("example"), [], cwd=tmp_path, icount=True, sleep_off=True)
    target_lines = [line for line in target.splitlines() if not line.startswith("cpu:")]
    assert target_lines == host.stdout.splitlines()
    text = host.stdout
    assert "active" in text.splitlines()[0]
    assert "refused" in text  # the unknown model id
    qualities = set("".join(re.findall(r"[xy]=\s*-?\d+ ([CFHR])", text)))
    # compensated, fallback model, and beyond both ranges the cubic holding its edge (never raw: it holds)
    assert qualities == {"C", "F", "H"}, text
    health = re.search(r"^health: .* held (\d+) raw (\d+) ", text, re.MULTILINE)
    assert health is not None and int(health.group(1)) > 0 and int(health.group(2)) == 0, text
    assert any(line.startswith("cpu:") for line in target.splitlines())


def test_benchmark_app_counts_instructions(exported: Callable[..., Any], tmp_path: Path) -> None:
    """bench_app under -icount: SysTick calibration, and a network step costs more than a plain sample."""
    for method in ("pla", "dlstm-temp"):
        model, module_dir, name = exported(method)
        counts = cm.bench(cm.Build(module_dir, name, tmp_path / method), tmp_path / f"run-{method}")
        assert counts.model_id == f"sha256:{model.sha256}"
        assert counts.instructions_per_tick == 40.0
        assert 0 < counts.plain <= counts.average <= counts.worst
        if method == "dlstm-temp":
            assert counts.decimation == 200
            assert counts.worst > 10 * counts.plain
            assert counts.worst > model.quantised.macs_per_step()  # the lower bound


@pytest.mark.slow
def test_cortex_m4_equals_golden_on_a_full_two_hour_recording(
    exported: Callable[..., Any], tmp_path: Path
) -> None:
    """The paper's whole validation run (1.44 million samples) through the temperature DLSTM."""
    model, module_dir, name = exported("dlstm-temp")
    path = tmp_path / "valid.npz"
    assert trainer_main(["simulate", "--protocol", "paper-oven", "--seed", "2", "-o", str(path)]) == 0
    accel, temp = (v.astype(np.int64) for v in to_step_units(read_recording(path)))
    build = cm.Build(module_dir, name, tmp_path / "build")
    result = cm.stream(build, accel, temp, np.zeros(accel.size, dtype=np.int64), tmp_path / "run")
    assert_bit_exact(result.outputs, golden_for(model.quantised).run(accel, temp), "2 h recording")
