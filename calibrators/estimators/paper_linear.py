"""``paper``: the paper's linear estimator, eq. (10).

The readings of the paper's procedure (the ``paper`` agent: for each leg Zero -> Max ->
Min three times and a last Zero, section 4) are averaged per posture, and the twelve
differences (Max - Zero and Min - Zero of six gauges) form the linear system of eq. (10),
solved with the Moore-Penrose pseudo-inverse for the full set or for drho or dL alone.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from calibrators.estimators.base import (
    PARAM_NAMES,
    PARAM_SETS,
    Estimate,
    Estimator,
    register,
)
from calibrators.estimators.constraints import (
    BOOLEAN,
    Constraint,
    Interval,
    InvalidParameterError,
    Options,
)
from calibrators.estimators.differences import (
    Differences,
    MissingZeroError,
    differences,
    paper_matrix,
)
from calibrators.estimators.holdout import MAX_FOLDS as MAX_FOLDS
from calibrators.estimators.holdout import folds
from calibrators.estimators.identifiability import analyse
from calibrators.measurements import Measurements
from orthoglide_env.instruments.dial import DEFAULT_SIGMA
from orthoglide_env.instruments.slots import GaugeSpec


class NeedsExactFit(ValueError):
    """Readings or options the linear fit cannot take and the exact-model fit can.  The
    message names no option: each command says how its user reaches that fit."""


@register
class PaperCalibrator(Estimator):
    """The paper's linear least-squares solution of eq. (10).

    Parameters: ``params``, the parameter set (:data:`~calibrators.estimators.base.PARAM_SETS`);
    ``sigma``, a dial gauge's repeatability (mm); ``verify``, leave-one-repetition-out
    verification.  What only the exact-model fit takes (a prior, fixed parameters, the
    lab's conditions, ...) is refused with :class:`NeedsExactFit`.
    """

    name = "paper"
    title = "the paper's linear fit (eq. 10)"
    _parameter_constraints: ClassVar[dict[str, list[Constraint]]] = {
        "params": [Options(tuple(PARAM_SETS))],
        "sigma": [Interval(0, None)],
        "verify": [BOOLEAN],
    }

    def __init__(self, *, params: str = "paper6", sigma: float = DEFAULT_SIGMA,
                 verify: bool = True) -> None:
        self.params, self.sigma, self.verify = params, sigma, verify
        self._validate_params()

    def _validate_params(self) -> None:
        try:
            super()._validate_params()
        except InvalidParameterError as exc:
            if exc.parameter != "params":
                raise
            raise NeedsExactFit(f"{self.title} estimates {list(PARAM_SETS)} only, not "
                                f"'{self.params}'; the exact-model fit estimates any "
                                "parameters") from None

    @classmethod
    def refuse(cls, unknown: list[str]) -> ValueError:
        return NeedsExactFit(f"{cls.title} takes no {', '.join(unknown)}; the exact-model "
                             "fit does")

    def solve(self, rows: Differences, free: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Parameters (all six, fixed ones 0) and their covariance over the free ones."""
        pinv = np.linalg.pinv(paper_matrix(rows)[:, list(free)])
        theta = np.zeros(6)
        theta[list(free)] = pinv @ rows.values
        return theta, self.sigma**2 * pinv @ rows.cov_unit @ pinv.T

    def fit(self, data: Measurements) -> Estimate:
        """The estimate of ``data``: readings of dial gauges only."""
        free = PARAM_SETS[self.params]
        if any(not isinstance(m.gauge, GaugeSpec) for m in data.items):
            raise NeedsExactFit("the paper's linear fit (eq. 10) reads dial gauges only; "
                                "the exact-model fit reads a tracker's readings too")
        rows = differences(data)
        if len(rows) < len(free):
            raise ValueError(f"only {len(rows)} usable differences for {len(free)} parameters: "
                             "too many readings were not valid")
        theta, cov = self.solve(rows, free)
        ident = analyse(paper_matrix(rows)[:, list(free)], rows.cov_unit, self.sigma,
                        tuple(PARAM_NAMES[k] for k in free))
        return Estimate(
            strategy=self.name, params=self.params, drho=theta[:3], dL=theta[3:],
            covariance=cov, residuals=rows.values - paper_matrix(rows) @ theta,
            singular_values=ident.singular_values, crlb=ident.crlb,
            weak_directions=ident.weak_directions, n_readings=len(data),
            experiment_time_s=data.experiment_time_s,
            verification_rms_mm=self.verify_fit(data, free) if self.verify else None,
            sigma=self.sigma, fisher=ident.fisher, readings=data,
        )

    def verify_fit(self, data: Measurements, free: tuple[int, ...]) -> float | None:
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
            theta, _ = self.solve(train, free)
            errors.append(test.values - paper_matrix(test) @ theta)
        return float(np.sqrt(np.mean(np.concatenate(errors) ** 2))) if errors else None
