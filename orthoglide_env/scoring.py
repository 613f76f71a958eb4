"""Scoring an estimate against the true machine (for benchmarks, never for agents).

The controller of a calibrated machine computes its joint commands with the estimated
model; the TCP then lands where the *true* machine puts it.  The score is the distance
from the target over a grid of the workspace, compared with the uncompensated machine
(commands from the nominal model).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from .geometry import RHO_MAX, RHO_MIN, MachineParams
from .kinematics import UnreachableError, direct, inverse

#: TCP targets of the scoring grid span this cube (mm): inside the workspace that the
#: nominal model reaches within the control limits.
GRID_RANGE: tuple[float, float] = (-80.0, 50.0)
GRID_POINTS: int = 7


@dataclass(frozen=True)
class ErrorStats:
    rms: float
    max: float

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        return cls(float(np.sqrt(np.mean(errors**2))), float(np.max(errors)))


@dataclass(frozen=True)
class ScoreReport:
    """Parameter errors (estimate - truth, mm) and TCP errors over the workspace grid."""

    drho_error: list[float]
    dL_error: list[float]
    tcp_before: ErrorStats
    tcp_after: ErrorStats
    n_targets: int
    n_skipped: int

    def to_dict(self) -> dict:
        return asdict(self)


def workspace_grid(points: int = GRID_POINTS) -> np.ndarray:
    """TCP targets (mm) on a cubic grid whose nominal commands respect the control limits."""
    axis = np.linspace(*GRID_RANGE, points)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    rho = inverse(MachineParams(), grid)
    return grid[np.all((rho >= RHO_MIN) & (rho <= RHO_MAX), axis=-1)]


def _rowwise(solve: Callable[[np.ndarray], np.ndarray], points: np.ndarray) -> np.ndarray:
    """``solve`` over rows of ``points`` (n, 3), NaN rows where it finds no solution: the
    batch call raises for the whole batch when one row fails, so only then go row by row
    (a poor estimate may put some targets out of its own reach)."""
    try:
        return solve(points)
    except UnreachableError:
        out = np.full(points.shape, np.nan)
        for k, point in enumerate(points):
            with contextlib.suppress(UnreachableError):
                out[k] = solve(point)
        return out


def tcp_errors(model: MachineParams, truth: MachineParams, targets: np.ndarray) -> np.ndarray:
    """Distance (mm) from each target to where the true machine goes when commanded with
    ``model``; NaN where the model has no command or it would leave the control limits."""
    targets = np.asarray(targets, dtype=float).reshape(-1, 3)
    rho = _rowwise(lambda p: inverse(model, p), targets)
    with np.errstate(invalid="ignore"):
        inside = np.all((rho >= RHO_MIN) & (rho <= RHO_MAX), axis=-1)
    errors = np.full(len(targets), np.nan)
    reached = _rowwise(lambda r: direct(truth, r), rho[inside])
    errors[inside] = np.linalg.norm(reached - targets[inside], axis=-1)
    return errors


def score(
    estimate: MachineParams, truth: MachineParams, grid: np.ndarray | None = None
) -> ScoreReport:
    """Score ``estimate`` against ``truth``: parameter errors and TCP errors before
    (nominal model) and after (estimated model) compensation."""
    targets = workspace_grid() if grid is None else np.asarray(grid, dtype=float)
    before = tcp_errors(MachineParams(), truth, targets)
    after = tcp_errors(estimate, truth, targets)
    usable = np.isfinite(before) & np.isfinite(after)
    if not usable.any():
        raise ValueError("no target of the scoring grid is reachable within the control limits")
    return ScoreReport(
        drho_error=(estimate.drho - truth.drho).tolist(),
        dL_error=(estimate.dL - truth.dL).tolist(),
        tcp_before=ErrorStats.of(before[usable]),
        tcp_after=ErrorStats.of(after[usable]),
        n_targets=int(usable.sum()),
        n_skipped=int((~usable).sum()),
    )
