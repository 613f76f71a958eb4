"""Scoring calibrated machines: against the truth (:mod:`.truth`, for benchmarks, never
for agents) and as predicted from an estimate's covariance (:mod:`.predicted`), over the
workspace grid of :mod:`.grid`, reported as in :mod:`.reports`.

Every public name of the former module ``orthoglide_env/scoring.py`` is importable from
here.
"""

from orthoglide_env.scoring.grid import (
    BLOCK,
    GRID_POINTS,
    commands,
    commands_many,
    workspace_grid,
)
from orthoglide_env.scoring.predicted import (
    DriveTerms,
    motion_basis,
    predicted_frame_errors,
    predicted_target_errors,
    predicted_tcp_frames,
    predicted_tcp_frames_many,
    rigid_weights,
)
from orthoglide_env.scoring.reports import FRAMES, ErrorStats, FrameErrors, ScoreReport
from orthoglide_env.scoring.truth import (
    Correction,
    best_rigid_motion,
    frame_errors,
    remove_rigid,
    remove_translation,
    score,
    score_batch,
    tcp_error_vectors,
    tcp_error_vectors_many,
    tcp_errors,
    uncalibrated_errors,
)

__all__ = [
    "BLOCK", "FRAMES", "GRID_POINTS", "Correction", "DriveTerms", "ErrorStats", "FrameErrors",
    "ScoreReport", "best_rigid_motion", "commands", "commands_many", "frame_errors",
    "motion_basis", "predicted_frame_errors", "predicted_target_errors",
    "predicted_tcp_frames", "predicted_tcp_frames_many", "remove_rigid",
    "remove_translation", "rigid_weights", "score", "score_batch", "tcp_error_vectors",
    "tcp_error_vectors_many", "tcp_errors", "uncalibrated_errors", "workspace_grid",
]
