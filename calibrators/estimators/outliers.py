"""Outliers of an exact-model fit: which reading to leave out next (a wrong reading, told
from model error by its repetitions), and the readings the model does not fit.

Every function works on the residuals of a batch of machines (M, N) at once; each
machine's numbers are those it gets alone.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.instruments.dial import weighting_sigma

#: A reading is an outlier when its residual exceeds this many robust standard deviations
#: (1.4826 x the median absolute residual, or its instrument's sigma when larger): a normal
#: reading does so with probability 6e-5, so 60 readings flag a good one once in 270 fits.
OUTLIER_K: float = 4.0
#: What the report says of a flagged reading, by its cause (:func:`next_outlier` for the left
#: out ones, :func:`model_misfits` for model error).
CAUSE_WORDS: dict[str, str] = {
    "reading": "unlike its repetitions: a mistyped or misread reading",
    "unrepeated": "no repetition to tell a wrong reading from model error (repeat it to "
                  "tell)",
    "model": "its repetitions read the same: model error, kept in the fit",
}
#: The warning on model error names this many readings, then counts the rest.
LISTED_MISFITS: int = 5
#: At most this fraction of the readings is flagged; beyond it the model, not the
#: readings, is wrong, and the warning says so.
MAX_OUTLIER_FRACTION: float = 0.05


def repetition_means(residuals: np.ndarray, group: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Per reading of each machine (``residuals`` (..., N)), the mean residual of its
    repetitions (the other finite residuals of its group; NaN without one) and how many
    there are, in one pass over every machine's readings.  Each machine's bins are its
    own, filled in the order of its readings: its numbers are those it gets alone."""
    used = np.isfinite(residuals)
    r = np.where(used, residuals, 0.0)
    size = int(group.max()) + 1 if group.size else 0
    machines = int(np.prod(residuals.shape[:-1], dtype=int))
    bins = (group + size * np.arange(machines)[:, None]).ravel()

    def per_reading(weights: np.ndarray) -> np.ndarray:
        sums = np.bincount(bins, weights.ravel(), minlength=machines * size)
        return np.take_along_axis(sums.reshape(machines, size),
                                  np.broadcast_to(group, (machines, len(group))), axis=1)

    total = per_reading(r).reshape(residuals.shape) - r
    count = per_reading(used.astype(float)).reshape(residuals.shape) - used
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan), count


def _nanmedian(values: np.ndarray) -> np.ndarray:
    """``np.nanmedian`` of each row (M, N) over its last axis, to the bit (the mean of the
    two middle finite values, or the middle one twice), and NaN for a row without one,
    with no warning: the rows of a batch at once."""
    ordered = np.sort(values, axis=-1)  # NaN last
    count = np.sum(~np.isnan(values), axis=-1)
    low, high = (np.maximum(i, 0)[:, None] for i in ((count - 1) // 2, count // 2))
    middle = (np.take_along_axis(ordered, low, -1) + np.take_along_axis(ordered, high, -1))
    return np.where(count > 0, middle[:, 0] / 2, np.nan)


def _first_max(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's (M, N) first largest finite value's index and the value, (-1, NaN) for a
    row without one (``np.nanargmax``'s choice)."""
    finite = np.isfinite(values).any(axis=-1)
    index = np.where(finite, np.argmax(np.where(np.isnan(values), -np.inf, values), axis=-1),
                     -1)
    return index, np.where(finite, np.take_along_axis(
        values, np.maximum(index, 0)[:, None], -1)[:, 0], np.nan)


def next_outlier(residuals: np.ndarray, group: np.ndarray, noise: np.ndarray
                 ) -> tuple[np.ndarray, list[str]]:
    """The reading to leave out next of each machine (``residuals`` (M, N)), -1 for none,
    and why.  First the reading furthest from its repetitions, beyond :data:`OUTLIER_K`
    robust standard deviations of that spread (``reading``: a mistyped or misread one; the
    model cannot tell it, since repetitions share the model's error); else the unrepeated
    reading furthest from the model, beyond as many of the residuals' (``unrepeated``).  A
    repeated reading far from the model whose repetitions agree is model error and is not
    left out (:func:`model_misfits`)."""
    if not len(residuals):
        return np.zeros(0, dtype=int), []
    sigma = weighting_sigma(noise)  # gauges and a tracker differ
    repeated, count = repetition_means(residuals, group)
    # In units of its own spread: a reading and the mean of n others differ by
    # sigma * sqrt(1 + 1/n) when both are only noise.
    with np.errstate(divide="ignore"):
        departure = np.abs(residuals - repeated) / (sigma * np.sqrt(1 + 1 / count))
    # A row with a finite value has a finite median: the comparisons below see no NaN.
    spread = 1.4826 * _nanmedian(departure)
    k, worst = _first_max(departure)
    with np.errstate(invalid="ignore"):
        reading = (k >= 0) & (worst > OUTLIER_K * np.maximum(1.0, spread))
    score = np.abs(residuals) / sigma
    robust = 1.4826 * _nanmedian(score)
    score[count > 0] = np.nan
    j, worst = _first_max(score)
    with np.errstate(invalid="ignore"):
        unrepeated = ~reading & (j >= 0) & (worst > OUTLIER_K * np.maximum(1.0, robust))
    index = np.where(reading, k, np.where(unrepeated, j, -1))
    return index, ["reading" if r else "unrepeated" if u else ""
                   for r, u in zip(reading, unrepeated, strict=True)]


def model_misfits(residuals: np.ndarray, group: np.ndarray, noise: np.ndarray
                  ) -> list[np.ndarray]:
    """Of each machine (``residuals`` (M, N)), the used readings beyond :data:`OUTLIER_K`
    robust standard deviations of the residuals whose repetitions read with them: model
    error, kept."""
    score = np.abs(residuals) / weighting_sigma(noise)
    robust = 1.4826 * _nanmedian(score)
    _, count = repetition_means(residuals, group)
    with np.errstate(invalid="ignore"):
        far = (score > OUTLIER_K * np.maximum(1.0, robust)[:, None]) & (count > 0)
    return [np.flatnonzero(row) for row in far]
