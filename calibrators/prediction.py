"""What an estimate predicts for the machine's accuracy, without knowing the truth.

A real machine has no ground truth to score against; what a calibration can tell is how
far its compensation moves the tool (the error the estimate attributes to the
uncalibrated machine) and how uncertain the compensated tool position is, from the
estimate's covariance.  Both are reported in the three frames of the scoring
(:data:`orthoglide_env.scoring.FRAMES`): raw, after the best-fit translation and after
the best-fit rigid motion over the workspace grid.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.gauges import cross
from orthoglide_env.geometry import ERROR_NAMES, MachineParams
from orthoglide_env.kinematics import direct
from orthoglide_env.scoring import (
    FRAMES,
    ErrorStats,
    FrameErrors,
    commands,
    frame_errors,
    tcp_error_vectors,
    workspace_grid,
)

from .base import Estimate

#: Step of the finite differences of the TCP over the machine's errors (mm or rad): the
#: TCP is smooth in them on a scale of the leg length (or a radian), so the truncation is
#: ~1e-4 / 310 relative, and the round-off ~eps * 310 mm / 1e-4 ~ 1e-9 mm per mm.
TCP_FD_STEP: float = 1e-4


def predicted_correction(est: Estimate, grid: np.ndarray | None = None) -> FrameErrors:
    """How far, over the workspace grid, the estimated machine puts the tool from its
    target under the nominal model's commands: what compensation takes out."""
    targets = workspace_grid() if grid is None else np.asarray(grid, dtype=float)
    errors = tcp_error_vectors(MachineParams(), est.machine, targets)
    return frame_errors(targets, (targets + errors)[None],
                        np.isfinite(errors).all(axis=-1)[None])[0]


def tcp_jacobian(est: Estimate, grid: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The targets of the grid that the estimate commands within the control limits
    (m, 3), and the derivative of the TCP reached at those commands over the machine's
    27 errors (m, 3, 27), all perturbations in one batched solve: to first order the
    compensated error is ``jac @ (theta - theta_hat)``."""
    targets = workspace_grid() if grid is None else np.asarray(grid, dtype=float)
    model = est.machine
    rho = commands(model, targets)
    usable = np.isfinite(rho).all(axis=-1)
    rho = rho[usable]
    theta = model.to_vector()
    steps = TCP_FD_STEP * np.eye(len(ERROR_NAMES))
    moved = direct(MachineParams.from_vector(np.vstack([theta, theta + steps])), rho[None])
    return targets[usable], np.moveaxis((moved[1:] - moved[0]) / TCP_FD_STEP, 0, -1)


def motion_basis(targets: np.ndarray, frame: str) -> np.ndarray:
    """Error fields over ``targets`` (m, 3) that the best fit of ``frame`` removes, to
    first order, as columns of a (3m, k) matrix: none (raw), the 3 constant translations,
    or those and the 3 small rotations ``omega x target`` (rigid)."""
    m = len(targets)
    if frame == "raw":
        return np.zeros((3 * m, 0))
    fields = [np.broadcast_to(axis, (m, 3)) for axis in np.eye(3)]
    if frame == "rigid":
        fields += [cross(axis, targets) for axis in np.eye(3)]
    elif frame != "translation":
        raise ValueError(f"unknown frame '{frame}'; frames are {', '.join(FRAMES)}")
    return np.stack([f.reshape(-1) for f in fields], axis=-1)


def predicted_frame_errors(targets: np.ndarray, jac: np.ndarray,
                           covariance: np.ndarray) -> FrameErrors:
    """Expected TCP error over ``targets`` (m, 3) in each frame for a linear error
    ``jac @ delta`` (jac (m, 3, p)) with ``delta ~ N(0, covariance)``.

    The best fit of a frame is, to first order, the least-squares projection ``P`` off
    its :func:`motion_basis`; the RMS is ``sqrt(trace(P J C J^T P) / m)`` and the max is
    the largest per-target root of the expected squared error."""
    flat = jac.reshape(-1, jac.shape[-1])
    stats = []
    for frame in FRAMES:
        basis = motion_basis(targets, frame)
        left = flat
        if basis.shape[1]:
            left = flat - basis @ np.linalg.lstsq(basis, flat, rcond=None)[0]
        per_target = np.einsum("rf,fg,rg->r", left, covariance, left).reshape(-1, 3).sum(-1)
        per_target = np.clip(per_target, 0.0, None)  # round-off of a PSD quadratic form
        stats.append(ErrorStats(float(np.sqrt(per_target.mean())),
                                float(np.sqrt(per_target.max()))))
    return FrameErrors(*stats)


def predicted_tcp_error(est: Estimate, grid: np.ndarray | None = None) -> FrameErrors:
    """Expected error (mm) of the compensated tool position over the workspace grid, in
    the three frames, from the covariance of the estimate's error over the machine's
    errors (with the errors its model leaves out, when it says so): the raw RMS is the 3-D standard
    deviation (square root of the trace of the position covariance) averaged over the
    grid in the mean-square sense."""
    targets, jac = tcp_jacobian(est, grid)
    n = len(ERROR_NAMES)
    return predicted_frame_errors(targets, jac, est.error_covariance[:n, :n])
