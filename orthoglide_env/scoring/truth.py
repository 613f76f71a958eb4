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

from collections.abc import Callable, Sequence

import numpy as np

from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import UnreachableError, direct, dot
from orthoglide_env.scoring.grid import (
    BLOCK,
    blocks,
    commands_many,
    grid_targets,
    kept_rows,
    rowwise,
)
from orthoglide_env.scoring.reports import ErrorStats, FrameErrors, ScoreReport
from orthoglide_env.world.truth import World

#: The drives' error (mm) a controller compensates, a function of its commands: (n, 3)
#: -> (n, 3).
Correction = Callable[[np.ndarray], np.ndarray]


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
                           corrections: Sequence[Correction | None] | None = None,
                           commands: np.ndarray | None = None) -> np.ndarray:
    """:func:`tcp_error_vectors` of many pairs over the targets (n, 3): (M, n, 3).  The
    true machines reach their commands in one batched solve; each machine's numbers are
    those it gets alone.  ``worlds``: the machines' worlds, whose drives' lead error
    the commands meet (the rest of a world passes: the truth is the machine at the 20 C
    reference, warm, each axis at the centre of its backlash).  ``corrections``: per
    model, the drives' error (mm, a function of ``rho`` (n, 3)) that its controller
    compensates (a pitch-error table's, :mod:`orthoglide_env.model.compensation`): it
    commands ``rho - correction(rho)``.  ``commands``: the models' :func:`~orthoglide_env.
    scoring.grid.commands_many` for the targets, when the caller has them."""
    if len(models) > BLOCK:
        return np.concatenate([tcp_error_vectors_many(
            models[b], truths[b], targets, None if worlds is None else worlds[b],
            None if corrections is None else corrections[b],
            None if commands is None else commands[b]) for b in blocks(len(models))])
    # (M, n, 3); a copy of the caller's, which the corrections below change in place.
    rho = commands_many(models, targets) if commands is None else commands.copy()
    inside = np.isfinite(rho).all(axis=-1)
    for m, correct in enumerate(corrections or ()):
        if correct is not None:
            rho[m][inside[m]] -= correct(rho[m][inside[m]])
    if worlds is not None:
        rho = rho + World.stack(list(worlds)).lead_error(rho, truths[0].design)

    def alone(m: int) -> np.ndarray:
        out = np.full(rho[m].shape, np.nan)
        out[inside[m]] = rowwise(lambda r: direct(truths[m], r), rho[m][inside[m]])
        return out

    # Rows without a command are solved at Zero (any posture will do) and dropped; when a
    # posture cannot be assembled, each machine alone.
    try:
        reached = direct(MachineParams.stack(list(truths)), kept_rows(rho, inside, 0.0))
    except UnreachableError:
        reached = np.stack([alone(m) for m in range(len(truths))])
    return kept_rows(reached, inside, np.nan, fresh=True) - targets



def tcp_errors(model: MachineParams, truth: MachineParams, targets: np.ndarray) -> np.ndarray:
    """Distance (mm) from each target to where the true machine goes when commanded with
    ``model``; NaN where the model has no command within the control limits."""
    return np.linalg.norm(tcp_error_vectors(model, truth, targets), axis=-1)


def _masked_centroids(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Targets and reached points about their centroids over ``mask``, zero (not NaN) in
    the rows left out so that sums ignore them, and the two centroids (..., 3)."""
    q = kept_rows(targets, mask, 0.0)
    p = kept_rows(reached, mask, 0.0)
    count = np.sum(mask, axis=-1)[..., None]
    cq = q.sum(axis=-2) / count
    cp = p.sum(axis=-2) / count
    return (kept_rows(q - cq[..., None, :], mask, 0.0, fresh=True),
            kept_rows(p - cp[..., None, :], mask, 0.0, fresh=True), cq, cp)


def best_rigid_motion(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R`` (..., 3, 3) and translation ``t`` (..., 3) minimising the sum over
    ``mask`` of ``|R reached + t - target|^2``, for a batch of machines: ``targets`` and
    ``reached`` (..., n, 3) broadcast together, ``mask`` (..., n) marks the usable targets.

    Kabsch's solution without scale: with ``H = sum p q^T`` over the centred points and
    ``H = U S V^T``, ``R = V diag(1, 1, d) U^T`` where ``d = det(V U^T)`` keeps ``R`` a
    rotation when the best orthogonal fit would be a reflection."""
    targets, reached = np.broadcast_arrays(targets, reached)
    return _rigid_motion(*_masked_centroids(targets, reached, np.asarray(mask, dtype=bool)))


def _rigid_motion(q: np.ndarray, p: np.ndarray, cq: np.ndarray, cp: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`best_rigid_motion` from the targets and reached points about their centroids
    and the centroids (:func:`_masked_centroids`)."""
    u, _, vt = np.linalg.svd(np.einsum("...ni,...nj->...ij", p, q))
    ut, v = np.swapaxes(u, -1, -2), np.swapaxes(vt, -1, -2).copy()
    v[..., 2] *= np.sign(np.linalg.det(v @ ut))[..., None]
    rotation = v @ ut
    return rotation, cq - np.einsum("...ij,...j->...i", rotation, cp)


def remove_translation(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray,
                       centred: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Error vectors (..., n, 3) left after the best-fit translation over ``mask``: the
    errors minus their mean, i.e. the centred reached points minus the centred targets;
    NaN outside ``mask``.  ``centred``: :func:`_masked_centroids` of the three, when the
    caller has them."""
    mask = np.asarray(mask, dtype=bool)
    q, p, _, _ = _masked_centroids(targets, reached, mask) if centred is None else centred
    return kept_rows(p - q, mask, np.nan, fresh=True)


def remove_rigid(targets: np.ndarray, reached: np.ndarray, mask: np.ndarray,
                 centred: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Error vectors ``R reached + t - target`` (..., n, 3) left after the best-fit rigid
    motion over ``mask`` (:func:`best_rigid_motion`); NaN outside ``mask``.  ``centred``:
    see :func:`remove_translation`."""
    rotation, shift = (best_rigid_motion(targets, reached, mask) if centred is None
                       else _rigid_motion(*centred))
    moved = np.einsum("...ij,...nj->...ni", rotation, reached) + shift[..., None, :]
    return kept_rows(moved - targets, np.asarray(mask, dtype=bool), np.nan, fresh=True)


def _stats(errors: np.ndarray, mask: np.ndarray) -> list[ErrorStats]:
    """RMS and max of the lengths of error vectors (B, n, 3) over ``mask`` (B, n)."""
    kept = kept_rows(errors, mask, 0.0)
    length2 = dot(kept, kept)
    rms = np.sqrt(length2.sum(axis=-1) / mask.sum(axis=-1))
    worst = np.sqrt(np.max(length2, axis=-1))
    return [ErrorStats(r, m) for r, m in zip(rms.tolist(), worst.tolist(), strict=True)]


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
        return [frames for b in blocks(len(reached))
                for frames in frame_errors(targets[b], reached[b], mask[b])]
    raw = _stats(reached - targets, mask)
    # Both fits start from the same centred points, computed once.
    centred = _masked_centroids(targets, reached, mask)
    translation = _stats(remove_translation(targets, reached, mask, centred), mask)
    rigid = _stats(remove_rigid(targets, reached, mask, centred), mask)
    return [FrameErrors(*frames) for frames in zip(raw, translation, rigid, strict=True)]


def uncalibrated_errors(truths: Sequence[MachineParams], grid: np.ndarray | None = None,
                        worlds: Sequence[World] | None = None) -> np.ndarray:
    """TCP error vectors (M, n, 3) over the grid of each true machine (in its world, when
    given) commanded with the nominal model: what :func:`score_batch` compares a
    compensation with."""
    targets = grid_targets(grid, truths)
    nominal = MachineParams(design=truths[0].design) if len(truths) else MachineParams()
    return tcp_error_vectors_many([nominal] * len(truths), truths, targets, worlds)


def score_batch(estimates: Sequence[MachineParams], truths: Sequence[MachineParams],
                grid: np.ndarray | None = None, before: np.ndarray | None = None,
                worlds: Sequence[World] | None = None,
                corrections: Sequence[Correction | None] | None = None,
                commands: np.ndarray | None = None) -> list[ScoreReport]:
    """Score each estimate against its true machine (see :func:`score`; ``worlds``,
    ``corrections`` and the estimates' ``commands``: see :func:`tcp_error_vectors_many`);
    ``before``: the
    :func:`uncalibrated_errors` of ``truths``, when already known (they depend on the
    machines only, not on the estimates).

    The kinematics and the frame fits run once over the whole batch."""
    if len(estimates) != len(truths) or not truths:
        raise ValueError("score_batch needs as many estimates as true machines, at least one")
    targets = grid_targets(grid, truths)
    if before is None:
        before = uncalibrated_errors(truths, targets, worlds)
    after = tcp_error_vectors_many(estimates, truths, targets, worlds, corrections, commands)
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

