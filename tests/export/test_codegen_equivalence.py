"""The generated C equals the golden model bit for bit: outputs and states, every method, random
models and inputs (hypothesis) including saturation extremes, resets, side-by-side instances, and
under AddressSanitizer + UndefinedBehaviorSanitizer (the kernel library alone:
tests/export/test_codegen_kernels.py)."""

from __future__ import annotations

import itertools
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from codegen.export import LoadedModel, export
from codegen.golden_select import golden_for
from codegen.hostbuild import (
    CMD_INIT,
    CMD_RESET,
    build_harness,
    load_module,
    load_modules,
    run_harness,
    write_vectors,
)
from codegen.render import render_template
from codegen.verify import to_step_units
from tests import testmodels as tm
from tests.golden_checks import assert_states_equal, replay
from trainer import methods as registry
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
ALL_METHODS = registry.with_renderer()


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    """The paper's oven run compressed to 10 minutes (120,000 samples at 200 Hz)."""
    path = tmp_path_factory.mktemp("rec") / "short.npz"
    assert trainer_main(["simulate", "--seed", "2", "--duration", "600", "-o", str(path)]) == 0
    return read_recording(path)


checkpoint_for = tm.checkpoint_for


def export_checkpoint(checkpoint: dict[str, Any], directory: Path, name: str) -> LoadedModel:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.pt"
    tm.save_checkpoint(checkpoint, path)
    model, _ = export(path, directory / "out", name=name)
    return model


def compare_stream(
    model: LoadedModel,
    out_dir: Path,
    name: str,
    accel: np.ndarray,
    temp: np.ndarray,
    reset_at: tuple[int, ...] = (),
) -> None:
    """C and golden over the same stream with resets; outputs and states after every segment."""
    host = load_module(out_dir, name, flags=("-O1",))
    state, golden = host.new_state(), golden_for(model.quantised)
    bounds = [0, *reset_at, accel.size]
    for k, (start, stop) in enumerate(itertools.pairwise(bounds)):
        if k:
            host.reset(state)
            golden.reset()
        c_out = host.run(state, accel[start:stop], temp[start:stop])
        g_out = golden.run(accel[start:stop], temp[start:stop])
        np.testing.assert_array_equal(c_out, g_out)
        assert_states_equal(host.read_state(state), golden.state())


@pytest.mark.parametrize("method", ALL_METHODS)
def test_c_equals_golden_on_a_recording(method: str, recording: Recording, tmp_path: Path) -> None:
    model = export_checkpoint(checkpoint_for(method, recording), tmp_path, "m")
    accel, temp = to_step_units(recording)
    compare_stream(model, tmp_path / "out", "m", accel, temp, reset_at=(50_017,))


@pytest.mark.parametrize("method", ["dlstm", "dlstm-temp"])
def test_golden_in_chunks_equals_golden_in_one_go(method: str, recording: Recording, tmp_path: Path) -> None:
    """Streaming state is complete: any chunking gives the same outputs and final state."""
    model = export_checkpoint(checkpoint_for(method, recording), tmp_path, "m")
    accel, temp = to_step_units(recording.slice(0, 20_000))
    whole = golden_for(model.quantised)
    expected = whole.run(accel, temp)
    chunked = golden_for(model.quantised)
    cuts = [0, 1, 2, 150, 151, 999, 1000, 1001, 7777, 20_000]
    got = np.concatenate([chunked.run(accel[a:b], temp[a:b]) for a, b in itertools.pairwise(cuts)])
    np.testing.assert_array_equal(got, expected)
    assert_states_equal(chunked.state(), whole.state())


def test_reset_restarts_the_stream_like_a_fresh_instance(recording: Recording, tmp_path: Path) -> None:
    export_checkpoint(checkpoint_for("dlstm-temp", recording), tmp_path, "m")
    host = load_module(tmp_path / "out", "m", flags=("-O1",))
    accel, temp = to_step_units(recording.slice(0, 6_000))
    used, fresh = host.new_state(), host.new_state()
    host.run(used, accel[:3_333], temp[:3_333])
    host.reset(used)
    np.testing.assert_array_equal(host.run(used, accel, temp), host.run(fresh, accel, temp))
    a, b = host.read_state(used), host.read_state(fresh)
    assert a.pop("samples") == 3_333 + b.pop("samples")  # the counter survives a reset, like the flags
    assert_states_equal(a, b)


def test_instances_run_side_by_side(recording: Recording, tmp_path: Path) -> None:
    """Two modules in one program, and two states of one module interleaved, do not interact."""
    m1 = export_checkpoint(checkpoint_for("dlstm", recording, seed=1), tmp_path / "a", "axis_x")
    m2 = export_checkpoint(checkpoint_for("pla", recording), tmp_path / "b", "axis_y")
    x, y = load_modules([(tmp_path / "a" / "out", "axis_x"), (tmp_path / "b" / "out", "axis_y")])
    accel, temp = to_step_units(recording.slice(0, 2_000))
    sx1, sx2, sy = x.new_state(), x.new_state(), y.new_state()
    out = np.empty((3, accel.size), dtype=np.int64)
    for n in range(accel.size):  # interleaved sample by sample
        out[0, n] = x.step(sx1, int(accel[n]), int(temp[n]))
        out[1, n] = x.step(sx2, int(-accel[n]), int(temp[n]))
        out[2, n] = y.step(sy, int(accel[n]), int(temp[n]))
    np.testing.assert_array_equal(out[0], golden_for(m1.quantised).run(accel, temp))
    np.testing.assert_array_equal(out[1], golden_for(m1.quantised).run(-accel, temp))
    np.testing.assert_array_equal(out[2], golden_for(m2.quantised).run(accel, temp))


# ------------------------------------------------------------------------------------ property-based


def extreme_stream(draw: st.DrawFn, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Mostly plausible samples, with bursts at the int32 limits, full scale and maximum slew."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    accel = rng.normal(0, draw(st.sampled_from([1e3, 1e5, 1e7])), n)
    temp = np.cumsum(rng.normal(0, draw(st.sampled_from([1.0, 100.0, 1e4])), n)) + rng.uniform(-5e4, 9e4)
    for _ in range(draw(st.integers(0, 4))):
        start = int(rng.integers(0, n))
        stop = min(n, start + int(rng.integers(1, 400)))
        accel[start:stop] = rng.choice([INT32_MIN, INT32_MAX, -2.56e8, 2.56e8, 0])
        temp[start:stop] = rng.choice([INT32_MIN, INT32_MAX, -1e5, 2e5, -3e5, 5e5])
    return (
        np.clip(accel, INT32_MIN, INT32_MAX).astype(np.int64),
        np.clip(temp, INT32_MIN, INT32_MAX).astype(np.int64),
    )


@st.composite
def random_dlstm(draw: st.DrawFn) -> dict[str, Any]:
    method = draw(st.sampled_from(["dlstm", "dlstm-temp"]))
    n_in = 2 if method == "dlstm-temp" else 1
    hidden, layers = draw(st.integers(1, 6)), draw(st.integers(1, 3))
    scale = draw(st.sampled_from([0.05, 1.0, 4.0, 30.0]))
    weights = tm.random_weights(n_in, hidden, layers, seed=draw(st.integers(0, 10_000)), scale=scale)
    if draw(st.booleans()):  # a forget gate stuck near 1: long memory, cell state close to its limits
        weights["b0"][hidden : 2 * hidden] += 12.0
    rate = draw(st.sampled_from([50.0, 200.0]))
    frontend = {
        "rate_hz": rate,
        "accel_window": draw(st.integers(1, 40)),
        "temp_window": draw(st.integers(1, 40)),
        "decimation": draw(st.integers(1, 25)),
        "train_accel_window": 10,
    }
    spread = draw(st.sampled_from([1e-3, 1.0, 300.0]))
    normalisation = {
        "inputs_mean": [draw(st.floats(-50, 50)) for _ in range(n_in)],
        "inputs_std": [spread * draw(st.floats(0.1, 10)) for _ in range(n_in)],
        "output_mean": draw(st.floats(-1000, 1000)),
        "output_std": draw(st.sampled_from([1e-3, 1.0, 50.0])),
    }
    payload = tm.dlstm_payload(method, weights, frontend, normalisation)
    return tm.checkpoint_dict(method, payload, (draw(st.floats(-60, 20)), draw(st.floats(21, 130))))


@st.composite
def random_baseline(draw: st.DrawFn) -> dict[str, Any]:
    finite = st.floats(-1e3, 1e3, allow_nan=False)
    lo = draw(st.floats(-60, 40))
    hi = lo + draw(st.floats(0.5, 150))
    if draw(st.booleans()):
        n = draw(st.integers(1, 12))
        payload = {
            "n_intervals": n,
            "split_points_c": torch.tensor(np.linspace(lo, hi, n + 1)[1:-1], dtype=torch.float64),
            "slopes_mg_per_c": torch.tensor(
                [draw(st.floats(-20, 20)) for _ in range(n)], dtype=torch.float64
            ),
            "intercepts_mg": torch.tensor([draw(finite) for _ in range(n)], dtype=torch.float64),
            "temp_range_c": [lo, hi],
        }
        return tm.checkpoint_dict("pla", payload, (lo, hi))
    coefficients = [
        draw(finite),
        draw(st.floats(-50, 50)),
        draw(st.floats(-1, 1)),
        draw(st.floats(-0.05, 0.05)),
    ]
    payload = {
        "coefficients_mg": torch.tensor(coefficients, dtype=torch.float64),
        "t_ref_c": (lo + hi) / 2,
        "temp_range_c": [lo, hi],
        "remove_median": False,
        "median_kernel": 31,
        "n_bins": 2000,
    }
    return tm.checkpoint_dict("poly3", payload, (lo, hi))


_HYPOTHESIS = settings(
    max_examples=14,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@_HYPOTHESIS
@given(checkpoint=random_dlstm(), data=st.data())
def test_random_networks_c_equals_golden(
    checkpoint: dict[str, Any], data: st.DataObject, tmp_path: Path
) -> None:
    work = tmp_path / f"ex{np.random.default_rng().integers(1 << 30)}"
    model = export_checkpoint(checkpoint, work, "rnd")
    n = data.draw(st.integers(1, 3_000))
    accel, temp = extreme_stream(data.draw, n)
    compare_stream(model, work / "out", "rnd", accel, temp, reset_at=(data.draw(st.integers(0, n)),))
    shutil.rmtree(work)


@_HYPOTHESIS
@given(checkpoint=random_baseline(), data=st.data())
def test_random_baselines_c_equals_golden(
    checkpoint: dict[str, Any], data: st.DataObject, tmp_path: Path
) -> None:
    work = tmp_path / f"ex{np.random.default_rng().integers(1 << 30)}"
    model = export_checkpoint(checkpoint, work, "rnd")
    accel, temp = extreme_stream(data.draw, 2_000)
    temp[:200] = np.linspace(-150_000, 250_000, 200)  # every interval, both clips, both extrapolations
    compare_stream(model, work / "out", "rnd", accel, temp)
    shutil.rmtree(work)


@pytest.fixture(scope="module")
def strong_memory_module(
    tmp_path_factory: pytest.TempPathFactory, recording: Recording
) -> tuple[LoadedModel, Path]:
    """A 2x10 temperature network with D = 5, W = 7 and large weights: every path is reachable."""
    fe = tm.frontend_fields(200.0, run_s=0.035, temp_s=0.035, step_s=0.025)
    checkpoint = tm.dlstm_checkpoint("dlstm-temp", recording, scale=3.0, frontend=fe)
    work = tmp_path_factory.mktemp("strong")
    return export_checkpoint(checkpoint, work, "strong"), work / "out"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_streams_through_one_module(
    strong_memory_module: tuple[LoadedModel, Path], data: st.DataObject
) -> None:
    model, out_dir = strong_memory_module
    host = _cached_host(out_dir)
    n = data.draw(st.integers(1, 5_000))
    accel, temp = extreme_stream(data.draw, n)
    state, golden = host.new_state(), golden_for(model.quantised)
    np.testing.assert_array_equal(host.run(state, accel, temp), golden.run(accel, temp))
    assert_states_equal(host.read_state(state), golden.state())


_HOSTS: dict[Path, Any] = {}


def _cached_host(out_dir: Path) -> Any:
    if out_dir not in _HOSTS:
        _HOSTS[out_dir] = load_module(out_dir, "strong")
    return _HOSTS[out_dir]


# ------------------------------------------------------------------------------------ sanitizers


@pytest.mark.parametrize("method", ["dlstm-issa", "dlstm-temp", "persistence", "pla", "poly3"])
def test_under_address_and_undefined_behaviour_sanitizers(
    method: str, recording: Recording, tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (scripts/install_c_tools.sh)")
    fe = tm.frontend_fields(200.0, step_s=0.05)
    model = export_checkpoint(checkpoint_for(method, recording, scale=3.0, frontend=fe), tmp_path, "san")
    accel, temp = to_step_units(recording.slice(0, 30_000))
    rng = np.random.default_rng(7)
    accel[5_000:5_300] = INT32_MAX  # full scale and beyond, both signs
    accel[9_000:9_100] = INT32_MIN
    temp[12_000:12_500] = np.where(np.arange(500) % 2, INT32_MAX, INT32_MIN)  # maximum slew
    accel[20_000:] += rng.integers(-(2**27), 2**27, accel.size - 20_000, dtype=np.int32)
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[[7_001, 15_555]] = CMD_RESET
    commands[25_000] = CMD_INIT
    vectors = tmp_path / "vectors.bin"
    write_vectors(vectors, accel, temp, commands)
    source = render_template("harness_vectors.c.j2", model.quantised, "san", model.sha256)
    binary = build_harness(tmp_path / "out", "san", source, tmp_path / "harness", cc="gcc")
    state_bytes = run_harness(binary, vectors, tmp_path / "outputs.bin")
    c_out = np.frombuffer((tmp_path / "outputs.bin").read_bytes(), dtype="<i4")

    golden = golden_for(model.quantised)
    np.testing.assert_array_equal(c_out, replay(golden, accel, temp, commands))
    host = load_module(tmp_path / "out", "san", flags=("-O0",))
    assert_states_equal(host.state_from_bytes(state_bytes), golden.state())


# ------------------------------------------------------------------------------------ output rounding


def test_output_rounding_errors_cancel_over_any_run_of_samples(recording: Recording, tmp_path: Path) -> None:
    """The held estimate is Q16; the output rounds it to whole LSB with error feedback, so the
    rounding errors of any run of consecutive samples sum to less than one LSB (plain rounding
    would hold up to half an LSB for a whole network step)."""
    export_checkpoint(
        checkpoint_for("dlstm", recording, frontend=tm.frontend_fields(200.0, step_s=0.1)), tmp_path, "m"
    )
    host = load_module(tmp_path / "out", "m", flags=("-O1",))
    state = host.new_state()
    accel, temp = to_step_units(recording.slice(0, 3_000))
    errors = np.empty(accel.size, dtype=np.int64)
    fractions = set()
    for n in range(accel.size):
        out = host.step(state, int(accel[n]), int(temp[n]))
        held = host.read_state(state)  # the estimate held for this sample, Q16
        q16 = int(held["estimate"]) * 2**16 + int(held["estimate_frac"])
        errors[n] = (int(accel[n]) - out) * 2**16 - q16
        fractions.add(int(held["estimate_frac"]))
    assert len(fractions) > 10  # the estimate really has fractions to carry
    assert np.max(np.abs(errors)) < 2**16  # under one LSB per sample
    prefix = np.concatenate(([0], np.cumsum(errors)))
    assert np.ptp(prefix) < 2**16  # |sum over samples a..b| = |prefix[b + 1] - prefix[a]| < one LSB


@pytest.mark.parametrize("output_std_mg", [50.0, 5e4])
def test_head_clamp_only_where_the_bound_reaches_the_limit(output_std_mg: float, tmp_path: Path) -> None:
    """The head's estimate clamp is emitted only when the accumulator's bound can reach it; a head
    that can saturate keeps it and the C still equals the golden model, which always clamps."""
    weights = tm.random_weights(1, 4, 1, seed=3, scale=30.0)
    weights["b0"][:] = 8.0  # every gate open: h near its limits, the estimate near its bound
    weights["w_out"][:] = 1.0  # with 5e4 mg per unit, four units reach 2e5 mg: beyond the clamp (1.3e5 mg)
    frontend = {
        "rate_hz": 200.0,
        "accel_window": 4,
        "temp_window": 4,
        "decimation": 4,
        "train_accel_window": 10,
    }
    normalisation = {
        "inputs_mean": [0.0],
        "inputs_std": [1.0],
        "output_mean": 0.0,
        "output_std": output_std_mg,
    }
    checkpoint = tm.checkpoint_dict(
        "dlstm", tm.dlstm_payload("dlstm", weights, frontend, normalisation), (-40, 85)
    )
    model = export_checkpoint(checkpoint, tmp_path, "hd")
    head = model.quantised.head
    assert head is not None
    limit_lsb = 2**31 - 1  # the estimate's clamp, whole accel LSB (independent of the quantiser's constant)
    can_reach = head.acc_bound / 2.0**head.shift >= limit_lsb
    assert head.may_saturate == can_reach
    source = (tmp_path / "out" / "hd.c").read_text(encoding="utf-8")
    assert ("HD_FLAG_SATURATED;\n        acc = (acc > 0)" in source) == can_reach
    accel = np.resize(np.array([2.5e8, -2.5e8, 0, 1e6], dtype=np.int64), 2_000)
    accel[1_000:] = np.sort(accel[1_000:])
    temp = np.full(accel.size, 20_000, dtype=np.int64)
    compare_stream(model, tmp_path / "out", "hd", accel, temp, reset_at=(777,))
    golden = golden_for(model.quantised)
    golden.fine_estimates = []
    golden.run(accel, temp)
    reached = max(abs(e) for e in golden.fine_estimates) > limit_lsb
    assert reached == can_reach  # the saturating head is driven into its clamp on this stream
