"""Scoring an estimate against the true machine (for benchmarks, never for agents).

The controller of a calibrated machine computes its joint commands with the estimated
model; the TCP then lands where the *true* machine puts it.  The score is the TCP error
over a fixed grid of the workspace, compared with the uncompensated machine (commands
from the nominal model), in three frames:

* ``raw``: the world frame;
* ``translation``: after the translation that best fits the reached points to the targets;
* ``rigid``: after the best-fitting rigid motion (rotation and translation, no scale).

No instrument fixed to the base sees the world frame, and no user needs it: before
machining the operator touches off the workpiece, which takes out any rigid offset and
rotation of the machine frame.  What is left after the rigid fit is what a user can act
on, so it is the headline; raw stays beside it.  Best fits are least squares over the
grid, batched over machines (a single machine is a batch of one).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import MachineParams, within_limits
from orthoglide_env.model.kinematics import (
    ERROR_LEGS,
    UnreachableError,
    cross,
    direct,
    dot,
    inverse,
    tcp_sensitivity,
    tcp_sensitivity_factors,
)
from orthoglide_env.world.truth import World

#: The drives' error (mm) a controller compensates, a function of its commands: (n, 3)
#: -> (n, 3).
Correction = Callable[[np.ndarray], np.ndarray]
#: Error terms of the drives at the commands, mm per unit coefficient: (n, 3) -> (n, 3, K).
DriveTerms = Callable[[np.ndarray], np.ndarray]
#: Points along each axis of the scoring grid, whose TCP targets span the design's
#: ``grid_range`` cube (mm), inside the workspace its nominal model reaches within the
#: control limits.
GRID_POINTS: int = 7
#: The frames a TCP error is reported in, headline last.
FRAMES: tuple[str, ...] = ("raw", "translation", "rigid")
#: Machines per pass of the batched scoring.  The arrays of a pass over the grid stay in
#: the processor's cache for 100 machines (~1 MB per array of points); 500 machines at
#: once run at memory speed, 1.5-2x slower per machine (blocks of 50 or 200: 7-25 %).
BLOCK: int = 100


def _blocks(count: int) -> list[slice]:
    """Consecutive slices of at most :data:`BLOCK` machines that cover ``count``."""
    return [slice(i, min(i + BLOCK, count)) for i in range(0, count, BLOCK)]


class _Plain:
    """A result that scripts read as nested dicts of numbers (mm): :meth:`to_dict`."""

    def to_dict(self) -> dict:
        return asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class ErrorStats(_Plain):
    """RMS and maximum (mm) of the TCP error's length over the targets."""

    rms: float
    max: float


@dataclass(frozen=True)
class FrameErrors(_Plain):
    """One TCP error in the three frames of :data:`FRAMES`: as a dict, ``{"raw": {"rms",
    "max"}, "translation": {...}, "rigid": {...}}`` in mm."""

    raw: ErrorStats
    translation: ErrorStats
    rigid: ErrorStats


@dataclass(frozen=True)
class ScoreReport(_Plain):
    """Parameter errors (estimate - truth, mm) and TCP errors over the workspace grid,
    before and after compensation, over the same targets."""

    drho_error: list[float]
    dL_error: list[float]
    tcp_before: FrameErrors
    tcp_after: FrameErrors
    n_targets: int
    n_skipped: int


def workspace_grid(points: int = GRID_POINTS, design: MachineDesign = PROTOTYPE) -> np.ndarray:
    """TCP targets (mm) on a cubic grid over ``design``'s ``grid_range`` whose nominal
    commands respect its control limits."""
    axis = np.linspace(*design.grid_range, points)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[within_limits(inverse(MachineParams(design=design), grid), design).all(axis=-1)]


def _targets(grid: np.ndarray | None, machines: Sequence[MachineParams]) -> np.ndarray:
    """The TCP targets ``grid``, or the scoring grid of the machines' design."""
    if grid is not None:
        return np.asarray(grid, dtype=float)
    return workspace_grid(design=machines[0].design if len(machines) else PROTOTYPE)


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


def commands(model: MachineParams, targets: np.ndarray) -> np.ndarray:
    """Joint commands ``rho`` (mm, shape of ``targets``) that ``model`` computes for the
    TCP ``targets`` (..., 3); NaN rows where it has none within the control limits (the
    controller refuses those)."""
    targets = np.asarray(targets, dtype=float)
    rho = _rowwise(lambda p: inverse(model, p), targets.reshape(-1, 3))
    with np.errstate(invalid="ignore"):
        inside = within_limits(rho, model.design).all(axis=-1)
    rho[~inside] = np.nan
    return rho.reshape(targets.shape)


def tcp_error_vectors(model: MachineParams, truth: MachineParams,
                      targets: np.ndarray) -> np.ndarray:
    """TCP error vectors ``reached - target`` (mm, shape of ``targets`` (..., n, 3)) of the
    true machine commanded with ``model``; NaN rows where ``model`` has no command within
    the control limits."""
    targets = np.asarray(targets, dtype=float)
    return tcp_error_vectors_many([model], [truth], targets.reshape(-1, 3))[0].reshape(
        targets.shape)


def tcp_error_vectors_many(models: Sequence[MachineParams], truths: Sequence[MachineParams],
                           targets: np.ndarray, worlds: Sequence[World] | None = None,
                           corrections: Sequence[Correction | None] | None = None
                           ) -> np.ndarray:
    """:func:`tcp_error_vectors` of many pairs over the targets (n, 3): (M, n, 3).  The
    true machines reach their commands in one batched solve; each machine's numbers are
    those it gets alone.  ``worlds``: the machines' worlds, whose drives' lead error
    the commands meet (the rest of a world passes: the truth is the machine at the 20 C
    reference, warm, each axis at the centre of its backlash).  ``corrections``: per
    model, the drives' error (mm, a function of ``rho`` (n, 3)) that its controller
    compensates (a pitch-error table's, :mod:`orthoglide_env.model.compensation`): it
    commands ``rho - correction(rho)``."""
    if len(models) > BLOCK:
        return np.concatenate([tcp_error_vectors_many(
            models[b], truths[b], targets, None if worlds is None else worlds[b],
            None if corrections is None else corrections[b]) for b in _blocks(len(models))])
    rho = commands_many(models, targets)  # (M, n, 3)
    inside = np.isfinite(rho).all(axis=-1)
    for m, correct in enumerate(corrections or ()):
        if correct is not None:
            rho[m][inside[m]] -= correct(rho[m][inside[m]])
    if worlds is not None:
        rho = rho + World.stack(list(worlds)).lead_error(rho, truths[0].design)

    def alone(m: int) -> np.ndarray:
        out = np.full(rho[m].shape, np.nan)
        out[inside[m]] = _rowwise(lambda r: direct(truths[m], r), rho[m][inside[m]])
        return out

    # Rows without a command are solved at Zero (any posture will do) and dropped; when a
    # posture cannot be assembled, each machine alone.
    try:
        reached = direct(MachineParams.stack(list(truths)), np.where(inside[..., None], rho, 0.0))
    except UnreachableError:
        reached = np.stack([alone(m) for m in range(len(truths))])
    return np.where(inside[..., None], reached, np.nan) - targets


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
    return np.where(inside[..., None], rho, np.nan)


def tcp_errors(model: MachineParams, truth: MachineParams, targets: np.ndarray) -> np.ndarray:
    """Distance (mm) from each target to where the true machine goes when commanded with
    ``model``; NaN where the model has no command within the control limits."""
    return np.linalg.norm(tcp_error_vectors(model, truth, targets), axis=-1)


def _masked_centroids(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Targets and reached points about their centroids over ``mask``, zero (not NaN) in
    the rows left out so that sums ignore them, and the two centroids (..., 3)."""
    keep = mask[..., None]
    q = np.where(keep, targets, 0.0)
    p = np.where(keep, reached, 0.0)
    count = np.sum(mask, axis=-1)[..., None]
    cq = q.sum(axis=-2) / count
    cp = p.sum(axis=-2) / count
    return (np.where(keep, q - cq[..., None, :], 0.0), np.where(keep, p - cp[..., None, :], 0.0),
            cq, cp)


def best_rigid_motion(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R`` (..., 3, 3) and translation ``t`` (..., 3) minimising the sum over
    ``mask`` of ``|R reached + t - target|^2``, for a batch of machines: ``targets`` and
    ``reached`` (..., n, 3) broadcast together, ``mask`` (..., n) marks the usable targets.

    Kabsch's solution without scale: with ``H = sum p q^T`` over the centred points and
    ``H = U S V^T``, ``R = V diag(1, 1, d) U^T`` where ``d = det(V U^T)`` keeps ``R`` a
    rotation when the best orthogonal fit would be a reflection."""
    targets, reached = np.broadcast_arrays(targets, reached)
    q, p, cq, cp = _masked_centroids(targets, reached, np.asarray(mask, dtype=bool))
    u, _, vt = np.linalg.svd(np.einsum("...ni,...nj->...ij", p, q))
    ut, v = np.swapaxes(u, -1, -2), np.swapaxes(vt, -1, -2).copy()
    v[..., 2] *= np.sign(np.linalg.det(v @ ut))[..., None]
    rotation = v @ ut
    return rotation, cq - np.einsum("...ij,...j->...i", rotation, cp)


def remove_translation(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Error vectors (..., n, 3) left after the best-fit translation over ``mask``: the
    errors minus their mean, i.e. the centred reached points minus the centred targets;
    NaN outside ``mask``."""
    mask = np.asarray(mask, dtype=bool)
    q, p, _, _ = _masked_centroids(targets, reached, mask)
    return np.where(mask[..., None], p - q, np.nan)


def remove_rigid(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Error vectors ``R reached + t - target`` (..., n, 3) left after the best-fit rigid
    motion over ``mask`` (:func:`best_rigid_motion`); NaN outside ``mask``."""
    rotation, shift = best_rigid_motion(targets, reached, mask)
    moved = np.einsum("...ij,...nj->...ni", rotation, reached) + shift[..., None, :]
    return np.where(np.asarray(mask, dtype=bool)[..., None], moved - targets, np.nan)


def _stats(errors: np.ndarray, mask: np.ndarray) -> list[ErrorStats]:
    """RMS and max of the lengths of error vectors (B, n, 3) over ``mask`` (B, n)."""
    kept = np.where(mask[..., None], errors, 0.0)
    length2 = dot(kept, kept)
    rms = np.sqrt(length2.sum(axis=-1) / mask.sum(axis=-1))
    worst = np.sqrt(np.max(length2, axis=-1))
    return [ErrorStats(float(r), float(m)) for r, m in zip(rms, worst, strict=True)]


def frame_errors(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray) -> list[FrameErrors]:
    """TCP errors in the three frames for each machine of a batch: ``reached`` (B, n, 3),
    ``targets`` broadcasting to it (a shared grid (n, 3) does), ``mask`` (B, n) of the
    usable targets (at least one per machine)."""
    targets, reached = np.broadcast_arrays(np.asarray(targets, dtype=float),
                                           np.asarray(reached, dtype=float))
    mask = np.asarray(mask, dtype=bool)
    if reached.ndim != 3 or mask.shape != reached.shape[:2]:
        raise ValueError("frame_errors needs reached (B, n, 3) and mask (B, n)")
    if not mask.any(axis=-1).all():
        raise ValueError("every machine needs at least one usable target")
    if len(reached) > BLOCK:
        return [frames for b in _blocks(len(reached))
                for frames in frame_errors(targets[b], reached[b], mask[b])]
    raw = _stats(reached - targets, mask)
    translation = _stats(remove_translation(targets, reached, mask), mask)
    rigid = _stats(remove_rigid(targets, reached, mask), mask)
    return [FrameErrors(*frames) for frames in zip(raw, translation, rigid, strict=True)]


def uncalibrated_errors(truths: Sequence[MachineParams], grid: np.ndarray | None = None,
                        worlds: Sequence[World] | None = None) -> np.ndarray:
    """TCP error vectors (M, n, 3) over the grid of each true machine (in its world, when
    given) commanded with the nominal model: what :func:`score_batch` compares a
    compensation with."""
    targets = _targets(grid, truths)
    nominal = MachineParams(design=truths[0].design) if len(truths) else MachineParams()
    return tcp_error_vectors_many([nominal] * len(truths), truths, targets, worlds)


def score_batch(estimates: Sequence[MachineParams], truths: Sequence[MachineParams],
                grid: np.ndarray | None = None, before: np.ndarray | None = None,
                worlds: Sequence[World] | None = None,
                corrections: Sequence[Correction | None] | None = None) -> list[ScoreReport]:
    """Score each estimate against its true machine (see :func:`score`; ``worlds`` and
    ``corrections``: see :func:`tcp_error_vectors_many`); ``before``: the
    :func:`uncalibrated_errors` of ``truths``, when already known (they depend on the
    machines only, not on the estimates).

    The kinematics and the frame fits run once over the whole batch."""
    if len(estimates) != len(truths) or not truths:
        raise ValueError("score_batch needs as many estimates as true machines, at least one")
    targets = _targets(grid, truths)
    if before is None:
        before = uncalibrated_errors(truths, targets, worlds)
    after = tcp_error_vectors_many(estimates, truths, targets, worlds, corrections)
    usable = np.isfinite(before).all(axis=-1) & np.isfinite(after).all(axis=-1)
    empty = np.flatnonzero(~usable.any(axis=-1))
    if empty.size:
        raise ValueError("no target of the scoring grid is reachable within the control "
                         f"limits (machines {empty.tolist()} of the batch)")
    frames_before = frame_errors(targets, targets + before, usable)
    frames_after = frame_errors(targets, targets + after, usable)
    return [ScoreReport(drho_error=(e.drho - t.drho).tolist(), dL_error=(e.dL - t.dL).tolist(),
                        tcp_before=b, tcp_after=a, n_targets=int(m.sum()),
                        n_skipped=int((~m).sum()))
            for e, t, b, a, m in zip(estimates, truths, frames_before, frames_after, usable,
                                     strict=True)]


def score(estimate: MachineParams, truth: MachineParams, grid: np.ndarray | None = None,
          world: World | None = None, correction: Correction | None = None) -> ScoreReport:
    """Score ``estimate`` against ``truth`` (in its ``world``, when given; its controller
    compensating the drives' error ``correction``, when given): parameter errors and TCP
    errors before (nominal model) and after (estimated model) compensation, in the three
    frames, over the targets both reach within the control limits."""
    return score_batch([estimate], [truth], grid, worlds=None if world is None else [world],
                       corrections=[correction])[0]


# --- predicted errors, from a covariance ----------------------------------------------
def _commanded(models: Sequence[MachineParams], targets: np.ndarray
               ) -> tuple[np.ndarray, MachineParams, np.ndarray, np.ndarray]:
    """Which targets (n, 3) each model commands within the control limits (M, n), the
    models stacked, and the commands and TCPs (M, n, 3) to take derivatives at.

    A model's commands put its own TCP on the target exactly (the inverse is closed form),
    so the target is the TCP.  Targets without a command are taken at Zero, TCP at the
    origin (any well-posed point will do), for the callers to drop.  The derivative of
    the TCP reached at every command over the machine's 27 errors is
    :func:`~orthoglide_env.model.kinematics.tcp_sensitivity` there (the implicit function
    theorem): to first order a machine compensated with a model is off by
    ``jac @ (theta - theta_model)``."""
    machines = MachineParams.stack(list(models))
    rho = commands_many(models, targets, machines)  # (M, n, 3)
    usable = np.isfinite(rho).all(axis=-1)
    rho = np.where(usable[..., None], rho, 0.0)
    p = np.where(usable[..., None], targets, 0.0)
    return usable, machines, rho, p


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
    return _predicted_frames(targets, jac[None], covariance[None])[0]


def _predicted_frames(targets: np.ndarray, jac: np.ndarray, covariance: np.ndarray
                      ) -> list[FrameErrors]:
    """:func:`predicted_frame_errors` of many error models over the same ``targets``:
    ``jac`` (k, m, 3, p), ``covariance`` (k, p, p)."""
    per_target = _per_target(targets, jac, covariance)
    stats = [[ErrorStats(float(r), float(m)) for r, m in zip(
        np.sqrt(per_target[frame].mean(axis=-1)), np.sqrt(per_target[frame].max(axis=-1)),
        strict=True)] for frame in FRAMES]
    return [FrameErrors(*frames) for frames in zip(*stats, strict=True)]


def _per_target(targets: np.ndarray, jac: np.ndarray, covariance: np.ndarray
                ) -> dict[str, np.ndarray]:
    """Per frame, the expected squared error (mm^2) at each target (k, m) of the error
    models of :func:`_predicted_frames`."""
    flat = jac.reshape(len(jac), -1, jac.shape[-1])
    out = {}
    for frame in FRAMES:
        basis = motion_basis(targets, frame)
        left = flat
        if basis.shape[1]:
            q, _ = np.linalg.qr(basis)  # an orthonormal basis: the projection is q q^T
            left = flat - q @ (q.T @ flat)
        per_target = np.sum((left @ covariance) * left, axis=-1).reshape(
            len(jac), -1, 3).sum(-1)
        out[frame] = np.clip(per_target, 0.0, None)  # round-off of a PSD quadratic form
    return out


def _same_targets(usable: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The models (rows of ``usable``, (M, n)) grouped by the targets they reach: each
    distinct mask with the indices of its models."""
    masks, group = np.unique(usable, axis=0, return_inverse=True)
    return [(mask, np.flatnonzero(np.ravel(group) == k)) for k, mask in enumerate(masks)]


def rigid_weights(models: Sequence[MachineParams], grid: np.ndarray | None = None
                  ) -> np.ndarray:
    """``W`` (M, 27, 27) of each model: ``trace(W C)`` is the mean square over the grid of
    the expected TCP error after the best-fit rigid motion (mm^2) for a machine compensated
    with the model whose errors are off by ``N(0, C)``, i.e. the square of
    :func:`predicted_tcp_frames`' rigid RMS: ``W = J^T P J / m``, one matrix product per
    model instead of a quadratic form per target.

    ``J`` is never formed: at each target its column ``e`` is column ``leg(e)`` of a 3 x 3
    inverse ``A`` times a scalar ``r_e`` (:func:`~orthoglide_env.model.kinematics.
    tcp_sensitivity_factors`), so ``J^T J`` has the blocks ``sum_t r_a (A^T A)_ab r_b^T``
    of each pair of legs, and the rigid fit's part ``Q^T J`` has the blocks
    ``sum_t (Q_t^T A)_a r_a^T``: a third of the memory and of the products."""
    if not models:
        return np.zeros((0, 27, 27))
    targets = _targets(grid, models)
    if len(models) > BLOCK:
        return np.concatenate([rigid_weights(models[b], targets) for b in _blocks(len(models))])
    usable, machines, rho, p = _commanded(models, targets)
    inv, row = tcp_sensitivity_factors(machines, rho, p)
    row = np.where(usable[..., None], row, 0.0)  # unreachable targets count for nothing
    # The rigid fit's orthonormal basis over each model's reachable targets, zero on the
    # others: in the common case one set of targets, one basis shared by every model.
    groups = _same_targets(usable)
    shared = len(groups) == 1
    basis = np.zeros((1 if shared else len(models), len(targets), 3, 6))
    for mask, members in groups:
        q = np.linalg.qr(motion_basis(targets[mask], "rigid"))[0].reshape(-1, 3, 6)
        basis[np.ix_([0] if shared else members, np.flatnonzero(mask))] = q
    columns = [np.flatnonzero(ERROR_LEGS == leg) for leg in range(3)]
    rows = [row[..., c] for c in columns]  # (M, n, 9) each
    # Products of 3 x 3 matrices written out: a stack of tens of thousands of small
    # matmuls costs several times more.
    legs = [inv[..., a] for a in range(3)]  # (M, n, 3): the inverse's column of each leg
    out = np.empty((len(models), 27, 27))
    for a, ca in enumerate(columns):
        for b, cb in enumerate(columns[a:], start=a):
            block = np.swapaxes(rows[a] * dot(legs[a], legs[b])[..., None], -1, -2) @ rows[b]
            out[:, ca[:, None], cb] = block
            out[:, cb[:, None], ca] = np.swapaxes(block, -1, -2)
    # Q_t^T A's column of leg a, (M, n, 6), against that leg's entries.
    taken = np.concatenate([np.swapaxes(
        basis[..., 0, :] * legs[a][..., 0, None] + basis[..., 1, :] * legs[a][..., 1, None]
        + basis[..., 2, :] * legs[a][..., 2, None], -1, -2) @ rows[a] for a in range(3)],
        axis=-1)  # (M, 6, 27) in the order of ``columns``
    order = np.concatenate(columns)
    out[:, order[:, None], order] -= np.swapaxes(taken, -1, -2) @ taken
    return out / usable.sum(axis=-1)[:, None, None]


def predicted_tcp_frames(model: MachineParams, covariance: np.ndarray,
                         grid: np.ndarray | None = None) -> FrameErrors:
    """Expected TCP error over the grid, in the three frames, of a machine compensated with
    ``model`` whose 27 errors are off by ``N(0, covariance)``."""
    return predicted_tcp_frames_many([model], [covariance], grid)[0]


def predicted_target_errors(model: MachineParams, covariance: np.ndarray,
                            targets: np.ndarray, drive: DriveTerms | None = None
                            ) -> dict[str, np.ndarray]:
    """Per frame, the expected error (mm, root mean square) at each of ``targets`` (n, 3)
    of a machine compensated with ``model`` (see :func:`predicted_tcp_frames_many`; the
    best fit of a frame is over these targets); NaN where ``model`` has no command."""
    targets = np.asarray(targets, dtype=float)
    usable, machines, rho, p = _commanded([model], targets)
    jac, cov = _with_drives(tcp_sensitivity(machines, rho, p), rho, [covariance],
                            None if drive is None else [drive])
    mask = usable[0]
    out = {frame: np.full(len(targets), np.nan) for frame in FRAMES}
    for frame, values in _per_target(targets[mask], jac[:, mask], cov).items():
        out[frame][mask] = np.sqrt(values[0])
    return out


def _with_drives(jac: np.ndarray, rho: np.ndarray, covariances: Sequence[np.ndarray],
                 drives: Sequence[DriveTerms | None] | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobians (M, n, 3, 27) and covariances extended by each model's drive terms
    at its commands ``rho`` (M, n, 3) (a carriage error moves the tool as an encoder
    offset does), padded with zeros to the largest; unchanged without drives."""
    covariances = [np.asarray(c, dtype=float) for c in covariances]
    if drives is None or all(d is None for d in drives):
        return jac, np.stack(covariances)
    terms = [np.zeros((*rho.shape[1:], 0)) if d is None else d(rho[m])
             for m, d in enumerate(drives)]
    width = max(t.shape[-1] for t in terms)
    moved = np.zeros((*jac.shape[:3], width))
    padded = np.zeros((len(covariances), jac.shape[-1] + width, jac.shape[-1] + width))
    for m, (t, c) in enumerate(zip(terms, covariances, strict=True)):
        moved[m, ..., :t.shape[-1]] = np.einsum("nia,nak->nik", jac[m, ..., :3], t)
        padded[m, :len(c), :len(c)] = c
    return np.concatenate([jac, moved], axis=-1), padded


def predicted_tcp_frames_many(models: Sequence[MachineParams],
                              covariances: Sequence[np.ndarray],
                              grid: np.ndarray | None = None,
                              drives: Sequence[DriveTerms | None] | None = None
                              ) -> list[FrameErrors]:
    """:func:`predicted_tcp_frames` of each model and covariance (the kinematics batched,
    and the frames of the models that reach the same targets).  ``drives``: per model,
    K terms of the drives' error after compensation (their carriage errors at the
    commands); its covariance is then over the 27 errors and the K terms' coefficients
    (a carriage error moves the tool as an encoder offset does)."""
    if not models:
        return []
    targets = _targets(grid, models)
    usable, machines, rho, p = _commanded(models, targets)
    jac, stacked = _with_drives(tcp_sensitivity(machines, rho, p), rho, covariances, drives)
    out: list[FrameErrors | None] = [None] * len(models)
    for mask, members in _same_targets(usable):
        frames = _predicted_frames(targets[mask], jac[members][:, mask], stacked[members])
        for m, frame in zip(members, frames, strict=True):
            out[m] = frame
    return out  # type: ignore[return-value]
