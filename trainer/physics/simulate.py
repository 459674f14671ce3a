"""Assemble a simulated oven recording from a :class:`PhysicsConfig` and a seed.

Chain (catalogue): set-point ``S`` -> ``T_die = LP(S, case_tau_s)`` -> thermometer column, and
``accel_mg = g_in (1 + 1e-6 sf (T_pm - T_ref)) + bias + noise``. Ground truth goes into
``true_*`` columns so that ``accel_mg == true_accel_mg + true_drift_mg + true_noise_mg``.
"""

from __future__ import annotations

import zlib

import numpy as np

from trainer import __version__
from trainer.budget import check_rows
from trainer.data.channels import truth_columns
from trainer.data.recording import Recording
from trainer.errors import UserError
from trainer.physics.catalogue import EFFECTS, NOISE
from trainer.physics.config import ChannelConfig, PhysicsConfig, config_hash, input_setters
from trainer.physics.effects import drift
from trainer.physics.inputs import input_signal
from trainer.physics.noise import noise_term
from trainer.physics.profiles import build_profile, format_segments
from trainer.physics.thermal import lowpass
from trainer.progress import progress_bar

# One random stream per source, derived by SeedSequence spawning: the thermometer, the input, then
# one per noise term in catalogue order. Indices are permanent: new streams (new noise terms) are
# appended, so switching one term on or adding a new one never changes the others.
STREAMS: tuple[str, ...] = ("thermometer", "input", *NOISE)
# The columns of every simulated recording; a further channel adds its data column and its truth.
SIMULATED_COLUMNS = (
    "time_s",
    "temp_c",
    "accel_mg",
    "chamber_c",
    "true_temp_c",
    "true_pm_temp_c",
    "true_accel_mg",
    "true_drift_mg",
    "true_noise_mg",
)
CHANNEL_COLUMNS = 1 + len(truth_columns("accel0_x", "mg"))


def stream_rngs(seed: int) -> dict[str, np.random.Generator]:
    """Independent generators per stream for ``seed``."""
    children = np.random.SeedSequence(seed).spawn(len(STREAMS))
    return {name: np.random.default_rng(child) for name, child in zip(STREAMS, children, strict=True)}


def _check(cfg: PhysicsConfig, seed: int, n: int, fs: float) -> None:
    src = cfg.source
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise UserError(f"seed must be a non-negative integer, got {seed!r}")
    if n < 2:
        raise UserError(f"{src}: [recording] duration and sample_rate_hz give {n} samples; need at least 2")
    for index, tone in enumerate(cfg.input.tones if cfg.input.kind == "motion" else ()):
        if tone.freq_hz >= fs / 2:
            raise UserError(
                f"{src}: [input.tones #{index + 1}] freq_hz {tone.freq_hz:g} "
                f"is not below the Nyquist frequency {fs / 2:g} Hz"
            )
    for effect in cfg.effects:
        check = EFFECTS[effect.identifier].sampling_check
        problem = None if check is None else check(effect.params, fs)
        if problem:
            raise UserError(f"{src}: {problem}")
    sf_input = input_setters(cfg.effects)
    if sf_input and cfg.input.kind != "zero":
        effect, name = sf_input[0]
        raise UserError(
            f"{src}: [effects.{effect.identifier}] {name} and [input] both set the true input; give only one"
        )


def channel_rngs(seed: int, name: str) -> dict[str, np.random.Generator]:
    """One generator per noise term of channel ``name``: independent of the recording's streams
    (adding a channel never changes ``accel_mg``) and of other channels' (the name is the key)."""
    entropy = [int(seed), zlib.crc32(name.encode("ascii"))]
    children = np.random.SeedSequence(entropy).spawn(len(NOISE))
    return {term: np.random.default_rng(child) for term, child in zip(NOISE, children, strict=True)}


# The true input of a further channel in a static chamber test: a barometer reads the ambient
# pressure (the standard atmosphere at sea level, ISO 2533), every other axis rests at zero.
STATIC_INPUT = {"pa": 101325.0}


def _channel_columns(
    channel: ChannelConfig, seed: int, t: np.ndarray, T_die: np.ndarray, rate: np.ndarray
) -> dict[str, np.ndarray]:
    """A further channel's data and ground-truth columns: a static chamber test, whose true input is
    :data:`STATIC_INPUT` (a barometer that read 0 Pa would be refused as no barometer's output)."""
    n, dt = t.size, float(t[1] - t[0])
    breakdown = drift(channel.effects, t, T_die, g_in_mg=0.0, dT_die_dt_c_per_min=rate)
    rngs = channel_rngs(seed, channel.name)
    noise = np.zeros(n)
    for term in channel.noise:
        noise += noise_term(term.identifier, term.params, n, dt, rngs[term.identifier])
    total = np.ascontiguousarray(breakdown.total, dtype=np.float64)
    truth = truth_columns(channel.name, channel.unit)
    true_input = np.full(n, STATIC_INPUT.get(channel.unit, 0.0))
    return {
        channel.column: true_input + total + noise,
        truth["true_accel_mg"]: true_input,
        truth["true_drift_mg"]: total,
        truth["true_noise_mg"]: noise,
        truth["true_pm_temp_c"]: np.array(breakdown.T_pm, dtype=np.float64),
    }


@np.errstate(over="ignore", invalid="ignore")  # an overflow is refused by _check_finite
def simulate(cfg: PhysicsConfig, seed: int, *, progress: bool = False) -> Recording:
    """Simulate one recording; same ``cfg`` and ``seed`` give bit-identical columns.

    ``progress`` shows a bar on stderr (timed lines when stderr is not a terminal).
    """
    fs = cfg.recording.sample_rate_hz
    dt = 1.0 / fs
    start_c, specs = cfg.protocol.resolved()
    nominal_rows(cfg)  # within the memory budget before anything is allocated
    profile = build_profile(cfg.protocol.name, start_c, specs, cfg.recording.duration_s)
    n = round(profile.duration_s * fs)
    _check(cfg, seed, n, fs)
    rngs = stream_rngs(int(seed))
    stages = progress_bar(progress=progress, total=5, desc="simulate", unit="stage", leave=False)

    t = np.arange(n) * dt
    setpoint = profile.setpoint(t)
    tau = cfg.temperature.case_tau_s
    T_die = lowpass(setpoint, tau, dt)
    # Analytic derivative of the continuous LP at the sample instants: dT/dt = (S - T)/tau.
    rate = (setpoint - T_die) / tau * 60.0
    stages.update()

    sf_given = [effect.params[name] for effect, name in input_setters(cfg.effects)]
    g_in = np.full(n, sf_given[0]) if sf_given else input_signal(cfg.input, t, rngs["input"])
    stages.update()

    breakdown = drift(cfg.effects, t, T_die, g_in_mg=g_in, dT_die_dt_c_per_min=rate)
    stages.update()

    temp_c = T_die + rngs["thermometer"].standard_normal(n) * cfg.temperature.temp_noise_c
    for effect in cfg.effects:
        reading = EFFECTS[effect.identifier].thermometer
        if reading is not None:
            temp_c = reading(temp_c, effect.params)
    stages.update()

    noise = np.zeros(n)
    for term in cfg.noise:
        noise += noise_term(term.identifier, term.params, n, dt, rngs[term.identifier])
    stages.update()
    stages.close()

    total_drift = np.ascontiguousarray(breakdown.total, dtype=np.float64)
    values = (
        t,
        temp_c,
        g_in + total_drift + noise,
        setpoint,
        T_die,
        np.array(breakdown.T_pm, dtype=np.float64),
        g_in,
        total_drift,
        noise,
    )
    columns = dict(zip(SIMULATED_COLUMNS, values, strict=True))
    for channel in cfg.channels:
        columns.update(_channel_columns(channel, int(seed), t, T_die, rate))
    meta = {
        "sample_rate_hz": f"{fs:.12g}",
        "sensor": cfg.recording.sensor,
        "seed": str(int(seed)),
        "protocol": cfg.protocol.name,
        "segments": format_segments(profile.segments),
        "effects": ",".join(e.identifier for e in cfg.effects) or "none",
        "noise": ",".join(term.identifier for term in cfg.noise) or "none",
        **{f"effects_{c.name}": ",".join(e.identifier for e in c.effects) or "none" for c in cfg.channels},
        "config_hash": config_hash(cfg),
        "generator": f"mems-tdc {__version__} trainer simulate",
    }
    if cfg.recording.duration_s is not None:
        meta["time_scale"] = f"{cfg.recording.duration_s / sum(s.duration_s for s in specs):.12g}"
    _check_finite(cfg, columns)
    return Recording(columns, meta, source=f"simulate(seed={seed})")


def _check_finite(cfg: PhysicsConfig, columns: dict[str, np.ndarray]) -> None:
    """A parameter such as ``c0_mg = 1e308`` overflows to inf: refuse the configuration, naming it."""
    for name, values in columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise UserError(
                f"{cfg.source}: column {name!r} is not finite from row {bad[0]} (t = {columns['time_s'][bad[0]]:g} s): "
                f"a parameter too large for float64 (|value| near 1e308?) in [effects], [noise] or [input]"
            )


def nominal_rows(cfg: PhysicsConfig) -> int:
    """Row count ``simulate`` will produce, refused (one line) when above the memory budget."""
    _, specs = cfg.protocol.resolved()
    duration = cfg.recording.duration_s or sum(s.duration_s for s in specs)
    rate = cfg.recording.sample_rate_hz
    return check_rows(
        duration * rate,
        len(SIMULATED_COLUMNS) + len(cfg.channels) * CHANNEL_COLUMNS,
        f"{cfg.source}: {duration:.4g} s at {rate:.4g} Hz",
        "a shorter protocol or duration (--duration, [recording] duration_s, segment duration_s) or a lower "
        "rate (--rate, [recording] sample_rate_hz)",
    )
