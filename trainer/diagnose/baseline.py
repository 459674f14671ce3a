"""The user's simulation as the starting model: which terms, their starting values, the known input.

Every effect of the configuration becomes a model term whose free parameters are calibrated to
the recording; the configuration's values are only starting points. Without a configuration the
baseline is ``bias_poly`` plus the default noise terms (white noise, bias instability, rate random
walk), as in ``trainer/physics/default.toml``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from trainer.diagnose.model import Term
from trainer.physics.config import PhysicsConfig
from trainer.physics.profiles import input_signal

DEFAULT_NOISE = ("bias_instability", "rate_random_walk")
BLOCK_NOISE = ("bias_instability", "rate_random_walk")


@dataclass
class Baseline:
    terms: tuple[Term, ...]
    noise_terms: tuple[str, ...]
    identifiers: list[str]  # effects and noise terms of the starting model, for the report
    known_input: np.ndarray | None
    input_varies: bool
    notes: list[str] = field(default_factory=list)


def known_input(cfg: PhysicsConfig, t: np.ndarray) -> np.ndarray | None:
    """The deterministic true input the configuration declares (Singer manoeuvres are unknown)."""
    given = [e.params["g_in_mg"] for e in cfg.effect_instances("scale_factor_tc") if "g_in_mg" in e.params]
    if given:
        return np.full(t.size, float(given[0]))
    if cfg.input.kind == "zero":
        return None
    deterministic = replace(cfg.input, singer_sigma_mg=0.0)
    return input_signal(deterministic, t, np.random.default_rng(0))


def build_baseline(cfg: PhysicsConfig | None, t: np.ndarray, lattice_lsb_c: float | None) -> Baseline:
    """Terms and noise of the starting model (``t``: the recording's time axis from 0)."""
    if cfg is None:
        return Baseline(
            terms=(Term("bias_poly"),),
            noise_terms=DEFAULT_NOISE,
            identifiers=["bias_poly", "white_noise", *DEFAULT_NOISE],
            known_input=None,
            input_varies=False,
            notes=[
                "no --sim given: baseline is bias_poly plus white noise, bias instability, rate random walk"
            ],
        )
    notes: list[str] = []
    g_in = known_input(cfg, t)
    varies = bool(g_in is not None and np.ptp(g_in) > 1.0)
    terms: list[Term] = [Term("bias_poly")]
    identifiers = ["bias_poly"]
    if not cfg.effect_instances("bias_poly"):
        notes.append("the simulation has no bias_poly; the finder always fits one (the drift's backbone)")
    for effect in cfg.effects:
        ident, p = effect.identifier, effect.params
        if ident == "bias_poly":
            continue
        identifiers.append(ident)
        if ident in ("thermal_lag", "stress_relaxation", "warmup"):
            terms.append(Term(ident, (p["tau_s"],)))
        elif ident == "hysteresis":
            terms.append(Term(ident, (p["width_c"],)))
        elif ident == "periodic":
            terms.append(Term(ident, (p["period_s"],)))
        elif ident == "bias_step":
            terms.append(Term(ident, (p["t_s"],)))
        elif ident == "temp_rate":
            terms.append(Term(ident))
        elif ident == "temp_quantization":
            lsb = lattice_lsb_c if lattice_lsb_c is not None else p["lsb_c"]
            if lattice_lsb_c is None:
                notes.append("temp_quantization is listed but the thermometer column is not on a lattice")
            terms.append(Term(ident, (lsb,), fixed=True))
        elif ident == "scale_factor_tc":
            terms.append(Term(ident, (p["sf_ppm_per_c"],), fixed=True))
            if not varies:
                notes.append(
                    "scale_factor_tc is kept at the configured value: with a constant input it equals "
                    "bias_poly's linear term and cannot be calibrated"
                )
    noise = []
    for term in cfg.noise:
        identifiers.append(term.identifier)
        if term.identifier in BLOCK_NOISE:
            noise.append(term.identifier)
        elif term.identifier == "rate_ramp":
            terms.append(Term("rate_ramp"))
        elif term.identifier == "quantization_noise":
            notes.append(
                "quantization_noise only shows at the shortest taus; it is not part of the drift model"
            )
    if "white_noise" not in identifiers:
        notes.append("the simulation has no white_noise; every sensor has some, so it is always fitted")
    order = [t for t in BLOCK_NOISE if t in noise]
    return Baseline(tuple(terms), tuple(order), identifiers, g_in, varies, notes)
