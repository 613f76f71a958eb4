"""Predicted TCP errors: what a machine compensated with a model is expected to miss by,
in the three frames, when the model's errors are off by a known covariance (first order).

Used by agents and planners to judge an experiment before its truth is known, and by the
lab to say whether an episode met its target.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import (
    ERROR_LEGS,
    cross,
    sensitivity_parts,
    tcp_sensitivity,
)
from orthoglide_env.scoring.grid import blocks, commands_many, grid_targets, kept_rows
from orthoglide_env.scoring.reports import FRAMES, ErrorStats, FrameErrors

#: Error terms of the drives at the commands, mm per unit coefficient: (n, 3) -> (n, 3, K).
DriveTerms = Callable[[np.ndarray], np.ndarray]


def _commanded(models: Sequence[MachineParams], targets: np.ndarray,
               commands: np.ndarray | None = None
               ) -> tuple[np.ndarray, MachineParams, np.ndarray, np.ndarray]:
    """Which targets (n, 3) each model commands within the control limits (M, n), the
    models stacked, and the commands and TCPs (M, n, 3) to take derivatives at.

    A model's commands put its own TCP on the target exactly (the inverse is closed form),
    so the target is the TCP.  Targets without a command are taken at Zero, TCP at the
    origin (any well-posed point will do), for the callers to drop.  The derivative of
    the TCP reached at every command over the machine's 27 errors is
    :func:`~orthoglide_env.model.kinematics.tcp_sensitivity` there (the implicit function
    theorem): to first order a machine compensated with a model is off by
    ``jac @ (theta - theta_model)``.  ``commands``: the models' :func:`~orthoglide_env.
    scoring.grid.commands_many` for the targets, when the caller has them."""
    machines = MachineParams.stack(list(models))
    rho = (commands_many(models, targets, machines) if commands is None
           else commands)  # (M, n, 3)
    usable = np.isfinite(rho).all(axis=-1)
    rho = kept_rows(rho, usable, 0.0)
    p = kept_rows(targets, usable, 0.0)
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
    distinct mask with the indices of its models.  Mostly every model reaches the same
    targets: then one group; else the groups in the order of their first models, found by
    the masks' bytes (sorting the masks, as ``np.unique`` does, costs ~30x more)."""
    if (usable == usable[:1]).all():
        return [(usable[0], np.arange(len(usable)))]
    groups: dict[bytes, list[int]] = {}
    for m, mask in enumerate(usable):
        groups.setdefault(mask.tobytes(), []).append(m)
    return [(usable[members[0]], np.array(members)) for members in groups.values()]


def rigid_weights(models: Sequence[MachineParams], grid: np.ndarray | None = None,
                  commands: np.ndarray | None = None) -> np.ndarray:
    """``W`` (M, 27, 27) of each model: ``trace(W C)`` is the mean square over the grid of
    the expected TCP error after the best-fit rigid motion (mm^2) for a machine compensated
    with the model whose errors are off by ``N(0, C)``, i.e. the square of
    :func:`predicted_tcp_frames`' rigid RMS: ``W = J^T P J / m``, one matrix product per
    model instead of a quadratic form per target.

    ``J`` is never formed: at each target its column ``e`` is column ``leg(e)`` of a 3 x 3
    inverse ``A`` times a scalar ``r_e`` (:func:`~orthoglide_env.model.kinematics.
    tcp_sensitivity_factors`), so ``J^T J`` has the blocks ``sum_t r_a (A^T A)_ab r_b^T``
    of each pair of legs, and the rigid fit's part ``Q^T J`` has the blocks
    ``sum_t (Q_t^T A)_a r_a^T``: a third of the memory and of the products.
    ``commands``: the models' :func:`~orthoglide_env.scoring.grid.commands_many` for the
    grid, when the caller has them (a scoring of the same models does)."""
    if not models:
        return np.zeros((0, 27, 27))
    targets = grid_targets(grid, models)
    bases: dict[bytes, np.ndarray] = {}
    return np.concatenate([_rigid_weights(models[b], targets, bases,
                                          None if commands is None else commands[b])
                           for b in blocks(len(models))])


def _rigid_basis(targets: np.ndarray, mask: np.ndarray, bases: dict[bytes, np.ndarray]
                 ) -> np.ndarray:
    """The rigid fit's orthonormal basis (m, 3, 6) over the ``targets`` of ``mask``, from
    ``bases`` when a block before found it (every block of a sweep mostly reaches the
    same targets)."""
    key = mask.tobytes()
    if key not in bases:
        bases[key] = np.linalg.qr(motion_basis(targets[mask], "rigid"))[0].reshape(-1, 3, 6)
    return bases[key]


def _rigid_weights(models: Sequence[MachineParams], targets: np.ndarray,
                   bases: dict[bytes, np.ndarray], commands: np.ndarray | None
                   ) -> np.ndarray:
    """:func:`rigid_weights` of one block of models (``bases``: see :func:`_rigid_basis`;
    ``commands``: the block's, or None)."""
    usable, machines, rho, p = _commanded(models, targets, commands)
    parts = sensitivity_parts(machines, rho, p)
    everywhere = bool(usable.all())
    # The rigid fit's orthonormal basis over each model's reachable targets, zero on the
    # others: in the common case one set of targets, one basis shared by every model.
    groups = _same_targets(usable)
    shared = len(groups) == 1
    basis = np.zeros((1 if shared else len(models), len(targets), 3, 6))
    for mask, members in groups:
        basis[np.ix_([0] if shared else members, np.flatnonzero(mask))] = _rigid_basis(
            targets, mask, bases)
    columns = [np.flatnonzero(ERROR_LEGS == leg) for leg in range(3)]
    # Each leg's entries (M, n, 9), laid out entry by entry in memory as a fancy index of
    # the 27 would make them: the products below then run the same BLAS kernels on the
    # same layout (the same bits).
    rows = []
    for c in columns:
        entries = np.empty((len(c), *usable.shape))
        for k, e in enumerate(c):
            entries[k] = parts.entries[e]
        if not everywhere:
            entries[:, ~usable] = 0.0  # unreached targets count for nothing
        rows.append(np.moveaxis(entries, 0, -1))
    # The inverse's column of each leg, coordinate by coordinate; products of 3 x 3
    # matrices written out: a stack of tens of thousands of small matmuls costs several
    # times more.
    legs = [[parts.inverse[j][a] for j in range(3)] for a in range(3)]
    out = np.empty((len(models), 27, 27))
    for a, ca in enumerate(columns):
        for b, cb in enumerate(columns[a:], start=a):
            through = (legs[a][0] * legs[b][0] + legs[a][1] * legs[b][1]
                       + legs[a][2] * legs[b][2])
            block = np.swapaxes(rows[a] * through[..., None], -1, -2) @ rows[b]
            out[:, ca[:, None], cb] = block
            out[:, cb[:, None], ca] = np.swapaxes(block, -1, -2)
    # Q_t^T A's column of leg a, (M, n, 6), against that leg's entries.
    along = [np.ascontiguousarray(np.moveaxis(basis[..., k, :], -1, 0))
             for k in range(3)]  # (6, 1 | M, n) each
    taken = np.concatenate([np.swapaxes(_turned(along, legs[a]), -1, -2) @ rows[a]
                            for a in range(3)], axis=-1)  # (M, 6, 27) in the order of ``columns``
    order = np.concatenate(columns)
    out[:, order[:, None], order] -= np.swapaxes(taken, -1, -2) @ taken
    return out / usable.sum(axis=-1)[:, None, None]


def _turned(along: list[np.ndarray], leg: list[np.ndarray]) -> np.ndarray:
    """``sum_k Q_t[k] A_t[k]``, (M, n, 6), of the basis's coordinates ``along`` (three of
    (6, 1 | M, n)) and a column of the inverse ``leg`` (three of (M, n)): each of the six
    columns over every target in one run, where the product of (..., 6) and (..., 1)
    operands went through numpy's buffers six numbers at a time (the same operations in
    the same order, in the same layout)."""
    out = np.empty((*leg[0].shape, 6))
    for j in range(6):
        np.add(along[0][j] * leg[0] + along[1][j] * leg[1], along[2][j] * leg[2],
               out=out[..., j])
    return out


def rigid_weight_with_drives(model: MachineParams, drive: DriveTerms,
                             grid: np.ndarray | None = None) -> np.ndarray:
    """``W`` (27 + K, 27 + K) over ``model``'s 27 errors (mm, as the machine file has them)
    and the K coefficients of the drives' terms ``drive`` (as in
    :func:`predicted_tcp_frames_many`): ``trace(W C)`` is the square of the rigid RMS that
    :func:`predicted_tcp_frames_many` gives for ``C`` over them, as one matrix (an
    experiment's designer prices readings against it)."""
    targets = grid_targets(grid, [model])
    usable, machines, rho, p = _commanded([model], targets)
    sensitivity = tcp_sensitivity(machines, rho, p)
    width = sensitivity.shape[-1]
    jac, _ = _with_drives(sensitivity, rho, [np.zeros((width, width))], [drive])
    mask = usable[0]
    flat = jac[0, mask].reshape(-1, jac.shape[-1])
    q, _ = np.linalg.qr(motion_basis(targets[mask], "rigid"))
    left = flat - q @ (q.T @ flat)
    return left.T @ left / np.count_nonzero(mask)


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
    targets = grid_targets(grid, models)
    usable, machines, rho, p = _commanded(models, targets)
    jac, stacked = _with_drives(tcp_sensitivity(machines, rho, p), rho, covariances, drives)
    out: list[FrameErrors | None] = [None] * len(models)
    for mask, members in _same_targets(usable):
        frames = _predicted_frames(targets[mask], jac[members][:, mask], stacked[members])
        for m, frame in zip(members, frames, strict=True):
            out[m] = frame
    return out  # type: ignore[return-value]

