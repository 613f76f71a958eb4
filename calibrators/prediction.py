"""What an estimate predicts for the machine's accuracy, without knowing the truth.

A real machine has no ground truth to score against; what a calibration can tell is how
far its compensation moves the tool (the error the estimate attributes to the
uncalibrated machine) and how uncertain the compensated tool position is, from the
estimate's covariance.  The correction is reported in the three frames of the scoring
(:data:`orthoglide_env.scoring.FRAMES`).
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.geometry import MachineParams
from orthoglide_env.kinematics import direct
from orthoglide_env.scoring import (
    ErrorStats,
    FrameErrors,
    commands,
    frame_errors,
    tcp_error_vectors,
    workspace_grid,
)

from .base import PARAM_SETS, Estimate

#: Step of the finite differences of the TCP over the parameters (mm): the TCP is smooth
#: in them on a scale of the leg length, so the truncation is ~1e-4 / 310 relative.
TCP_FD_STEP: float = 1e-4


def predicted_correction(est: Estimate, grid: np.ndarray | None = None) -> FrameErrors:
    """How far, over the workspace grid, the estimated machine puts the tool from its
    target under the nominal model's commands: what compensation takes out."""
    targets = workspace_grid() if grid is None else np.asarray(grid, dtype=float)
    errors = tcp_error_vectors(MachineParams(), est.machine, targets)
    return frame_errors(targets, (targets + errors)[None],
                        np.isfinite(errors).all(axis=-1)[None])[0]


def predicted_tcp_std(est: Estimate, grid: np.ndarray | None = None) -> ErrorStats:
    """Standard deviation (mm, 3-D: square root of the trace of the position covariance)
    of the compensated tool position over the workspace grid, from the estimate's
    covariance: to first order the compensated error is ``dp/dtheta (theta - theta_hat)``
    at the commands computed with the estimate."""
    targets = workspace_grid() if grid is None else grid
    model = est.machine
    rho = commands(model, targets)
    rho = rho[np.isfinite(rho).all(axis=-1)]
    theta = np.concatenate([est.drho, est.dL])
    base = direct(model, rho)
    cols = []
    for k in PARAM_SETS[est.params]:
        shifted = theta.copy()
        shifted[k] += TCP_FD_STEP
        moved = direct(MachineParams(drho=shifted[:3], dL=shifted[3:]), rho)
        cols.append((moved - base) / TCP_FD_STEP)
    jac = np.stack(cols, axis=-1)  # (targets, 3, free)
    variance = np.clip(np.einsum("tif,fg,tig->t", jac, est.covariance, jac), 0.0, None)
    return ErrorStats(float(np.sqrt(variance.mean())), float(np.sqrt(variance.max())))
