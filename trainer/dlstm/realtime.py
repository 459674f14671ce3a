"""The streaming front end of the DLSTM compensators (docs/realtime.md is the contract).

Per 200 Hz sample: trailing moving averages of acceleration and temperature; a network step at
every ``n % D == 0`` on the smoothed values; the network's estimate ``h`` held until the next step;
output ``a(n) - h``. Because the network is causal and only sees the decimated sequence, running
it once over the whole decimated sequence and repeating each estimate ``D`` times is *exactly*
the streaming computation, and is what this module does (vectorised).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from fractions import Fraction
from typing import Any

import numpy as np

from trainer.data.recording import Recording
from trainer.data.smoothing import moving_average, window_samples
from trainer.errors import UserError

PAPER_TRAIN_SMOOTHING_S = 5.0
PAPER_RUN_SMOOTHING_S = 0.5
DEFAULT_TEMP_SMOOTHING_S = 5.0
DEFAULT_STEP_S = 1.0

# Front-end kinds, as written in a checkpoint's payload.frontend.kind (docs/realtime.md).
RECURSIVE_KIND = "recursive"  # the network sees the smoothed output
TEMPERATURE_KIND = "temperature"  # the network sees the smoothed temperature and its rate
PERSISTENCE_KIND = "persistence"  # no network: the estimate is the smoothed output itself


@dataclass(frozen=True)
class FrontEnd:
    """Windows and decimation in samples at ``rate_hz`` (see the table in docs/realtime.md)."""

    rate_hz: float
    accel_window: int
    temp_window: int
    decimation: int
    train_accel_window: int

    @classmethod
    def from_seconds(
        cls,
        rate_hz: float,
        *,
        run_smoothing_s: float = PAPER_RUN_SMOOTHING_S,
        temp_smoothing_s: float = DEFAULT_TEMP_SMOOTHING_S,
        step_s: float = DEFAULT_STEP_S,
        train_smoothing_s: float = PAPER_TRAIN_SMOOTHING_S,
    ) -> FrontEnd:
        return cls(
            rate_hz=float(rate_hz),
            accel_window=window_samples(run_smoothing_s, rate_hz),
            temp_window=window_samples(temp_smoothing_s, rate_hz),
            decimation=window_samples(step_s, rate_hz),
            train_accel_window=window_samples(train_smoothing_s, rate_hz),
        )

    @property
    def step_s(self) -> float:
        return self.decimation / self.rate_hz

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FrontEnd:
        return cls(
            rate_hz=float(data["rate_hz"]),
            accel_window=int(data["accel_window"]),
            temp_window=int(data["temp_window"]),
            decimation=int(data["decimation"]),
            train_accel_window=int(data["train_accel_window"]),
        )

    def at_rate(self, rate_millihz: int) -> FrontEnd:
        """The same windows and step in seconds at another rate, exactly, or a one-line refusal.

        Every window (and the decimation) must be a whole number of samples at the new rate, so the
        network sees the same smoothed inputs at the same step times; the refusal names the rates
        that would work (multiples of ``trained rate / gcd(windows)``).
        """
        trained = round(self.rate_hz * 1000)
        if trained <= 0:
            raise UserError(f"the front end's rate {self.rate_hz:g} Hz is below 1 mHz: cannot re-derive it")
        windows = {
            "accel_window": self.accel_window,
            "temp_window": self.temp_window,
            "decimation": self.decimation,
            "train_accel_window": self.train_accel_window,
        }
        ratio = Fraction(rate_millihz, trained)
        if all((w * ratio).denominator == 1 for w in windows.values()):
            return replace(
                self, rate_hz=rate_millihz / 1000, **{k: int(w * ratio) for k, w in windows.items()}
            )
        base = Fraction(trained, 1000 * math.gcd(*windows.values()))
        base *= (base * 1000).denominator  # the smallest such multiple in whole millihertz
        examples = ", ".join(f"{float(base * k):g}" for k in _nearby_multiples(base, rate_millihz))
        raise UserError(
            f"--rate {rate_millihz / 1000:g}: the front end (windows "
            f"{self.accel_window}/{self.temp_window} samples, a step every {self.decimation} at "
            f"{trained / 1000:g} Hz) is not a whole number of samples at that rate; rates that work are "
            f"multiples of {float(base):g} Hz, e.g. {examples}"
        )

    def check_rate(self, rec: Recording) -> None:
        """Refuse a recording whose rate differs from the model's by more than 1 %."""
        rate = rec.sample_rate_hz
        if abs(rate - self.rate_hz) > 0.01 * self.rate_hz:
            raise UserError(
                f"{rec.source}: sample rate {rate:g} Hz, but the model was trained at {self.rate_hz:g} Hz"
            )


def _nearby_multiples(base: Fraction, rate_millihz: int) -> list[int]:
    """The three multiples k of ``base`` (Hz) nearest the requested rate."""
    target = Fraction(rate_millihz, 1000) / base
    found = range(max(1, math.floor(target) - 3), math.floor(target) + 5)
    return sorted(sorted(found, key=lambda k: (abs(k - target), k))[:3])


def smoothed_steps(x: np.ndarray, window: int, decimation: int) -> np.ndarray:
    """Trailing mean over ``window`` samples, taken at the network steps ``0, D, 2D, ...``."""
    return moving_average(np.asarray(x, dtype=np.float64), window, mode="trailing")[::decimation]


def temperature_steps(temp_c: np.ndarray, frontend: FrontEnd) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed temperature ``T_k`` and its rate ``r_k`` in degC/min at the network steps (r_0 = 0)."""
    temp_k = smoothed_steps(temp_c, frontend.temp_window, frontend.decimation)
    rate_k = np.zeros_like(temp_k)
    rate_k[1:] = np.diff(temp_k) * (60.0 / frontend.step_s)
    return temp_k, rate_k


def hold(estimates: np.ndarray, n_samples: int, decimation: int) -> np.ndarray:
    """Zero-order hold: estimate ``k`` applies to samples ``kD .. kD + D - 1``."""
    return np.repeat(estimates, decimation)[:n_samples]


@dataclass(frozen=True)
class Standardiser:
    """``(x - mean) / std`` per feature; what the network sees is unit-scale."""

    mean: tuple[float, ...]
    std: tuple[float, ...]

    @classmethod
    def fit(cls, features: np.ndarray) -> Standardiser:
        """From a (T, F) array, NaN (no value: a held-out target) left out; a constant feature gets
        std 1 so that it does not blow up."""
        mean = np.nanmean(features, axis=0)
        std = np.nanstd(features, axis=0)
        std = np.where(std > 0, std, 1.0)
        return cls(tuple(float(v) for v in mean), tuple(float(v) for v in std))

    def apply(self, features: np.ndarray) -> np.ndarray:
        return (features - np.asarray(self.mean)) / np.asarray(self.std)

    def invert(self, values: np.ndarray) -> np.ndarray:
        return values * np.asarray(self.std) + np.asarray(self.mean)
