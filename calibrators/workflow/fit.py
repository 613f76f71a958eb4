"""The calibration of a real machine from its measured gauge readings.

:class:`Fit` (the readings, the estimator, the gauges' noise, the conditions the readings
were taken in and, for a filled sheet, its plan) makes the :class:`Calibration`: the
estimate, which :meth:`Calibration.write` saves as an estimate file
(:func:`~calibrators.workflow.compensate.write_estimate`) for
:mod:`~calibrators.workflow.compensate` and :mod:`~calibrators.workflow.verify`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from calibrators.estimators.base import Estimate, Estimator, strict
from calibrators.estimators.catalogue import DEFAULT_ESTIMATOR, for_readings, get_estimator
from calibrators.measurements import Measurements
from calibrators.workflow.compensate import write_estimate
from calibrators.workflow.plan import Procedure, SheetError, check_sheet
from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    GaugeNoise,
    check_noise,
)
from orthoglide_env.world.conditions import IDEAL, Conditions

#: The estimate file :meth:`Calibration.write` writes.
ESTIMATE_FILE = "estimate.json"


class Fit:
    """The fit, configured: the measured ``readings`` (a filled sheet of ``plan``, when
    given, is checked against its steps), read with gauges of repeatability ``sigma`` and
    display ``resolution`` (mm; left out: the plan's gauges, which it was designed for,
    else the dial gauges'), taken under ``conditions`` (``"auto"``: the fit
    estimates them), fitted by ``estimator``: a
    name of :data:`~calibrators.estimators.catalogue.CATALOGUE` or an estimator configured
    with :func:`~calibrators.estimators.get_estimator` (its noise and conditions are set
    from this fit's).  At construction, ``ValueError`` for an unknown estimator, bad noise
    or an estimator that cannot read these conditions, and its kind
    :class:`~calibrators.workflow.plan.SheetError` for readings the plan does not hold;
    :meth:`run` makes the :class:`Calibration`."""

    def __init__(self, readings: Measurements, *,
                 estimator: str | Estimator = DEFAULT_ESTIMATOR,
                 sigma: float | None = None, resolution: float | None = None,
                 conditions: Conditions | str | None = None, plan: Procedure | None = None
                 ) -> None:
        # Gauges not given: the ones the plan was designed for, else the dial gauges.
        gauges = (plan.gauges if plan is not None and plan.gauges is not None
                  else GaugeNoise(DEFAULT_SIGMA, DEFAULT_RESOLUTION))
        sigma = gauges.sigma if sigma is None else sigma
        resolution = gauges.resolution if resolution is None else resolution
        check_noise(sigma, resolution, names=("sigma", "resolution"))
        chosen = get_estimator(estimator) if isinstance(estimator, str) else estimator
        if plan is not None:
            if plan.design != readings.design.to_dict():
                raise SheetError("the plan is for a machine of another design than the "
                                 "readings'")
            check_sheet(readings, plan)
        if conditions is None:
            # The world the plan was made for, else none beyond the geometry.
            conditions = IDEAL if plan is None else Conditions.from_dict(plan.conditions)
        self.readings, self.conditions = readings, conditions
        # A reading's noise: the repeatability and the dial's rounding.
        self.sigma = GaugeNoise(sigma, resolution).effective_sigma
        self.estimator = for_readings(chosen, self.sigma, conditions)

    def run(self) -> Calibration:
        """The estimate of the readings."""
        return Calibration(self.estimator.fit(self.readings))


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
