"""The interface every compensation method implements.

A compensator estimates the temperature drift of ``accel_mg`` sample by sample; the compensated
output is ``accel_mg - drift``. The methods (name, class, family, options, renderer) are listed
in :mod:`trainer.methods`; a class does not name or register itself.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from trainer.data.recording import Recording

if TYPE_CHECKING:
    from trainer.reference import OffsetRecord

# How long a constant-temperature stream runs before the drift at T_ref is read: long enough for
# any smoothing, network state or lag of a temperature-driven model to settle.
REFERENCE_SETTLE_S = 600.0


class Compensator(ABC):
    """Fit on a training recording, then estimate the drift of any recording.

    ``offset`` records what :func:`trainer.fitting.apply_offset_policy` did with the constant
    (None: recursive, or not applied). Temperature-driven methods implement :meth:`shift_drift`.

    Subclasses implement the four abstract methods. ``to_payload`` must return only tensors and plain Python values (str, int, float, bool, None, lists, dicts) so that the checkpoint loads with ``torch.load(weights_only=True)``.
    """

    offset: OffsetRecord | None = None

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

    @classmethod
    def undetermined_in(cls, payload: dict[str, Any]) -> list[str]:
        """Parameters a saved model (its :meth:`to_payload`) carries that its training run does not
        determine, one sentence each (a structure the user gave keeps them; the sign-off asks for a
        review); none by default. Read from the payload so that the code generator needs no model."""
        del payload
        return []

    def undetermined(self) -> list[str]:
        """:meth:`undetermined_in` of this model."""
        return self.undetermined_in(self.to_payload())

    def compensate(self, rec: Recording) -> np.ndarray:
        """The compensated output ``accel_mg - drift`` in mg."""
        return rec.accel_mg - self.predict_drift(rec)

    def drift_at_reference(self, t_ref_c: float, rate_hz: float, training: Recording | None = None) -> float:
        """The model's drift at ``t_ref_c`` (mg): what the offset policy moves out.

        By default the settled estimate at that constant temperature, from the model's own stream:
        :data:`REFERENCE_SETTLE_S` of constant temperature at ``rate_hz`` and zero acceleration,
        the last estimate read. ``training`` (the run the model was fitted on) is for a model whose
        inputs a constant temperature would take outside what it was trained on (``dlstm-temp``).
        """
        del training
        n = max(2, round(REFERENCE_SETTLE_S * rate_hz))
        columns = {
            "time_s": np.arange(n, dtype=np.float64) / rate_hz,
            "temp_c": np.full(n, float(t_ref_c)),
            "accel_mg": np.zeros(n),
        }
        rec = Recording(columns, {"sample_rate_hz": repr(float(rate_hz))}, f"<constant {t_ref_c:g} degC>")
        return float(self.predict_drift(rec)[-1])

    def expand_about(self, t_ref_c: float) -> None:
        """Write the model about the offset policy's ``t_ref_c`` (its estimates unchanged).

        A model that is a polynomial about a reference temperature of its own (the cubic, about the
        training range's mid-point) re-expands about the user's ``--tref``, so that the file holds one
        T_ref (the one PX4's ``TREF`` carries); the others have none to move.
        """
        del t_ref_c

    def shift_drift(self, delta_mg: float) -> None:
        """Add ``delta_mg`` to every drift estimate, in the fitted parameters (so the export carries it).

        Temperature-driven methods implement it; the offset policy calls it after fitting.
        """
        raise NotImplementedError(f"{type(self).__name__} cannot shift its drift estimate")
