"""DLSTM compensators: the paper's recursive real-time model, its SSA/ISSA fusions, the
temperature-input variant, and the persistence predictor that the honest scoring needs.

All of them run the streaming front end of :mod:`trainer.dlstm.realtime` (docs/realtime.md):

- ``dlstm``, ``dlstm-ssa``, ``dlstm-issa`` (kind ``recursive``): the network maps the smoothed
  output at step k to the one at step k+1 (the paper's ``U(t-1) -> U(t)``) and the compensated
  output is ``a(n) - F[u_k]``. It removes whatever is predictable from the past output, a true
  input signal included.
- ``dlstm-temp`` (kind ``temperature``): the network maps the smoothed temperature and its rate
  to the drift; it never sees the acceleration at run time, so a true input survives.
- ``persistence``: ``F`` = identity, the trivial predictor every Allan-based score must beat.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Any, ClassVar, Self

import numpy as np
import torch

from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.dlstm.fusion import (
    FusionResult,
    FusionSettings,
    Optimiser,
    TrainedPopulation,
    fuse,
    refine_stage,
)
from trainer.dlstm.network import PopulationDLSTM
from trainer.dlstm.realtime import (
    PERSISTENCE_KIND,
    RECURSIVE_KIND,
    TEMPERATURE_KIND,
    FrontEnd,
    Standardiser,
    hold,
    smoothed_steps,
    temperature_steps,
)
from trainer.errors import UserError
from trainer.reference import value_at_temperature

WEIGHT_KEYS = ("w_x0", "w_h0", "b0", "w_x1", "w_h1", "b1", "w_out", "b_out")
MIN_TRAINING_STEPS = 16


# Network runs kept by run_network, by content (each a sequence's outputs, (T,) float64; tests clear it).
NETWORK_RUNS_KEPT = 32
network_runs: OrderedDict[bytes, np.ndarray] = OrderedDict()


def _run_key(weights: dict[str, torch.Tensor], inputs: np.ndarray) -> bytes:
    """A digest of everything a run's outputs depend on: the weights (names, shapes, bits) and inputs."""
    digest = hashlib.sha256()
    for name, tensor in weights.items():
        value = tensor.detach().contiguous()
        digest.update(f"{name}{tuple(value.shape)}{value.dtype};".encode())
        digest.update(value.numpy().tobytes())
    digest.update(f"{inputs.shape}{inputs.dtype};".encode())
    digest.update(np.ascontiguousarray(inputs).tobytes())
    return digest.digest()


def run_network(weights: dict[str, torch.Tensor], inputs: np.ndarray) -> np.ndarray:
    """The float reference: one network over a (T, in) sequence in float64, outputs (T,).

    The outputs are a function of the weights and inputs only, and a comparison asks for the same
    run several times (its scores, input tests, figures and the offset reading; DLSTM+SSA/ISSA often
    export DLSTM's own network), so the last :data:`NETWORK_RUNS_KEPT` runs are kept by content.
    """
    inputs = np.asarray(inputs, dtype=np.float64)
    key = _run_key(weights, inputs)
    if key in network_runs:
        network_runs.move_to_end(key)
        return network_runs[key].copy()
    individual = {name: tensor.double() for name, tensor in weights.items()}
    net = PopulationDLSTM.from_individuals([individual], dtype=torch.float64)
    x = torch.from_numpy(np.ascontiguousarray(inputs)).reshape(1, 1, len(inputs), -1)
    with torch.no_grad():
        y, _ = net(x)
    outputs = y.reshape(-1).numpy()
    network_runs[key] = outputs.copy()
    while len(network_runs) > NETWORK_RUNS_KEPT:
        network_runs.popitem(last=False)
    return outputs


class StreamingDLSTM(Compensator):
    """Shared state and checkpoint layout of the DLSTM compensators."""

    kind: ClassVar[str]
    optimiser: ClassVar[Optimiser] = "none"

    def __init__(
        self,
        *,
        settings: FusionSettings | None = None,
        frontend_seconds: dict[str, float] | None = None,
        progress: bool = True,
    ) -> None:
        self.settings = settings or FusionSettings()
        check_search_population(self.optimiser, self.settings.population)
        self.frontend_seconds = frontend_seconds or {}
        self.progress = progress
        self.frontend: FrontEnd | None = None
        self.inputs_norm: Standardiser | None = None
        self.output_norm: Standardiser | None = None
        self.weights: dict[str, torch.Tensor] = {}
        self.training: dict[str, Any] = {}

    # -- what each kind defines ------------------------------------------------------------
    def training_pairs(self, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
        """Raw (unstandardised) network inputs (T, in) and targets (T,) from a training recording."""
        raise NotImplementedError

    def run_inputs(self, rec: Recording) -> np.ndarray:
        """Raw network inputs (K, in) at the network steps of a recording, as the stream sees them."""
        raise NotImplementedError

    # -- fitting ---------------------------------------------------------------------------
    def prepare(self, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
        """Front end and standardisation from the training recording; standardised pairs."""
        self.frontend = FrontEnd.from_seconds(rec.sample_rate_hz, **self.frontend_seconds)
        inputs, targets = self.training_pairs(rec)
        scored = int(np.count_nonzero(~np.isnan(targets)))
        if scored < MIN_TRAINING_STEPS:
            raise UserError(
                f"{rec.source}: only {scored} network steps of {self.frontend.step_s:g} s; "
                f"at least {MIN_TRAINING_STEPS} are needed to train a DLSTM"
            )
        self.inputs_norm = Standardiser.fit(inputs)
        self.output_norm = Standardiser.fit(targets.reshape(-1, 1))
        return self.inputs_norm.apply(inputs), self.output_norm.apply(targets.reshape(-1, 1))[:, 0]

    def adopt(self, result: FusionResult) -> Self:
        self.weights = result.weights
        self.training = {"settings": self.settings.to_dict(), **result.summary()}
        return self

    def fit(self, rec: Recording) -> Self:
        x, y = self.prepare(rec)
        return self.adopt(fuse(x, y, self.settings, self.optimiser, progress=self.progress))

    def fit_from_population(self, rec: Recording, trained: TrainedPopulation) -> Self:
        """Refine an already gradient-trained population (``trainer compare`` shares stage one)."""
        x, y = self.prepare(rec)
        result = refine_stage(trained, x, y, self.settings, self.optimiser, progress=self.progress)
        return self.adopt(result)

    # -- running ---------------------------------------------------------------------------
    def step_estimates(self, rec: Recording) -> np.ndarray:
        """The held estimate ``h_k`` at every network step (mg)."""
        assert self.frontend and self.inputs_norm and self.output_norm, "fit the model first"
        self.frontend.check_rate(rec)
        y = run_network(self.weights, self.inputs_norm.apply(self.run_inputs(rec)))
        return self.output_norm.invert(y.reshape(-1, 1))[:, 0]

    def predict_drift(self, rec: Recording) -> np.ndarray:
        assert self.frontend is not None, "fit the model first"
        return hold(self.step_estimates(rec), len(rec), self.frontend.decimation)

    # -- checkpoint ------------------------------------------------------------------------
    def to_payload(self) -> dict[str, Any]:
        assert self.frontend and self.inputs_norm and self.output_norm, "fit the model first"
        w_x0 = self.weights["w_x0"]
        return {
            "architecture": {
                "input_size": int(w_x0.shape[1]),
                "hidden_size": int(w_x0.shape[0] // 4),
                "num_layers": sum(1 for k in self.weights if k.startswith("w_h")),
                "output_size": int(self.weights["w_out"].shape[0]),
                "gate_order": "ifgo",
            },
            "weights": {k: v.detach().float().clone() for k, v in self.weights.items()},
            "frontend": {"kind": self.kind, **self.frontend.to_dict()},
            "normalisation": {
                "inputs_mean": list(self.inputs_norm.mean),
                "inputs_std": list(self.inputs_norm.std),
                "output_mean": self.output_norm.mean[0],
                "output_std": self.output_norm.std[0],
            },
            "training": self.training,
        }

    @classmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        model = cls(progress=False)
        settings = payload["training"].get("settings", {})
        model.settings = FusionSettings(**settings) if settings else FusionSettings()
        model.training = payload["training"]
        frontend = payload["frontend"]
        if frontend["kind"] != cls.kind:
            raise ValueError(f"frontend kind {frontend['kind']!r} does not belong to {cls.__name__}")
        model.frontend = FrontEnd.from_dict(frontend)
        norm = payload["normalisation"]
        model.inputs_norm = Standardiser(tuple(norm["inputs_mean"]), tuple(norm["inputs_std"]))
        model.output_norm = Standardiser((float(norm["output_mean"]),), (float(norm["output_std"]),))
        weights = payload["weights"]
        missing = [k for k in WEIGHT_KEYS if k not in weights]
        if missing:
            raise KeyError(f"weights {missing}")
        model.weights = {k: weights[k].float() for k in weights}
        return model


def check_search_population(optimiser: str, population: int) -> None:
    """Refuse, before the gradient training, a population the sparrow search cannot run on (the
    sparrows are the networks: it failed with a traceback after the training)."""
    if optimiser != "none" and population < 2:
        raise UserError(
            f"--population {population}: {optimiser.upper()} searches over the population's networks and "
            "needs at least 2 (one network, no search: --method dlstm)"
        )


class RecursiveDLSTM(StreamingDLSTM):
    """The paper's real-time model: ``u_{k+1} = F[u_k]`` on the smoothed output (DLSTM alone)."""

    kind = RECURSIVE_KIND

    def training_pairs(self, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
        assert self.frontend is not None
        u = smoothed_steps(rec.accel_mg, self.frontend.train_accel_window, self.frontend.decimation)
        return u[:-1].reshape(-1, 1), u[1:]

    def run_inputs(self, rec: Recording) -> np.ndarray:
        assert self.frontend is not None
        return smoothed_steps(rec.accel_mg, self.frontend.accel_window, self.frontend.decimation).reshape(
            -1, 1
        )


class RecursiveDLSTMWithSSA(RecursiveDLSTM):
    """DLSTM + SSA (Xue and Shen 2020) over the trained population."""

    optimiser = "ssa"


class RecursiveDLSTMWithISSA(RecursiveDLSTM):
    """DLSTM + ISSA (adaptive weight, Lévy flight, elitism) over the trained population."""

    optimiser = "issa"


class TemperatureDLSTM(StreamingDLSTM):
    """Physically meaningful variant: smoothed temperature and its rate in, drift out."""

    kind = TEMPERATURE_KIND

    def _features(self, rec: Recording) -> np.ndarray:
        assert self.frontend is not None
        temp_k, rate_k = temperature_steps(rec.temp_c, self.frontend)
        return np.column_stack([temp_k, rate_k])

    def training_pairs(self, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
        """Targets at the steps whose smoothing window reaches a held-out row (a cross-validation
        fold's imputed output) are NaN: the network runs through the whole temperature history and
        learns the training rows alone, as the physics fit does."""
        assert self.frontend is not None
        window, decimation = self.frontend.train_accel_window, self.frontend.decimation
        u = smoothed_steps(rec.accel_mg, window, decimation)
        held = rec.held_out()
        if held is not None:
            reached = smoothed_steps(held.astype(np.float64), window, decimation) > 0.5 / window
            u = np.where(reached, np.nan, u)
        return self._features(rec), u

    def run_inputs(self, rec: Recording) -> np.ndarray:
        return self._features(rec)

    def drift_at_reference(self, t_ref_c: float, rate_hz: float, training: Recording | None = None) -> float:
        """The estimate at ``t_ref_c`` on the training run, as the run passed it (mg).

        The network reads the temperature rate too: held at ``t_ref_c`` (the default reading) it sees
        a rate of 0, which a single ramp never shows it, and its answer there is an offset, not its
        shape. So the reference is read where it was trained: a line through the training run's
        estimates nearest ``t_ref_c`` (:func:`~trainer.reference.value_at_temperature`, the same
        reading the scoring applies to the true drift). Without the training run, the default.
        """
        if training is None:
            return super().drift_at_reference(t_ref_c, rate_hz)
        return value_at_temperature(training.temp_c, self.predict_drift(training), t_ref_c)

    def shift_drift(self, delta_mg: float) -> None:
        """The network's output is de-standardised with ``output_mean``: the shift goes there."""
        assert self.output_norm is not None, "fit the model first"
        self.output_norm = Standardiser((self.output_norm.mean[0] + delta_mg,), self.output_norm.std)


class Persistence(Compensator):
    """``F`` = identity: the held estimate is the last smoothed output (no learning at all)."""

    def __init__(self, frontend_seconds: dict[str, float] | None = None) -> None:
        self.frontend_seconds = frontend_seconds or {}
        self.frontend: FrontEnd | None = None

    def fit(self, rec: Recording) -> Self:
        self.frontend = FrontEnd.from_seconds(rec.sample_rate_hz, **self.frontend_seconds)
        return self

    def predict_drift(self, rec: Recording) -> np.ndarray:
        assert self.frontend is not None, "fit the model first"
        self.frontend.check_rate(rec)
        u = smoothed_steps(rec.accel_mg, self.frontend.accel_window, self.frontend.decimation)
        return hold(u, len(rec), self.frontend.decimation)

    def to_payload(self) -> dict[str, Any]:
        assert self.frontend is not None, "fit the model first"
        return {"frontend": {"kind": PERSISTENCE_KIND, **self.frontend.to_dict()}}

    @classmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        model = cls()
        model.frontend = FrontEnd.from_dict(payload["frontend"])
        return model
