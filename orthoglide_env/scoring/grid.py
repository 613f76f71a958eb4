"""The scoring grid, and the commands a model gives for its targets within the control limits.

Every score and every prediction of :mod:`orthoglide_env.scoring` is over these targets and
these commands, batched over machines in blocks (a single machine is a batch of one).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams, within_limits
from orthoglide_env.model.kinematics import UnreachableError, inverse

#: Points along each axis of the scoring grid, whose TCP targets span the design's
#: ``grid_range`` cube (mm), inside the workspace its nominal model reaches within the
#: control limits.
GRID_POINTS: int = 7
#: Machines per pass of the batched scoring.  The arrays of a pass over the grid stay in
#: the processor's cache for 100 machines (~1 MB per array of points); 500 machines at
#: once run at memory speed, 1.5-2x slower per machine (blocks of 50 or 200: 7-25 %).
BLOCK: int = 100


def kept_rows(values: np.ndarray, mask: np.ndarray, fill: float, fresh: bool = False
              ) -> np.ndarray:
    """``np.where(mask[..., None], values, fill)``: the points ``values`` (..., 3) in the
    rows ``mask`` keeps, ``fill`` in the others, a new C-ordered array (as numpy's
    selection makes it) unless ``fresh``: then ``values``, an array of the full shape the
    caller made and no longer needs, is filled in place.  The same numbers in half the
    time: numpy's selection broadcasts the mask over each point's three coordinates
    through its buffers."""
    if fresh:
        out = values
    else:
        out = np.empty(np.broadcast_shapes((*np.shape(mask), 1), np.shape(values)),
                       dtype=np.result_type(values, fill))
        out[...] = values
    out[~np.broadcast_to(mask, out.shape[:-1])] = fill
    return out


def blocks(count: int) -> list[slice]:
    """Consecutive slices of at most :data:`BLOCK` machines that cover ``count``."""
    return [slice(i, min(i + BLOCK, count)) for i in range(0, count, BLOCK)]


def workspace_grid(points: int = GRID_POINTS, *, design: MachineDesign) -> np.ndarray:
    """TCP targets (mm) on a cubic grid over ``design``'s ``grid_range`` whose nominal
    commands respect its control limits."""
    axis = np.linspace(*design.grid_range, points)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[within_limits(inverse(MachineParams(design=design), grid), design).all(axis=-1)]


def grid_targets(grid: np.ndarray | None, machines: Sequence[MachineParams]) -> np.ndarray:
    """The TCP targets ``grid``, or the scoring grid of the machines' design (at least
    one machine)."""
    if grid is not None:
        return np.asarray(grid, dtype=float)
    return workspace_grid(design=machines[0].design)


def rowwise(solve: Callable[[np.ndarray], np.ndarray], points: np.ndarray) -> np.ndarray:
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


def commands(model: MachineParams, targets: np.ndarray) -> np.ndarray:
    """Joint commands ``rho`` (mm, shape of ``targets``) that ``model`` computes for the
    TCP ``targets`` (..., 3); NaN rows where it has none within the control limits (the
    controller refuses those)."""
    targets = np.asarray(targets, dtype=float)
    rho = rowwise(lambda p: inverse(model, p), targets.reshape(-1, 3))
    with np.errstate(invalid="ignore"):
        inside = within_limits(rho, model.design).all(axis=-1)
    rho[~inside] = np.nan
    return rho.reshape(targets.shape)


def commands_many(models: Sequence[MachineParams], targets: np.ndarray,
                  stacked: MachineParams | None = None) -> np.ndarray:
    """:func:`commands` of each model for the targets (n, 3): (M, n, 3), in one batched
    solve unless a model cannot reach some target (then model by model, row by row); once
    when every model is the same (the nominal model of every uncalibrated machine).
    ``stacked``: the models as one batch, when the caller has it."""
    stacked = MachineParams.stack(list(models)) if stacked is None else stacked
    vectors = stacked.to_vector()
    if (vectors == vectors[0]).all():
        rho = commands(models[0], targets)
        return np.broadcast_to(rho, (len(models), *rho.shape)).copy()
    try:
        rho = inverse(stacked, np.asarray(targets, dtype=float)[None])
    except UnreachableError:
        return np.stack([commands(m, targets) for m in models])
    inside = within_limits(rho, stacked.design).all(axis=-1)
    return kept_rows(rho, inside, np.nan, fresh=True)

