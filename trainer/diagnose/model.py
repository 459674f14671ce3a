"""A physics model on block means: catalogue terms -> design matrix -> GLS fit -> catalogue params.

Each effect is split into nonlinear parameters (time constants, hysteresis width, period, step
time), searched numerically, and linear ones (amplitudes and the ``bias_poly`` coefficients),
solved by generalised least squares inside every evaluation (variable projection). The
``bias_poly`` is therefore always re-fitted jointly with the other terms: the point of the finder
is that a polynomial absorbs part of a missing effect, and only what it cannot absorb is evidence.

The columns use the physics package's own building blocks (``thermal.lowpass``,
``thermal.play_operator``) with the catalogue's formulas, and :func:`catalogue_effects` turns a
fit back into ``EffectConfig`` instances that ``physics.effects.drift`` evaluates identically.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.gls import Gls, NoiseState, fit_noise, initial_state
from trainer.physics.effects import T_REF_C, EffectConfig
from trainer.physics.thermal import lowpass, play_operator

POLY_SCALE_C = 50.0  # columns ((T - 25) / 50)^k keep the GLS well conditioned

NONLINEAR: dict[str, tuple[str, ...]] = {
    "bias_poly": (),
    "thermal_lag": ("tau_s",),
    "temp_rate": (),
    "hysteresis": ("width_c",),
    "stress_relaxation": ("tau_s",),
    "warmup": ("tau_s",),
    "periodic": ("period_s",),
    "bias_step": ("t_s",),
    "temp_quantization": (),
    "scale_factor_tc": (),
    "rate_ramp": (),
}
LOG_SCALED = frozenset({"tau_s", "width_c", "period_s"})

# Catalogue plausible ranges (physics-catalogue.md); the search goes somewhat beyond them so a
# value at the edge is seen as such, and the report flags values outside.
PLAUSIBLE: dict[tuple[str, str], tuple[float, float]] = {
    ("thermal_lag", "tau_s"): (10.0, 900.0),
    ("hysteresis", "width_c"): (2.0, 30.0),
    ("hysteresis", "amp_mg"): (0.02, 2.0),
    ("stress_relaxation", "tau_s"): (1200.0, 20000.0),
    ("stress_relaxation", "gain_mg_per_c"): (0.001, 0.05),
    ("warmup", "tau_s"): (60.0, 1800.0),
    ("warmup", "amp_mg"): (0.05, 5.0),
    ("periodic", "period_s"): (5.0, 2000.0),
    ("periodic", "amp_mg"): (0.005, 1.0),
    ("temp_rate", "k_mg_per_c_per_min"): (0.01, 2.0),
    ("bias_step", "step_mg"): (0.02, 5.0),
    ("temp_quantization", "lsb_c"): (0.0625, 1.0),
}


def search_bounds(identifier: str, data: BlockData) -> tuple[tuple[float, float], ...]:
    """Bounds of each nonlinear parameter of ``identifier`` for this recording."""
    span = data.duration_s
    if identifier == "thermal_lag":
        return ((3.0, 1500.0),)
    if identifier == "hysteresis":
        return ((0.5, 40.0),)
    if identifier == "stress_relaxation":
        return ((600.0, max(1200.0, min(40000.0, 4.0 * span))),)
    if identifier == "warmup":
        return ((max(5.0, 2.0 * data.block_s), max(60.0, min(6000.0, 0.5 * span))),)
    if identifier == "periodic":
        return ((max(2.0 * data.fine_step_s * 1.25, 4.0), 0.5 * span),)
    if identifier == "bias_step":
        return ((data.starts[2], data.starts[-2]),)
    return ()


@dataclass(frozen=True)
class Term:
    """One effect instance in a model.

    ``nl``: its nonlinear parameter values (``NONLINEAR`` order). ``fixed``: they are held, not
    searched. ``offset``: linear parameters that are also held (a fast periodic component fitted
    on the fine grid enters the block model as a known contribution, with no free columns).
    """

    identifier: str
    nl: tuple[float, ...] = ()
    fixed: bool = False
    offset: tuple[float, ...] | None = None

    @property
    def n_free_nl(self) -> int:
        """Parameters this term adds to the BIC count besides its linear columns.

        A step time or a period found by scanning hundreds of positions counts twice (the
        modified BIC for change points, Zhang & Siegmund 2007): the look-elsewhere effect of an
        exhaustive scan is far larger than that of a smooth time constant.
        """
        if self.identifier == "temp_quantization":
            return 1  # the LSB is estimated (from the lattice of the thermometer column)
        if self.identifier in ("bias_step", "periodic"):
            return 2
        return 0 if self.fixed else len(self.nl)


@dataclass
class Design:
    X: np.ndarray
    roles: list[tuple[int, str]]
    offset: np.ndarray
    T_pm: np.ndarray


def _sinc(x: np.ndarray | float) -> np.ndarray | float:
    return np.sinc(np.asarray(x) / np.pi)


def periodic_columns(t: np.ndarray, period_s: float, block_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact block means of ``sin`` and ``cos`` of ``2 pi t / P`` (centres ``t``, width ``block_s``)."""
    w = 2.0 * math.pi / period_s
    gain = float(_sinc(w * block_s / 2.0))
    return gain * np.sin(w * t), gain * np.cos(w * t)


def build_design(terms: Sequence[Term], data: BlockData) -> Design:
    """Design matrix of ``terms`` on the block means (poly columns first)."""
    ids = [term.identifier for term in terms]
    dequant = "temp_quantization" in ids
    T = data.temperature(dequant)
    rate = data.rate(dequant)
    B = data.block_s
    t = data.t
    T_pm = T
    for term in terms:
        if term.identifier == "thermal_lag":
            T_pm = lowpass(T, term.nl[0], B)
    T_b = T_pm
    columns: list[np.ndarray] = []
    roles: list[tuple[int, str]] = []
    offset = np.zeros(data.n)
    extra: list[tuple[int, str, np.ndarray]] = []
    for index, term in enumerate(terms):
        ident = term.identifier
        if ident == "hysteresis":
            width = term.nl[0]
            play = play_operator(T_pm, width)
            T_b = play
            extra.append((index, "amp_mg", (T_pm - play) / (width / 2.0)))
        elif ident == "temp_rate":
            extra.append((index, "k_mg_per_c_per_min", rate))
        elif ident == "stress_relaxation":
            extra.append((index, "gain_mg_per_c", T - lowpass(T, term.nl[0], B)))
        elif ident == "warmup":
            tau = term.nl[0]
            x = B / (2.0 * tau)
            extra.append((index, "amp_mg", np.exp(-t / tau) * (math.sinh(x) / x if x > 1e-8 else 1.0)))
        elif ident == "periodic":
            s, c = periodic_columns(t, term.nl[0], B)
            if term.offset is not None:
                amp, phase = term.offset
                offset += amp * (math.cos(phase) * s + math.sin(phase) * c)
            else:
                extra.append((index, "sin", s))
                extra.append((index, "cos", c))
        elif ident == "bias_step":
            extra.append((index, "step_mg", np.clip((t + 0.5 * B - term.nl[0]) / B, 0.0, 1.0)))
        elif ident == "rate_ramp":
            extra.append((index, "r_mg_per_s", t))
        elif ident == "temp_quantization":
            # In a quantised hold the true temperature is only known within +-LSB/2: an unknown
            # offset per plateau (the polynomial's slope times that temperature error).
            for k, (p0, p1) in enumerate(data.plateaus):
                inside = ((t >= p0) & (t < p1)).astype(np.float64)
                if inside.sum() >= 2:
                    extra.append((index, f"plateau{k}", inside))
        elif ident == "scale_factor_tc" and data.known_input_block is not None:
            extra.append((index, "sf_ppm_per_c", data.known_input_block * 1e-6 * (T_pm - T_REF_C)))
    poly_index = ids.index("bias_poly")  # always present: the finder's models all start from it
    u = (T_b - T_REF_C) / POLY_SCALE_C
    for k in range(4):
        columns.append(u**k)
        roles.append((poly_index, f"c{k}"))
    for index, role, column in extra:
        columns.append(column)
        roles.append((index, role))
    return Design(np.column_stack(columns), roles, offset, T_pm)


@dataclass
class ModelFit:
    """A fitted model: terms with their nonlinear values, noise state, GLS coefficients."""

    terms: tuple[Term, ...]
    gls: Gls
    beta: np.ndarray
    roles: list[tuple[int, str]]
    rss: float
    loglik: float
    n_params: int
    prediction: np.ndarray
    data: BlockData = field(repr=False)

    @property
    def noise(self) -> NoiseState:
        return self.gls.state

    @property
    def bic(self) -> float:
        return -2.0 * self.loglik + self.n_params * math.log(self.data.n)

    @property
    def residual(self) -> np.ndarray:
        return self.data.accel - self.prediction

    @property
    def identifiers(self) -> list[str]:
        return [term.identifier for term in self.terms]

    def noise_params(self) -> dict[str, dict[str, float]]:
        """Catalogue noise coefficients. White noise comes from the full-rate first differences:
        on block means it is barely separable from flicker, at the sample rate it dominates."""
        values = self.gls.noise_params(self.rss)
        values["white_noise"] = self.data.white_n_mg_rt_s
        names = {
            "white_noise": "n_mg_rt_s",
            "bias_instability": "b_mg",
            "rate_random_walk": "k_mg_per_rt_s",
        }
        return {term: {names[term]: value} for term, value in values.items()}

    def linear(self, index: int) -> dict[str, float]:
        return {
            role: float(b) for (owner, role), b in zip(self.roles, self.beta, strict=True) if owner == index
        }

    def term_contribution(self, index: int) -> np.ndarray:
        """Block-level contribution of one non-poly term (its columns times its coefficients)."""
        design = build_design(self.terms, self.data)
        mask = np.array([owner == index for owner, _ in self.roles])
        out = design.X[:, mask] @ self.beta[mask]
        term = self.terms[index]
        if term.offset is not None:
            out = out + build_design([term], self.data).offset
        return out


def count_params(terms: Sequence[Term], n_columns: int, noise: NoiseState) -> int:
    return n_columns + sum(term.n_free_nl for term in terms) + 1 + len(noise.terms)


def evaluate(terms: Sequence[Term], data: BlockData, gls: Gls) -> ModelFit:
    design = build_design(terms, data)
    y = data.accel - design.offset
    result = gls.fit(design.X, y)
    return ModelFit(
        terms=tuple(terms),
        gls=gls,
        beta=result.beta,
        roles=design.roles,
        rss=result.rss,
        loglik=result.loglik,
        n_params=count_params(terms, design.X.shape[1], gls.state),
        prediction=design.X @ result.beta + design.offset,
        data=data,
    )


def _free_slots(terms: Sequence[Term], data: BlockData) -> list[tuple[int, int, float, float, bool]]:
    """(term index, nl index, lower, upper, log-scaled) of every searchable nonlinear parameter."""
    slots = []
    for i, term in enumerate(terms):
        if term.fixed or term.offset is not None:
            continue
        names = NONLINEAR[term.identifier]
        for j, (name, (lo, hi)) in enumerate(zip(names, search_bounds(term.identifier, data), strict=True)):
            slots.append((i, j, lo, hi, name in LOG_SCALED))
    return slots


def with_values(terms: Sequence[Term], slots: list, z: np.ndarray) -> list[Term]:
    out = list(terms)
    for (i, j, lo, hi, logged), zi in zip(slots, z, strict=True):
        value = float(np.clip(10.0**zi if logged else zi, lo, hi))
        nl = list(out[i].nl)
        nl[j] = value
        out[i] = replace(out[i], nl=tuple(nl))
    return out


def polish(terms: Sequence[Term], data: BlockData, gls: Gls, *, max_evals: int = 120) -> ModelFit:
    """Joint local optimisation of all free nonlinear parameters at fixed noise ratios."""
    slots = _free_slots(terms, data)
    if not slots:
        return evaluate(terms, data, gls)
    z0 = np.array([math.log10(terms[i].nl[j]) if lg else terms[i].nl[j] for i, j, _, _, lg in slots])
    steps = np.array([0.08 if lg else max(data.block_s, 0.01 * (hi - lo)) for _, _, lo, hi, lg in slots])

    def objective(z: np.ndarray) -> float:
        return -evaluate(with_values(terms, slots, z), data, gls).loglik

    simplex = [z0] + [z0 + np.eye(z0.size)[k] * steps[k] for k in range(z0.size)]
    result = minimize(
        objective,
        z0,
        method="Nelder-Mead",
        options={"initial_simplex": np.array(simplex), "maxfev": max_evals, "xatol": 1e-3, "fatol": 0.01},
    )
    best = result.x if result.fun <= objective(z0) else z0
    return evaluate(with_values(terms, slots, best), data, gls)


def fit_model(
    terms: Sequence[Term],
    noise_terms: Sequence[str],
    data: BlockData,
    *,
    start: NoiseState | None = None,
    gls: Gls | None = None,
    refit_noise: bool = True,
    rounds: int = 2,
    optimise: bool = True,
) -> ModelFit:
    """Fit ``terms`` with ``noise_terms``: nonlinear polish and noise ML, alternated ``rounds`` times.

    A cold start (no ``start`` ratios for these noise terms) explores the noise ratios widely first.
    """
    explore = start is None or any(term not in start.terms for term in noise_terms)
    if gls is None:
        if start is None or start.terms != tuple(noise_terms):
            start = _restrict(start, noise_terms, data)
        gls = Gls(data.n, data.block_s, data.duration_s, start)
    fit = polish(terms, data, gls) if optimise else evaluate(terms, data, gls)
    if not refit_noise:
        return fit
    for _ in range(rounds):
        design = build_design(fit.terms, data)
        new_gls, _ = fit_noise(
            design.X,
            data.accel - design.offset,
            data.n,
            data.block_s,
            data.duration_s,
            fit.noise,
            explore=explore,
        )
        explore = False
        moved = np.max(np.abs(np.subtract(new_gls.state.log_ratios, fit.noise.log_ratios)), initial=0.0)
        fit = (
            polish(fit.terms, data, new_gls)
            if optimise and _free_slots(fit.terms, data)
            else evaluate(fit.terms, data, new_gls)
        )
        if moved < 0.15:
            break
    return fit


def _restrict(start: NoiseState | None, noise_terms: Sequence[str], data: BlockData) -> NoiseState:
    """A start state for ``noise_terms``, reusing ratios of ``start`` where it has them."""
    base = initial_state(noise_terms, data.block_s, data.white_n_mg_rt_s)
    if start is None:
        return base
    known = dict(zip(start.terms, start.log_ratios, strict=True))
    logs = tuple(known.get(term, lr) for term, lr in zip(base.terms, base.log_ratios, strict=True))
    return NoiseState(base.terms, logs)


def catalogue_effects(fit: ModelFit) -> list[EffectConfig]:
    """The fitted terms as catalogue ``EffectConfig`` instances (identifiers, names, units)."""
    effects: list[EffectConfig] = []
    for index, term in enumerate(fit.terms):
        lin = fit.linear(index)
        ident = term.identifier
        params: dict[str, float]
        if ident == "bias_poly":
            params = {
                "c0_mg": lin["c0"],
                "c1_mg_per_c": lin["c1"] / POLY_SCALE_C,
                "c2_mg_per_c2": lin["c2"] / POLY_SCALE_C**2,
                "c3_mg_per_c3": lin["c3"] / POLY_SCALE_C**3,
            }
        elif ident == "thermal_lag":
            params = {"tau_s": term.nl[0]}
        elif ident == "temp_rate":
            params = {"k_mg_per_c_per_min": lin["k_mg_per_c_per_min"]}
        elif ident == "hysteresis":
            params = {"amp_mg": lin["amp_mg"], "width_c": term.nl[0]}
        elif ident == "stress_relaxation":
            params = {"gain_mg_per_c": lin["gain_mg_per_c"], "tau_s": term.nl[0]}
        elif ident == "warmup":
            params = {"amp_mg": lin["amp_mg"], "tau_s": term.nl[0]}
        elif ident == "periodic":
            if term.offset is not None:
                amp, phase = term.offset
            else:
                amp, phase = math.hypot(lin["sin"], lin["cos"]), math.atan2(lin["cos"], lin["sin"])
            params = {"amp_mg": amp, "period_s": term.nl[0], "phase_rad": phase}
        elif ident == "bias_step":
            params = {"t_s": term.nl[0], "step_mg": lin["step_mg"]}
        elif ident == "temp_quantization":
            params = {"lsb_c": term.nl[0]}
        elif ident == "scale_factor_tc":
            # Fitted only when the known input varies; otherwise the user's value is kept.
            params = {"sf_ppm_per_c": lin.get("sf_ppm_per_c", term.nl[0] if term.nl else 0.0)}
        else:
            continue
        effects.append(EffectConfig(ident, params))
    return effects
