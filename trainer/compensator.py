"""The interface every compensation method implements.

A compensator estimates the temperature drift of ``accel_mg`` sample by sample; the compensated
output is ``accel_mg - drift``. The methods (name, class, family, options, renderer) are listed
in :mod:`trainer.methods`; a class does not name or register itself.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, Self

import numpy as np

from trainer.data.recording import Recording


class Compensator(ABC):
    """Fit on a training recording, then estimate the drift of any recording.

    Subclasses implement the four abstract methods. ``to_payload`` must return only tensors and plain Python values (str, int, float, bool, None, lists, dicts) so that the checkpoint loads with ``torch.load(weights_only=True)``.
    """

    @abstractmethod
    def fit(self, rec: Recording) -> Self:
        """Fit on ``rec`` (which never contains ``true_*`` columns when called by the tool)."""

    @abstractmethod
    def predict_drift(self, rec: Recording) -> np.ndarray:
        """The estimated drift in mg for every sample of ``rec``."""

    @abstractmethod
    def to_payload(self) -> dict[str, Any]:
        """The fitted state as tensors and plain values."""

    @classmethod
    @abstractmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        """Rebuild a fitted compensator from :meth:`to_payload`'s output."""

    def describe(self) -> list[str]:
        """Lines a user reads after fitting (structure, parameters, warnings); none by default."""
        return []

    def compensate(self, rec: Recording) -> np.ndarray:
        """The compensated output ``accel_mg - drift`` in mg."""
        return rec.accel_mg - self.predict_drift(rec)
