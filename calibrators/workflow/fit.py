"""The calibration of a real machine from its measured gauge readings.

:class:`Fit` (the readings, the estimator's strategy, parameters and options, the gauges'
noise, the conditions the readings were taken in and, for a filled sheet, its plan) makes
the :class:`Calibration`: the estimate, which :meth:`Calibration.write` saves as an
estimate file (:func:`~calibrators.workflow.compensate.write_estimate`) for
:mod:`~calibrators.workflow.compensate` and :mod:`~calibrators.workflow.verify`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibrators.estimators.base import Estimate, get_strategy, strict
from calibrators.measurements import Measurements
from calibrators.workflow.compensate import write_estimate
from calibrators.workflow.plan import Procedure, SheetError, check_sheet
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA, check_noise
from orthoglide_env.world.conditions import IDEAL, Conditions

#: The strategy a fit uses unless told, and the parameters each strategy frees unless
#: told: every error (and the lab's terms) for the exact model, the paper's six for its
#: linear fit.
DEFAULT_STRATEGY = "gauss-newton"
DEFAULT_PARAMS: dict[str, str] = {"gauss-newton": "full", "paper": "paper6"}
#: The estimate file :meth:`Calibration.write` writes.
ESTIMATE_FILE = "estimate.json"


class Fit:
    """The fit, configured: the measured ``readings`` (a filled sheet of ``plan``, when
    given, is checked against its steps), read with gauges of repeatability ``sigma`` and
    display ``resolution`` (mm), taken under ``conditions``, fitted by ``strategy`` with
    the free ``params`` (default :data:`DEFAULT_PARAMS`) and the estimator's own
    ``options`` (``prior``, ``fix``, ``holdout``, ``seed``, ...).  At construction,
    ``ValueError`` for an unknown strategy or bad noise, and its kind
    :class:`~calibrators.workflow.plan.SheetError` for readings the plan does not hold;
    :meth:`run` makes the :class:`Calibration`."""

    def __init__(self, readings: Measurements, *, strategy: str = DEFAULT_STRATEGY,
                 params: str | None = None, sigma: float = DEFAULT_SIGMA,
                 resolution: float = DEFAULT_RESOLUTION, conditions: Conditions = IDEAL,
                 plan: Procedure | None = None,
                 options: Mapping[str, Any] | None = None) -> None:
        get_strategy(strategy)
        check_noise(sigma, resolution, names=("sigma", "resolution"))
        if plan is not None:
            if plan.design != readings.design.to_dict():
                raise SheetError("the plan is for a machine of another design than the "
                                 "readings'")
            check_sheet(readings, plan)
        self.readings, self.strategy, self.conditions = readings, strategy, conditions
        self.params = DEFAULT_PARAMS.get(strategy, "full") if params is None else params
        # A reading's noise: the repeatability and the dial's rounding.
        self.sigma = float(np.hypot(sigma, resolution / np.sqrt(12)))
        self.options = dict(options or {})

    def run(self) -> Calibration:
        """The estimate of the readings."""
        return Calibration(_estimate(self.readings, self.strategy, self.params, self.sigma,
                                     self.conditions, self.options))


def _estimate(data: Measurements, strategy: str, params: str, sigma: float,
              conditions: Conditions, options: dict[str, Any]) -> Estimate:
    """The one call of an estimator in the workflow."""
    return get_strategy(strategy).estimate(data, params, sigma, conditions=conditions,
                                           **options)


@dataclass(frozen=True)
class Calibration:
    """A fit's outcome: the ``estimate`` (estimated machine, covariance, readings, the
    lab's fitted terms)."""

    estimate: Estimate

    def to_dict(self) -> dict[str, Any]:
        """The estimate as JSON (NaN and infinities as null)."""
        return strict(self.estimate.to_dict())

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Calibration:
        """The outcome :meth:`to_dict` wrote."""
        return cls(Estimate.from_dict(data))

    def write(self, folder: str | Path) -> list[Path]:
        """Write the estimate file :data:`ESTIMATE_FILE` into ``folder`` (made if missing);
        the paths written."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / ESTIMATE_FILE
        write_estimate(path, self.estimate)
        return [path]
