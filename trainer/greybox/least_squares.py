"""A one-effect structure fitted by least squares on the samples (``auto``'s ``physics-branch-room``).

The physics fit chooses an effect's nonlinear parameter by the finder's likelihood on block means,
whose noise model can take a slow loop for a random walk: on the bundled run's gyro x the branch
offset came out 1.3 degC wide on two folds, where the samples' least squares put 44 and 22 degC. A
compensator runs with no noise model, so here every parameter is chosen by what it is scored on:
the nonlinear one by the least training residual (a grid over the finder's search range, on a log
scale where the finder searches on one, then a bounded scalar minimisation between the grid points
around the best), the bias polynomial and the effect's amplitude by linear least squares at that
value. The drift is the simulator's own formula (:func:`trainer.physics.effects.drift`) on the
temperature clipped to the training range, the play operator started at ``play_start_c``
(:class:`~trainer.greybox.stream.PhysicsModel`), exactly as the compensator runs it. A
cross-validation fold's held-out rows are run through (the state crosses them) but not fitted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from trainer.data.channels import channel_unit
from trainer.data.recording import Recording
from trainer.diagnose.api import BlockData, Term, build_blocks, channel_scale, search_bounds
from trainer.errors import UserError
from trainer.greybox.fit import FittedPhysics, at_search_bound
from trainer.greybox.structure import Structure
from trainer.physics.catalogue import BACKBONE, DEFINITIONS
from trainer.physics.catalogue.base import T_REF_C, catalogue_params
from trainer.physics.catalogue.bias_poly import POLY_SCALE_C
from trainer.physics.catalogue.plausibility import implausible
from trainer.physics.catalogue.units import channel_param_name
from trainer.physics.effects import EffectConfig, drift

GRID_POINTS = 64


def poly_columns(temp_c: np.ndarray) -> np.ndarray:
    """The finder's backbone columns c0..c3 (powers of the scaled temperature about T_REF_C)."""
    u = (temp_c - T_REF_C) / POLY_SCALE_C
    return np.column_stack([u**k for k in range(4)])


def backbone(values: np.ndarray) -> dict[str, float]:
    """Values of the columns c0..c3 as the catalogue's polynomial coefficients (the finder's mapping)."""
    columns = {f"c{k}": float(v) for k, v in enumerate(values)}
    return catalogue_params(DEFINITIONS[BACKBONE], Term(BACKBONE), columns)


@dataclass(frozen=True)
class OneEffect:
    """A one-effect structure's effect (one shape, one amplitude) and the samples it is fitted on, as
    the compensator runs them: the time from the first sample, the temperature clipped to the training
    range, the output, the training rows (a cross-validation fold's held-out rows are run through,
    not fitted) and the finder's blocks (its search range, the channel's scale)."""

    identifier: str
    shape: str
    on_log: bool
    amplitude: str
    t: np.ndarray
    temp: np.ndarray
    out: np.ndarray
    train: np.ndarray
    data: BlockData

    @classmethod
    def of(
        cls, rec: Recording, structure: Structure, temp_range_c: tuple[float, float], what: str
    ) -> OneEffect:
        """``what`` names the fit in the one-line refusal of another structure."""
        if len(structure.compensated) != 1 or structure.nuisance:
            raise UserError(f"physics: {what} takes one effect; give one in --effects")
        identifier = structure.compensated[0].identifier
        definition = DEFINITIONS[identifier]
        nonlinear = definition.finder.nonlinear
        linear = [p.name for p in definition.params if p.name not in dict(nonlinear)]
        if len(nonlinear) != 1 or len(linear) != 1:
            raise UserError(
                f"physics: {what} takes an effect with one amplitude and one shape; {identifier} is not one"
            )
        (shape, on_log), amplitude = nonlinear[0], linear[0]
        rec = rec.without_truth()
        t = np.asarray(rec.time_s, dtype=np.float64)
        held = rec.held_out()
        out = np.asarray(rec.accel_mg, dtype=np.float64)
        return cls(
            identifier,
            shape,
            on_log,
            amplitude,
            t - t[0],
            np.clip(np.asarray(rec.temp_c, dtype=np.float64), *temp_range_c),
            out,
            np.ones(len(out), dtype=bool) if held is None else ~held,
            build_blocks(rec),
        )


def fit_least_squares(
    rec: Recording, structure: Structure, temp_range_c: tuple[float, float], play_start_c: float | None
) -> FittedPhysics:
    """``structure`` (one compensated effect with one nonlinear and one linear parameter) fitted by
    least squares on the training rows of ``rec``."""
    one = OneEffect.of(rec, structure, temp_range_c, "the least-squares fit")
    identifier, shape, amplitude = one.identifier, one.shape, one.amplitude
    definition = DEFINITIONS[identifier]
    t, temp, out, train, data = one.t, one.temp, one.out, one.train, one.data
    ((lo, hi),) = search_bounds(identifier, data)
    poly = poly_columns(temp)

    def solve(value: float) -> tuple[float, np.ndarray, np.ndarray]:
        unit_term = drift(
            (EffectConfig(identifier, {amplitude: 1.0, shape: value}),), t, temp, play_start_c=play_start_c
        )
        X = np.column_stack([poly, unit_term.total])[train]
        beta, *_ = np.linalg.lstsq(X, out[train], rcond=None)
        return float(np.sum((out[train] - X @ beta) ** 2)), beta, X

    grid = np.geomspace(lo, hi, GRID_POINTS) if one.on_log else np.linspace(lo, hi, GRID_POINTS)
    rss = [solve(float(v))[0] for v in grid]
    k = int(np.argmin(rss))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    best = minimize_scalar(
        lambda v: solve(float(v))[0], bounds=(a, b), method="bounded", options={"xatol": 1e-3 * (b - a)}
    )
    value = float(best.x) if best.fun <= rss[k] else float(grid[k])
    rss_best, beta, X = solve(value)
    dof = max(int(train.sum()) - X.shape[1], 1)
    sd = np.sqrt(np.maximum(np.diag((rss_best / dof) * np.linalg.pinv(X.T @ X)), 0.0))
    term = Term(identifier, (value,))
    params = catalogue_params(definition, term, {amplitude: float(beta[4])})

    unit = channel_unit(rec)
    shown = channel_param_name(shape, unit)
    bound = f"{shown} = {value:.4g} sits at the end of its search range {lo:g}..{hi:g}"
    reasons = [bound] if at_search_bound(term, data) else []
    outside = implausible(identifier, params, channel_scale(rec, data))
    return FittedPhysics(
        effects=(EffectConfig(BACKBONE, backbone(beta[:4])), EffectConfig(identifier, params)),
        nuisance=(),
        std={BACKBONE: backbone(sd[:4]), identifier: {amplitude: float(sd[4])}},
        at_bound=(f"{identifier}.{shown}",) if reasons else (),
        implausible=tuple(f"{identifier}.{channel_param_name(n, unit)}" for n in outside),
        blocks=int(train.sum()),
        block_s=0.0,
        structure=structure,
        notes=(f"{shown} by least squares on the samples over {lo:g}..{hi:g}: {value:.4g}",),
        unit=unit,
        why={identifier: (*reasons, *outside.values())} if reasons or outside else {},
    )
