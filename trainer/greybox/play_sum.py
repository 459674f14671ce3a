"""Several instances of a one-effect structure, one per width an octave apart, fitted by bounded
least squares (``auto``'s ``physics-branches``).

One play operator of width ``w`` gives a loop whose return after a reversal is the same whatever the
temperature did before: ``amp (T - P) / (w/2)`` crosses from one branch to the other over ``w`` degC.
A real sensor's loop is wider after a larger excursion: on the bundled run's gyro x, the cooling
from the 74 degC peak sits 0.5-0.7 deg/s above the cooling from 52 degC at 36..52 degC, and one
width fitted to the first cooling and the heating leaves more than no compensation on the last
cooling (0.112 against 0.106 deg/s). A sum of play operators of several widths with amplitudes of
one sign (the Prandtl-Ishlinskii model of hysteresis; a Preisach model whose loops are nested) has
exactly that property: the narrow plays saturate after a small excursion, the wide ones only after a
large one. The widths are a fixed basis, not estimates: an octave apart, halving from the top of
the catalogue's plausible range while inside it (60, 30, 15, 7.5 and 3.75 degC for the branch
offset: every width plausible); the bias polynomial and the amplitudes are linear in the data and
fitted together by bounded least squares (``scipy.optimize.lsq_linear``, amplitudes all >= 0 or all
<= 0, whichever leaves less), and a width whose amplitude comes out 0 is left out of the model. An
amplitude outside the plausible range is flagged by the catalogue's one rule, as any fitted one.
The columns are the simulator's own formula on the clipped temperature with the play operators
started at ``play_start_c``, exactly as the compensator runs them; a cross-validation fold's
held-out rows are run through but not fitted.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear

from trainer.data.channels import channel_unit
from trainer.data.recording import Recording
from trainer.diagnose.api import channel_scale, search_bounds
from trainer.greybox.fit import FittedPhysics
from trainer.greybox.least_squares import OneEffect, backbone, poly_columns
from trainer.greybox.structure import Structure
from trainer.physics.catalogue import BACKBONE, PARAMETERS
from trainer.physics.catalogue.plausibility import implausible
from trainer.physics.catalogue.streamed import instance_suffixes
from trainer.physics.catalogue.units import channel_param_name
from trainer.physics.effects import EffectConfig, drift


def octave_shapes(identifier: str, shape: str, search: tuple[float, float]) -> list[float]:
    """The basis: the plausible range's top, halved while inside the range (the search range where
    the catalogue gives no plausible range)."""
    lo, hi = PARAMETERS[(identifier, shape)].plausible or search
    shapes = [hi]
    while shapes[-1] / 2.0 >= lo:
        shapes.append(shapes[-1] / 2.0)
    return shapes


def fit_play_sum(
    rec: Recording, structure: Structure, temp_range_c: tuple[float, float], play_start_c: float | None
) -> FittedPhysics:
    """``structure`` (one compensated effect with one shape and one amplitude) as a sum of instances
    at the :func:`octave_shapes`, fitted on the training rows of ``rec``."""
    one = OneEffect.of(rec, structure, temp_range_c, "the sum of widths")
    identifier, shape, amplitude = one.identifier, one.shape, one.amplitude
    t, temp, out, train, data = one.t, one.temp, one.out, one.train, one.data
    ((search_lo, search_hi),) = search_bounds(identifier, data)
    shapes = octave_shapes(identifier, shape, (search_lo, search_hi))
    units = [
        drift(
            (EffectConfig(identifier, {amplitude: 1.0, shape: s}),), t, temp, play_start_c=play_start_c
        ).total
        for s in shapes
    ]
    X = np.column_stack([poly_columns(temp), *units])[train]
    y = out[train]
    column_rms = np.maximum(
        np.sqrt(np.mean(X**2, axis=0)), 1e-300
    )  # columns of comparable size for the solver
    free, n = np.full(4, np.inf), len(shapes)
    fits = [
        lsq_linear(X / column_rms, y, bounds=(np.r_[-free, lo], np.r_[free, hi]), method="bvls")
        for lo, hi in ((np.zeros(n), np.full(n, np.inf)), (np.full(n, -np.inf), np.zeros(n)))
    ]
    best = min(fits, key=lambda f: float(f.cost))
    beta = best.x / column_rms
    kept = [k for k in range(n) if beta[4 + k] != 0.0]
    columns = [0, 1, 2, 3, *(4 + k for k in kept)]
    rss = float(np.sum((y - X @ beta) ** 2))
    dof = max(int(train.sum()) - len(columns), 1)
    # standard deviations of the linear fit on the kept columns (the bounds inactive there)
    kept_x = X[:, columns]
    sd = np.sqrt(np.maximum(np.diag((rss / dof) * np.linalg.pinv(kept_x.T @ kept_x)), 0.0))
    instances = tuple(
        EffectConfig(identifier, {amplitude: float(beta[4 + k]), shape: shapes[k]}) for k in kept
    )
    suffixes = instance_suffixes([identifier] * len(instances))
    unit = channel_unit(rec)
    shown = channel_param_name(shape, unit)
    judged_by = channel_scale(rec, data)  # what a gyroscope's or barometer's amplitude is judged against
    outside = {
        identifier + suffix: implausible(identifier, e.params, judged_by)
        for e, suffix in zip(instances, suffixes, strict=True)
    }
    outside = {label: why for label, why in outside.items() if why}
    widths = ", ".join(f"{shapes[k]:.4g}" for k in kept) or "none"
    return FittedPhysics(
        effects=(EffectConfig(BACKBONE, backbone(beta[:4])), *instances),
        nuisance=(),
        std={
            BACKBONE: backbone(sd[:4]),
            **{identifier + suffix: {amplitude: float(sd[4 + i])} for i, suffix in enumerate(suffixes)},
        },
        at_bound=(),
        implausible=tuple(
            f"{label}.{channel_param_name(n, unit)}" for label, why in outside.items() for n in why
        ),
        blocks=int(train.sum()),
        block_s=0.0,
        structure=structure,
        notes=(
            f"{identifier} as a sum over {shown} = {', '.join(f'{s:.4g}' for s in shapes)} (a fixed basis, not "
            f"estimates), amplitudes of one sign by bounded least squares on the samples; kept: {widths}",
        ),
        unit=unit,
        why={label: tuple(why.values()) for label, why in outside.items()},
    )
