"""What an estimate predicts for the machine's accuracy, without knowing the truth.

A real machine has no ground truth to score against; what a calibration can tell is how
far its compensation moves the tool (the error the estimate attributes to the
uncalibrated machine) and how uncertain the compensated tool position is, from the
estimate's covariance.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.geometry import RHO_MAX, RHO_MIN, MachineParams
from orthoglide_env.kinematics import direct, inverse
from orthoglide_env.scoring import ErrorStats, tcp_errors, workspace_grid

from .base import PARAM_SETS, Estimate

#: Step of the finite differences of the TCP over the parameters (mm): the TCP is smooth
#: in them on a scale of the leg length, so the truncation is ~1e-4 / 310 relative.
TCP_FD_STEP: float = 1e-4


def predicted_correction(est: Estimate, grid: np.ndarray | None = None) -> ErrorStats:
    """How far, over the workspace grid, the estimated machine puts the tool from its
    target under the nominal model's commands: what compensation takes out."""
    targets = workspace_grid() if grid is None else grid
    errors = tcp_errors(MachineParams(), est.machine, targets)
    return ErrorStats.of(errors[np.isfinite(errors)])


def predicted_tcp_std(est: Estimate, grid: np.ndarray | None = None) -> ErrorStats:
    """Standard deviation (mm, 3-D: square root of the trace of the position covariance)
    of the compensated tool position over the workspace grid, from the estimate's
    covariance: to first order the compensated error is ``dp/dtheta (theta - theta_hat)``
    at the commands computed with the estimate."""
    targets = workspace_grid() if grid is None else grid
    model = est.machine
    rho = inverse(model, targets)
    rho = rho[np.all((rho >= RHO_MIN) & (rho <= RHO_MAX), axis=-1)]
    theta = np.concatenate([est.drho, est.dL])
    base = direct(model, rho)
    cols = []
    for k in PARAM_SETS[est.params]:
        shifted = theta.copy()
        shifted[k] += TCP_FD_STEP
        moved = direct(MachineParams(drho=shifted[:3], dL=shifted[3:]), rho)
        cols.append((moved - base) / TCP_FD_STEP)
    jac = np.stack(cols, axis=-1)  # (targets, 3, free)
    variance = np.einsum("tif,fg,tig->t", jac, est.covariance, jac)
    return ErrorStats.of(np.sqrt(np.clip(variance, 0.0, None)))
