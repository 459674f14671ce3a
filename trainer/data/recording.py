"""The in-memory recording: named 1-D float64 columns plus ``key=value`` metadata.

This mirrors ``shared/specs/recording-format.md``. Reading and writing files lives in
:mod:`trainer.data.recording_io`; this module only holds the data and the rules every consumer
shares (required columns, ground-truth columns that fitting must never see).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from trainer.data.flightlog import data_column
from trainer.errors import UserError

ONE_AXIS_COLUMNS: tuple[str, ...] = ("temp_c", "accel_mg")  # optional beside named channels
REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", *ONE_AXIS_COLUMNS)  # of a one-axis recording
MIN_ROWS = 2  # one time step: the least that defines a sample rate (and a drift)
TRUTH_PREFIX = "true_"
# A column a cross-validation adds (trainer.scoring.crossval): 1 on the held-out rows, whose output
# was imputed so that a method with state sees the run's whole temperature history. Every fit that
# reads it scores the training rows alone (the finder's blocks, the temperature-input DLSTM's loss).
HELD_OUT_COLUMN = "held_out"
# Metadata of a part cut by --holdout: the first time of the run it was cut from (Recording.time_origin_s)
TIME_ORIGIN_META = "time_origin_s"


@dataclass
class Recording:
    """A sensor recording.

    ``columns`` keeps the file's column order (dicts preserve insertion order). ``source`` is a
    human-readable origin (usually the path) used in error messages.
    """

    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    source: str = "<memory>"
    # Where a row and accel_mg come from in the file, for messages: "line 209" of a CSV row (None: "data
    # row N"), and the file's column a view's accel_mg holds (None: accel_mg itself, or the channel's column)
    row_label: Callable[[int], str] | None = field(default=None, compare=False, repr=False)
    accel_column: str | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        lengths = {name: len(values) for name, values in self.columns.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"{self.source}: columns have unequal lengths {lengths}")

    def __getstate__(self) -> dict[str, object]:
        """Pickled (to a worker process) without ``row_label``: a closure over the reader's table, and
        the rows a message names are named by the process that read the file."""
        state = dict(self.__dict__)
        state["row_label"] = None
        return state

    def __len__(self) -> int:
        return len(self.time_s)

    @property
    def time_s(self) -> np.ndarray:
        return self.columns["time_s"]

    @property
    def temp_c(self) -> np.ndarray:
        return self._one_axis("temp_c")

    @property
    def accel_mg(self) -> np.ndarray:
        return self._one_axis("accel_mg")

    def channel_column(self) -> str | None:
        """The named column (``gyro0_x_dps``) of the channel the ``channel`` and ``unit`` metadata
        name, when the recording holds it: what ``accel_mg`` stands for in a file of a gyroscope or
        barometer channel, which the contract keeps out of ``accel_mg`` (milli-g only)."""
        channel, unit = self.meta.get("channel"), self.meta.get("unit")
        if not channel or not unit or unit == "mg":  # an accelerometer's file keeps its accel_mg
            return None
        column = data_column(channel, unit)
        return column if column in self.columns else None

    def one_axis_or_none(self, name: str) -> np.ndarray | None:
        """``temp_c`` or ``accel_mg`` as a one-channel command reads it, or None: the file's column,
        else (``accel_mg``) the column of the channel its metadata names."""
        values = self.columns.get(name)
        if values is None and name == "accel_mg" and (column := self.channel_column()) is not None:
            values = self.columns[column]
        return values

    def _one_axis(self, name: str) -> np.ndarray:
        """A one-axis column; a multi-channel recording may leave it out (the contract's "Several
        channels"), and a one-channel command then asks for a channel in one line."""
        values = self.one_axis_or_none(name)
        if values is None:
            raise UserError(
                f"{self.source}: no column {name!r}: a multi-channel recording without a one-axis column "
                f"is read a channel at a time: name them with --channels (all, or a list such as "
                f"accel0_z,gyro0_x; columns: {', '.join(self.columns)})"
            )
        return values

    @property
    def sample_rate_hz(self) -> float:
        """The ``sample_rate_hz`` metadata when present, else derived from the median step."""
        if "sample_rate_hz" in self.meta:
            return float(self.meta["sample_rate_hz"])
        require_rows(len(self.time_s), self.source)  # user data: one line, not a traceback
        return float(1.0 / np.median(np.diff(self.time_s)))

    @property
    def time_origin_s(self) -> float:
        """Where the recording's clock counts from (s): its first sample, or, for a part cut by
        ``--holdout`` (:func:`trainer.data.holdout.split`), the first sample of the run it was cut from,
        so that a part's segments are named on the times the user gave ``--holdout`` in."""
        if TIME_ORIGIN_META in self.meta:
            return float(self.meta[TIME_ORIGIN_META])
        return float(self.time_s[0])

    def has(self, name: str) -> bool:
        return name in self.columns

    def truth(self, name: str) -> np.ndarray | None:
        """Ground-truth column ``true_<name>`` for evaluation only, or None when absent."""
        return self.columns.get(TRUTH_PREFIX + name)

    def held_out(self) -> np.ndarray | None:
        """Boolean mask of the rows a cross-validation fold holds out (:data:`HELD_OUT_COLUMN`), or None."""
        values = self.columns.get(HELD_OUT_COLUMN)
        return None if values is None else np.asarray(values, dtype=np.float64) > 0.5

    def without_truth(self) -> Recording:
        """A view for fitting and diagnosis: every ``true_*`` column removed."""
        kept = {k: v for k, v in self.columns.items() if not k.startswith(TRUTH_PREFIX)}
        return Recording(kept, dict(self.meta), self.source, self.row_label, self.accel_column)

    def slice(self, start: int, stop: int) -> Recording:
        """Rows ``start:stop`` (views, not copies)."""
        label = self.row_label
        shifted = None if label is None else (lambda row: label(row + start))
        columns = {k: v[start:stop] for k, v in self.columns.items()}
        return Recording(columns, dict(self.meta), self.source, shifted, self.accel_column)

    def file_column(self) -> str:
        """The file's column this recording's ``accel_mg`` holds (``gyro0_x_dps`` of a channel view)."""
        return self.accel_column or self.channel_column() or "accel_mg"


def require_rows(n: int, source: str) -> None:
    """Refuse fewer than :data:`MIN_ROWS` rows (``n`` >= 1; zero rows has its own message)."""
    if n < MIN_ROWS:
        raise UserError(
            f"{source}: {n} data row; a recording needs at least {MIN_ROWS} (its time step is its sample "
            "rate): the file is truncated or the logger stopped at once"
        )


def data_fingerprint(rec: Recording) -> str:
    """sha256 of the time, temperature and acceleration columns: the same data, whatever the file.

    ``train_stats.data_sha256`` of a model; :func:`trainer.data.holdout.overlap_warning` compares it
    with the scored data's."""
    digest = hashlib.sha256()
    for name in REQUIRED_COLUMNS:
        values = rec.columns["time_s"] if name == "time_s" else rec.one_axis_or_none(name)
        if values is not None:  # a multi-channel recording may carry no one-axis column
            digest.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return digest.hexdigest()
