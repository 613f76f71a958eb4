"""``paper``: the paper's linear estimator, eq. (10).

The readings of the paper's procedure (the ``paper`` agent: for each leg Zero -> Max ->
Min three times and a last Zero, section 4) are averaged per posture, and the twelve
differences (Max - Zero and Min - Zero of six gauges) form the linear system of eq. (10),
solved with the Moore-Penrose pseudo-inverse for the full set or for drho or dL alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibrators.estimators.base import (
    PARAM_NAMES,
    PARAM_SETS,
    Calibrator,
    Estimate,
    check_params,
    register,
)
from calibrators.estimators.differences import (
    Differences,
    MissingZeroError,
    differences,
    paper_matrix,
)
from calibrators.estimators.identifiability import analyse
from calibrators.measurements import Measurements
from orthoglide_env.instruments.dial import DEFAULT_SIGMA
from orthoglide_env.instruments.slots import GaugeSpec

#: Held-out sets of the verification: up to this many repetitions each is one; beyond,
#: this many runs of consecutive ones, so that its cost stays linear in the readings.
MAX_FOLDS: int = 10


class NeedsExactFit(ValueError):
    """Readings or options the linear fit cannot take and the exact-model fit can.  The
    message names no option: each command says how its user reaches that fit."""


def folds(data: Measurements) -> list[set[int]]:
    """The held-out sets of repetitions of the verification (see :data:`MAX_FOLDS`): those
    with readings away from Zero (the last Zero opens a repetition of its own)."""
    reps = sorted({m.repetition for m in data.items if not m.is_zero})
    if not reps:
        return []
    return [set(run.tolist()) for run in np.array_split(np.array(reps, dtype=int),
                                                         min(len(reps), MAX_FOLDS))]


@register
class PaperCalibrator(Calibrator):
    """The paper's linear least-squares solution of eq. (10)."""

    name = "paper"

    def solve(self, rows: Differences, free: tuple[int, ...], sigma: float
              ) -> tuple[np.ndarray, np.ndarray]:
        """Parameters (all six, fixed ones 0) and their covariance over the free ones."""
        pinv = np.linalg.pinv(paper_matrix(rows)[:, list(free)])
        theta = np.zeros(6)
        theta[list(free)] = pinv @ rows.values
        return theta, sigma**2 * pinv @ rows.cov_unit @ pinv.T

    def estimate(self, data: Measurements, params: str = "paper6", sigma: float = DEFAULT_SIGMA,
                 *, verify: bool = True, **options: Any) -> Estimate:
        used = [name for name, given in (
            ("prior", options.get("prior", "none") not in ("auto", "none")),
            ("fix", bool(options.get("fix"))), ("holdout", bool(options.get("holdout"))),
            ("keep_outliers", bool(options.get("keep_outliers"))),
            ("solver", options.get("solver", "gauss-newton") != "gauss-newton"),
            ("fit_world", bool(options.get("fit_world"))),
            ("node_spacing", options.get("node_spacing") is not None),
            ("conditions", str(getattr(options.get("conditions", "ideal"), "name",
                                       options.get("conditions", "ideal"))) != "ideal"))
            if given]
        if used:
            raise NeedsExactFit(f"the paper's linear fit (eq. 10) takes no "
                                f"{', '.join(used)}; the exact-model fit does")
        if params not in PARAM_SETS:
            raise NeedsExactFit(f"the paper's linear fit (eq. 10) estimates "
                                f"{list(PARAM_SETS)} only, not '{params}'; the exact-model "
                                "fit estimates any parameters")
        free = check_params(params)
        if any(not isinstance(m.gauge, GaugeSpec) for m in data.items):
            raise NeedsExactFit("the paper's linear fit (eq. 10) reads dial gauges only; "
                                "the exact-model fit reads a tracker's readings too")
        rows = differences(data)
        if len(rows) < len(free):
            raise ValueError(f"only {len(rows)} usable differences for {len(free)} parameters: "
                             "too many readings were not valid")
        theta, cov = self.solve(rows, free, sigma)
        ident = analyse(paper_matrix(rows)[:, list(free)], rows.cov_unit, sigma,
                        tuple(PARAM_NAMES[k] for k in free))
        return Estimate(
            strategy=self.name, params=params, drho=theta[:3], dL=theta[3:], covariance=cov,
            residuals=rows.values - paper_matrix(rows) @ theta,
            singular_values=ident.singular_values, crlb=ident.crlb,
            weak_directions=ident.weak_directions, n_readings=len(data),
            experiment_time_s=data.experiment_time_s,
            verification_rms_mm=self.verify(data, free, sigma) if verify else None,
            sigma=sigma, fisher=ident.fisher, readings=data,
        )

    def verify(self, data: Measurements, free: tuple[int, ...], sigma: float) -> float | None:
        """Leave-one-repetition-out (runs of repetitions beyond :data:`MAX_FOLDS`): fit
        without them, predict their differences; the RMS over every held-out difference
        (mm).  None with fewer than two repetitions.  A held-out set that cannot be fitted
        or predicted (too few rows, a mounting without its Zero) is skipped."""
        held_out = folds(data)
        if len(held_out) < 2:
            return None
        occurring = {m.repetition for m in data.items}
        errors = []
        for held in held_out:
            try:
                train = differences(data, occurring - held)
                test = differences(data, held)
            except MissingZeroError:
                continue
            if len(train) < len(free) or not len(test):
                continue
            theta, _ = self.solve(train, free, sigma)
            errors.append(test.values - paper_matrix(test) @ theta)
        return float(np.sqrt(np.mean(np.concatenate(errors) ** 2))) if errors else None
