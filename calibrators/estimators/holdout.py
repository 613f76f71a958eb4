"""Readings held out of a fit and predicted: a random fraction (``holdout``), and the
leave-one-repetition-out verification of the exact-model and the paper's fits.
"""

from __future__ import annotations

import numpy as np

from calibrators.estimators.exact_fit import BatchFit, newton_step
from calibrators.measurements import Measurements
from orthoglide_env.reading_model import ReadingLayout, predict

#: Held-out sets of the verification: up to this many repetitions each is one; beyond,
#: this many runs of consecutive ones, so that its cost stays linear in the readings.
MAX_FOLDS: int = 10


def folds(data: Measurements) -> list[set[int]]:
    """The held-out sets of repetitions of the verification (see :data:`MAX_FOLDS`): those
    with readings away from Zero (the last Zero opens a repetition of its own)."""
    reps = sorted({m.repetition for m in data.items if not m.is_zero})
    if not reps:
        return []
    return [set(run.tolist()) for run in np.array_split(np.array(reps, dtype=int),
                                                         min(len(reps), MAX_FOLDS))]


def held_out_residuals(design: ReadingLayout, values: np.ndarray, theta: np.ndarray,
                       train: np.ndarray, test: np.ndarray, world: np.ndarray | None = None
                       ) -> np.ndarray:
    """Residuals of the ``test`` readings predicted by ``theta`` (with the fitted terms of
    ``world``, (N, K), when there are), each mounting's zero taken from its ``train``
    readings (NaN where a mounting has none)."""
    out = np.full(len(values), np.nan)
    if not test.any():
        return out  # the usual fit: every reading used, none to predict
    n = len(design.space.names)
    raw = values - predict(theta[:n], design)
    if world is not None:
        raw -= world @ theta[n:]
    for k in range(len(design.mountings)):
        mine = design.mounting == k
        if (mine & train).any():
            out[mine & test] = raw[mine & test] - raw[mine & train].mean()
    return out


def holdout_mask(design: ReadingLayout, fraction: float, seed: int) -> np.ndarray:
    """A random ``fraction`` (in (0, 1)) of the readings, never a mounting's last
    remaining one."""
    rng = np.random.default_rng(seed)
    held = np.zeros(len(design), dtype=bool)
    held[rng.permutation(len(design))[: round(fraction * len(design))]] = True
    for k in range(len(design.mountings)):
        mine = np.flatnonzero(design.mounting == k)
        if held[mine].all():
            held[mine[0]] = False
    return held


def verification_rms(design: ReadingLayout, values: np.ndarray, result: BatchFit,
                     mask: np.ndarray, data: Measurements, world: np.ndarray | None
                     ) -> float | None:
    """The exact-model fit ``result``'s verification: leave one repetition out (runs of
    repetitions beyond :data:`MAX_FOLDS`, so that the cost stays linear in the
    readings), fit without it (one Gauss-Newton step from the fit of all,
    :func:`~calibrators.estimators.exact_fit.newton_step`), predict its readings (each
    mounting's zero from the rest); the RMS over every held-out reading (mm)."""
    reps = np.array([m.repetition for m in data.items])
    errors = []
    held_out = folds(data)
    if len(held_out) < 2:
        return None  # nothing to hold out: one repetition is the whole experiment
    for held in held_out:
        test = mask & np.isin(reps, list(held))
        train = mask & ~test
        try:
            theta = newton_step(design, values[None], train[None], result.sigma,
                                result.free, result.theta, result.prior, result.scale,
                                world=None if world is None else world[None])[0]
        except np.linalg.LinAlgError:
            continue
        held = held_out_residuals(design, values, theta, train, test, world)[test]
        errors.append(held[np.isfinite(held)])
    errors = np.concatenate(errors) if errors else np.zeros(0)
    return float(np.sqrt(np.mean(errors**2))) if errors.size else None
