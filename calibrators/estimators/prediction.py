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

from calibrators.estimators.base import Estimate
from orthoglide_env.model.errors import ERROR_NAMES, MachineParams
from orthoglide_env.scoring import (
    FrameErrors,
    frame_errors,
    predicted_tcp_frames_many,
    rigid_weights,
    tcp_error_vectors,
    workspace_grid,
)


def predicted_correction(est: Estimate, grid: np.ndarray | None = None) -> FrameErrors:
    """How far, over the workspace grid, the estimated machine puts the tool from its
    target under the nominal model's commands: what compensation takes out."""
    machine = est.machine
    targets = workspace_grid(design=machine.design) if grid is None else np.asarray(
        grid, dtype=float)
    errors = tcp_error_vectors(MachineParams(design=machine.design), machine, targets)
    return frame_errors(targets, (targets + errors)[None],
                        np.isfinite(errors).all(axis=-1)[None])[0]


def predicted_tcp_error(est: Estimate, grid: np.ndarray | None = None) -> FrameErrors:
    """:func:`predicted_tcp_errors` of one estimate."""
    return predicted_tcp_errors([est], grid)[0]


def predicted_rigid_mm(ests: list[Estimate], machines: list[MachineParams] | None = None,
                       commands: np.ndarray | None = None) -> np.ndarray:
    """The rigid-frame RMS of :func:`predicted_tcp_errors` of each estimate (mm), alone:
    ``sqrt(trace(W C))`` (:func:`~orthoglide_env.scoring.rigid_weights`) for the
    geometry's part, through the frames where the drives' lead error adds its own.
    ``machines``: the estimates' machines, and ``commands`` their commands over the
    scoring grid (:func:`~orthoglide_env.scoring.grid.commands_many`), when the caller has
    them already."""
    n = len(ERROR_NAMES)
    machines = [e.machine for e in ests] if machines is None else machines
    weights = rigid_weights(machines, commands=commands)
    covariances = np.array([e.error_covariance[:n, :n] for e in ests]).reshape(-1, n, n)
    out = np.sqrt(np.clip(np.einsum("mij,mji->m", weights, covariances), 0.0, None))
    leads = [k for k, e in enumerate(ests) if e.lead_terms]
    if leads:
        frames = predicted_tcp_errors([ests[k] for k in leads])
        out[leads] = [f.rigid.rms for f in frames]
    return out


def predicted_tcp_errors(ests: list[Estimate], grid: np.ndarray | None = None
                         ) -> list[FrameErrors]:
    """Expected error (mm) of the compensated tool position over the workspace grid, in
    the three frames, from the covariance of the estimate's error over the machine's
    errors (with the errors its model leaves out, when it says so) and, under conditions
    with lead error, over its terms (:attr:`~calibrators.estimators.base.Estimate.
    lead_covariance`: what the compensation leaves of a fitted one, all of a considered
    one): the raw RMS is the 3-D standard deviation (square root of the trace of the
    position covariance) averaged over the grid in the mean-square sense."""
    n = len(ERROR_NAMES)
    return predicted_tcp_frames_many(
        [e.machine for e in ests],
        [e.lead_covariance if e.lead_terms else e.error_covariance[:n, :n] for e in ests],
        grid, [e.lead_patterns if e.lead_terms else None for e in ests])
