"""What PLA and the cubic share: temperature in, drift out, a valid temperature range."""

from __future__ import annotations

from abc import abstractmethod
from typing import Self

import numpy as np

from trainer.compensator import Compensator
from trainer.data.recording import Recording


class TemperatureCompensator(Compensator):
    """A memoryless map from the sensor's temperature reading to its drift (mg)."""

    temp_range_c: tuple[float, float]

    @abstractmethod
    def fit_arrays(self, temp_c: np.ndarray, drift_mg: np.ndarray) -> Self:
        """Fit from plain arrays (temperature, drift)."""

    @abstractmethod
    def drift_at(self, temp_c: np.ndarray) -> np.ndarray:
        """The drift estimate at each temperature."""

    def fit(self, rec: Recording) -> Self:
        return self.fit_arrays(rec.temp_c, rec.accel_mg)

    def predict_drift(self, rec: Recording) -> np.ndarray:
        return self.drift_at(rec.temp_c)

    def out_of_range(self, temp_c: np.ndarray) -> np.ndarray:
        """True where the temperature lies outside the training range."""
        return (temp_c < self.temp_range_c[0]) | (temp_c > self.temp_range_c[1])
