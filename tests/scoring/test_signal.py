"""trainer.data.smoothing against brute-force loops written from the definitions, on random data."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trainer.data.smoothing import decimate, decimation_indices, moving_average, window_samples

signals = st.integers(min_value=0, max_value=60).flatmap(
    lambda n: st.lists(st.floats(-1e4, 1e4, allow_nan=False), min_size=n, max_size=n)
)
windows = st.integers(min_value=1, max_value=25)


def trailing_loop(x: list[float], window: int) -> list[float]:
    out = []
    for i in range(len(x)):
        part = x[max(0, i - window + 1) : i + 1]
        out.append(sum(part) / len(part))
    return out


def centered_loop(x: list[float], window: int) -> list[float]:
    """MATLAB smooth: odd span (even spans lose one sample), shrinking symmetrically at the ends."""
    span = window if window % 2 else window - 1
    out = []
    for i in range(len(x)):
        half = min(span // 2, i, len(x) - 1 - i)
        part = x[i - half : i + half + 1]
        out.append(sum(part) / len(part))
    return out


@settings(max_examples=200, deadline=None)
@given(x=signals, window=windows)
def test_trailing_matches_loop(x: list[float], window: int) -> None:
    np.testing.assert_allclose(
        moving_average(x, window, "trailing"), trailing_loop(x, window), rtol=1e-9, atol=1e-8
    )


@settings(max_examples=200, deadline=None)
@given(x=signals, window=windows)
def test_centered_matches_loop(x: list[float], window: int) -> None:
    np.testing.assert_allclose(
        moving_average(x, window, "centered"), centered_loop(x, window), rtol=1e-9, atol=1e-8
    )


def test_trailing_is_the_default_and_causal() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=200)
    changed = x.copy()
    changed[150:] += 100.0  # the future must not leak into earlier outputs
    np.testing.assert_array_equal(moving_average(x, 9)[:150], moving_average(changed, 9, "trailing")[:150])


def test_expanding_start_has_no_transient_towards_zero() -> None:
    constant = np.full(50, -968.0)
    np.testing.assert_allclose(moving_average(constant, 20), constant)
    np.testing.assert_allclose(moving_average(constant, 20, "centered"), constant)


def test_long_offset_signal_keeps_precision() -> None:
    """A 2 h, 200 Hz recording near -1 g: the running sums must not lose the mg digits."""
    rng = np.random.default_rng(2)
    x = -980.0 + rng.normal(0, 1, 1_440_000)
    window = 200
    got = moving_average(x, window)
    for i in (0, 199, 700_000, 1_439_999):
        assert got[i] == pytest.approx(x[max(0, i - window + 1) : i + 1].mean(), abs=1e-9)


def test_window_of_one_is_identity() -> None:
    x = np.random.default_rng(3).normal(size=30)
    np.testing.assert_allclose(moving_average(x, 1), x)
    np.testing.assert_allclose(moving_average(x, 2, "centered"), x)  # even span 2 -> 1


def test_empty_signal() -> None:
    assert moving_average([], 5).shape == (0,)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (([1.0, 2.0], 0), "window"),
        (([1.0, 2.0], 2.5), "window"),
        (([[1.0, 2.0]], 2), "1-D"),
        (([1.0, 2.0], 2, "causal"), "mode"),
    ],
)
def test_moving_average_rejects_bad_arguments(args: tuple, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        moving_average(*args)


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 100), factor=st.integers(1, 12))
def test_decimation_emits_when_a_block_completes(n: int, factor: int) -> None:
    """Streaming reference: count samples, emit the sample that completes a block."""
    x = np.arange(n) * 1.5
    emitted, count = [], 0
    for index, value in enumerate(x):
        count += 1
        if count == factor:
            emitted.append((index, value))
            count = 0
    np.testing.assert_array_equal(decimation_indices(n, factor), [i for i, _ in emitted])
    np.testing.assert_array_equal(decimate(x, factor), [v for _, v in emitted])
    assert len(decimate(x, factor)) == n // factor


def test_decimate_works_along_the_first_axis() -> None:
    x = np.arange(20).reshape(10, 2)
    np.testing.assert_array_equal(decimate(x, 3), x[[2, 5, 8]])


@settings(max_examples=100, deadline=None)
@given(x=signals, factor=st.integers(1, 10))
def test_trailing_average_then_decimate_is_block_mean(x: list[float], factor: int) -> None:
    blocks = len(x) // factor
    expected = np.array(x[: blocks * factor]).reshape(blocks, factor).mean(axis=1)
    got = decimate(moving_average(x, factor), factor)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-8)


@pytest.mark.parametrize("factor", [0, -2, 1.5, True])
def test_decimate_rejects_bad_factor(factor: object) -> None:
    with pytest.raises(ValueError, match="factor"):
        decimate(np.arange(5), factor)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="factor"):
        decimation_indices(5, factor)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("window_s", "rate_hz", "expected"),
    [
        (1.0, 200.0, 200),
        (0.025, 200.0, 5),  # 5.000000000000001 in floating point
        (0.0125, 200.0, 3),  # exactly 2.5 samples: half rounds up, not to even
        (0.0175, 200.0, 4),  # 3.5 -> 4
        (0.001, 200.0, 1),  # 0.2 samples: at least one
        (0.0, 200.0, 1),
        (60.0, 1.97861919, 119),  # 118.717... -> 119
    ],
)
def test_window_samples(window_s: float, rate_hz: float, expected: int) -> None:
    assert window_samples(window_s, rate_hz) == expected


@settings(max_examples=200, deadline=None)
@given(window_s=st.floats(0, 1e3), rate_hz=st.floats(1e-2, 1e4))
def test_window_samples_is_nearest_integer(window_s: float, rate_hz: float) -> None:
    samples = window_samples(window_s, rate_hz)
    exact = window_s * rate_hz
    assert samples >= 1
    assert samples == 1 or abs(samples - exact) <= 0.5


@pytest.mark.parametrize(
    ("window_s", "rate_hz"), [(-1.0, 200.0), (1.0, 0.0), (float("nan"), 1.0), (1.0, float("inf"))]
)
def test_window_samples_rejects_bad_arguments(window_s: float, rate_hz: float) -> None:
    with pytest.raises(ValueError):
        window_samples(window_s, rate_hz)
