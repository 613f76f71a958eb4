"""How far an estimate lies from the truth in its own error bars: the z-RMS of a virtual
machine's calibration."""

from __future__ import annotations

import numpy as np

from calibrators.estimators.base import Estimate
from calibrators.estimators.consider import WORLD_PREFIX
from calibrators.estimators.exact_fit import z_scores
from calibrators.estimators.gauss_newton import layout_and_values
from calibrators.measurements import Measurements
from calibrators.study.compare import machine_z_scores
from orthoglide_env.instruments.gauges import Gauge
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.reading_model import TrackerAxis, parameters_of


def z_rms(est: Estimate, data: Measurements, machine: MachineParams, gauges: list[Gauge]
          ) -> float | None:
    """RMS of the z-scores of the identifiable combinations of ``est`` (fitted to ``data``)
    against the true ``machine`` and its ``gauges``; None where there is none to take:
    the paper's linear fit reports no information matrix, and a tracker's frame has no
    truth the readings were aligned to."""
    if not est.information.size or any(isinstance(m.gauge, TrackerAxis) for m in data.items):
        return None
    if any(n.startswith(WORLD_PREFIX) for n in est.names):
        # The world's drawn numbers are not the fit's terms: the machine errors' z, as
        # compare scores them.
        z = machine_z_scores([est], [machine])[0]
    else:
        layout, _ = layout_and_values(data)
        truth = parameters_of(layout, machine, gauges)
        free = [est.space.index(n) for n in est.names]
        z = z_scores(est.theta[free], truth[free], est.covariance, est.information, est.scale)
    return float(np.sqrt(np.mean(z**2))) if len(z) else None
