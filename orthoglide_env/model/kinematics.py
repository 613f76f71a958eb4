"""Exact kinematics of the Orthoglide, vectorised over postures.

Two layers:

* the paper's closed forms for its six-parameter model (eq. 3 inverse, eq. 4 direct,
  eq. 5 Jacobian), in the paper's variables ``q_i = L + rho_i + drho_i``;
* the general model of :class:`~orthoglide_env.model.errors.MachineParams` (tilted and
  offset actuator axes, platform attachment errors), solved exactly: the inverse in
  closed form, the direct by Newton's method started from the paper's closed form.

Every function takes arrays of shape ``(..., 3)`` and keeps the leading dimensions.  A
machine may be a batch (:attr:`MachineParams.batch_shape`): then the leading dimensions of
``rho`` or ``p`` are the batch dimensions, followed by any posture dimensions, so
``rho`` of shape ``(B, P, 3)`` is P postures of each of B machines and ``(1, P, 3)`` the
same P postures on every machine.  One machine is a batch of shape ``()``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import R_LEG, MachineParams, within_limits


class UnreachableError(ValueError):
    """A posture the machine cannot reach or assemble in."""


class Geometry(NamedTuple):
    """A machine's derived geometry, shaped to broadcast against a batch of postures."""

    drho: np.ndarray  # (*batch, *1, 3)
    lengths: np.ndarray  # (*batch, *1, 3)
    u: np.ndarray  # actuator directions (*batch, *1, 3, 3)
    o: np.ndarray  # actuator axis points (*batch, *1, 3, 3)
    attach: np.ndarray  # R2 centres relative to the TCP (*batch, *1, 3, 3)


def geometry(machine: MachineParams, points: np.ndarray) -> tuple[Geometry, np.ndarray]:
    """``machine``'s geometry with one singleton axis per posture dimension of ``points``
    (shape ``(*batch, *postures, 3)``; fewer leading dimensions than the batch broadcast
    over it), and ``points`` as a float array."""
    points = np.asarray(points, dtype=float)
    batch = machine.batch_shape
    extra = points.ndim - 1 - len(batch)
    if extra < 0:
        points = points.reshape((1,) * -extra + points.shape)
        extra = 0
    pad = (1,) * extra

    def shaped(value: np.ndarray, tail: int) -> np.ndarray:
        return value.reshape(*batch, *pad, *value.shape[value.ndim - tail:])

    return Geometry(shaped(machine.drho, 1), shaped(machine.leg_lengths, 1),
                    shaped(machine.axis_directions, 2), shaped(machine.axis_origins, 2),
                    shaped(machine.attach_points, 2)), points


# --- the paper's model ---------------------------------------------------------------
def inverse_paper(p: np.ndarray, drho: np.ndarray, lengths: np.ndarray,
                  nominal: float) -> np.ndarray:
    """Eq. (3): control coordinates ``rho`` (mm) placing the TCP at ``p``.

    ``rho_i = p_i + sqrt(L_i^2 - p_j^2 - p_k^2) - drho_i - L`` (the configuration index
    s_i = +1 of the prototype's assembly mode; ``-L`` converts the paper's joint variable
    into control coordinates; ``nominal``: the design's L).
    """
    p = np.asarray(p, dtype=float)
    sq = dot(p, p)[..., None]
    disc = np.asarray(lengths) ** 2 - (sq - p**2)
    _require(disc >= 0, "the TCP is farther from an actuator axis than the leg length")
    return p + np.sqrt(disc) - np.asarray(drho) - nominal


def direct_paper(rho: np.ndarray, drho: np.ndarray, lengths: np.ndarray,
                 nominal: float) -> np.ndarray:
    """Eq. (4): TCP position from control coordinates, the assembly mode's root.

    With ``q = L + rho + drho`` (``L``: the design's, ``nominal``), subtracting the
    equations (2) pairwise gives
    ``p_i = a_i + t / q_i`` with ``a_i = (q_i^2 - L_i^2) / (2 q_i)`` and ``t = |p|^2 / 2``;
    ``|p|^2 = 2t`` is then quadratic in ``t``.  The prototype's assembly mode is the
    *smaller* root (at Zero the roots are ``0`` and ``2L^2/3``; the root printed in the
    paper, with ``+sqrt``, is the other mode), computed in the cancellation-free form
    ``t = 2c / (-b + sqrt(b^2 - 4ac))``.
    """
    q = nominal + np.asarray(rho, dtype=float) + np.asarray(drho)
    lengths = np.asarray(lengths, dtype=float)
    _require(np.abs(q) > 1e-9, "an actuator carriage sits at the axis intersection")
    a_vec = (q**2 - lengths**2) / (2 * q)
    b_vec = 1.0 / q
    qa = dot(b_vec, b_vec)
    qb = 2 * dot(a_vec, b_vec) - 2.0
    qc = dot(a_vec, a_vec)
    disc = qb**2 - 4 * qa * qc
    _require(disc >= 0, "the legs cannot be assembled at these joint coordinates")
    t = 2 * qc / (-qb + np.sqrt(disc))
    return a_vec + t[..., None] * b_vec


def jacobian_paper(p: np.ndarray, rho: np.ndarray, drho: np.ndarray, lengths: np.ndarray,
                   nominal: float) -> np.ndarray:
    """Eq. (5): ``dp / d(drho, L)``, shape ``(..., 3, 6)``.

    Differentiating eq. (2) gives ``M dp/ddrho = diag(p_i - q_i)`` and
    ``M dp/dL = diag(L_i)`` with ``M[i] = p - q_i e_i``.
    """
    p = np.asarray(p, dtype=float)
    q = nominal + np.asarray(rho, dtype=float) + np.asarray(drho)
    lengths = np.broadcast_to(np.asarray(lengths, dtype=float), q.shape)
    m = p[..., None, :] - q[..., :, None] * np.eye(3)
    diag_p = np.eye(3) * (p - q)[..., None, :]
    diag_l = np.eye(3) * lengths[..., None, :]
    return np.linalg.solve(m, np.concatenate([diag_p, diag_l], axis=-1))


# --- the general model -----------------------------------------------------------------
def carriage_points(machine: MachineParams, rho: np.ndarray) -> np.ndarray:
    """Centres A_i of the R1 joints, shape ``(..., 3 legs, 3)``."""
    g, rho = geometry(machine, rho)
    s = _slide(machine) + g.drho + rho
    return g.o + s[..., :, None] * g.u


def platform_points(machine: MachineParams, p: np.ndarray) -> np.ndarray:
    """Centres C_i of the R2 joints for TCP ``p``, shape ``(..., 3 legs, 3)``."""
    g, p = geometry(machine, p)
    return p[..., None, :] + g.attach


def inverse(machine: MachineParams, p: np.ndarray) -> np.ndarray:
    """Control coordinates ``rho`` (mm) that put the TCP at ``p`` (mm), exactly.

    Raises :class:`UnreachableError` when a leg cannot reach; the joint limits are not
    checked here (see :func:`check_reachable`).
    """
    g, p = geometry(machine, p)
    w = p[..., None, :] + g.attach - g.o - (_slide(machine) + g.drho)[..., None] * g.u
    uw = dot(w, g.u)
    disc = uw**2 - dot(w, w) + g.lengths**2
    _require(disc >= 0, "the TCP is out of reach of a leg")
    return uw + np.sqrt(disc)


def direct(machine: MachineParams, rho: np.ndarray, *, tol: float = 1e-11, max_iter: int = 30
           ) -> np.ndarray:
    """TCP position (mm) for control coordinates ``rho``, exactly (Newton to ``tol`` mm)."""
    g, rho = geometry(machine, rho)
    p = direct_paper(rho, g.drho, g.lengths, machine.design.L)
    if machine.is_paper_model:
        return p
    a = g.o + (_slide(machine) + g.drho + rho)[..., :, None] * g.u
    shape = p.shape[:-1]
    lengths2 = np.broadcast_to(g.lengths**2, (*shape, 3))
    if p.size == 3:
        # One posture (a single env's step): numpy scalars, whose arithmetic costs a
        # fraction of one-element arrays', in the same operations (the same bits).
        attach, carriage = (_components(np.reshape(x, (3, 3)), ()) for x in (g.attach, a))
        q = _newton(attach, carriage, list(lengths2.reshape(3)), list(p.reshape(3)), (),
                    tol, max_iter)
        return q.reshape(p.shape)
    # Every coordinate of every leg as one contiguous array over the whole batch: numpy then
    # runs each operation below as one long loop (a third faster on a sweep's scoring
    # grid), with the same arithmetic in the same order as the vector form.
    attach, carriage = (_components(np.broadcast_to(x, (*shape, 3, 3)), shape)
                        for x in (g.attach, a))
    return _newton(attach, carriage, [np.array(x) for x in np.moveaxis(lengths2, -1, 0)],
                   [np.array(p[..., j]) for j in range(3)], shape, tol, max_iter)


def _newton(attach: list[list[np.ndarray]], carriage: list[list[np.ndarray]],
            lengths2: list[np.ndarray], q: list[np.ndarray], shape: tuple[int, ...],
            tol: float, max_iter: int) -> np.ndarray:
    """:func:`direct`'s Newton iterations from the TCP ``q`` (its three coordinates), each
    leg ``i`` of squared length ``lengths2[i]`` between its carriage's R1 centre
    ``carriage[i]`` and the TCP plus ``attach[i]`` (coordinates ``[i][j]``, each of batch
    ``shape``, or scalars for ``()``): the TCPs ``(*shape, 3)``."""
    moving = np.ones(shape, dtype=bool)
    for _ in range(max_iter):
        v = [[(q[j] + attach[i][j]) - carriage[i][j] for j in range(3)] for i in range(3)]
        f = [v[i][0] * v[i][0] + v[i][1] * v[i][1] + v[i][2] * v[i][2] - lengths2[i]
             for i in range(3)]
        # Newton's step solves (2 v) step = f by Cramer's rule, the cross products of the
        # rows over the determinant: ~5x faster than batched LAPACK solves of tens of
        # thousands of 3 x 3 systems, and these are well conditioned (legs far from
        # parallel).
        r = [[2 * x for x in row] for row in v]
        c0, c1, c2 = _cross_rows(r[1], r[2]), _cross_rows(r[2], r[0]), _cross_rows(r[0], r[1])
        det = r[0][0] * c0[0] + r[0][1] * c0[1] + r[0][2] * c0[2]
        step = [(f[0] * c0[j] + f[1] * c1[j] + f[2] * c2[j]) / det for j in range(3)]
        # A converged posture stops moving, so its result does not depend on the batch
        # it was solved in (one machine or many give the same bits); while every one
        # moves, each takes its step as it is.
        held = step if moving.all() else [np.where(moving, s, 0.0) for s in step]
        q = [q[j] - held[j] for j in range(3)]
        size = np.maximum(np.maximum(abs(step[0]), abs(step[1])), abs(step[2]))
        moving &= size >= tol
        if not moving.any():
            return np.stack(q, axis=-1)
    raise UnreachableError("direct kinematics did not converge: posture near a singularity")


def _components(x: np.ndarray, shape: tuple[int, ...]) -> list[list[np.ndarray]]:
    """``x[..., i, j]`` (``(*shape, 3, 3)``) as contiguous copies, ``[i][j]`` (numpy
    scalars for ``shape`` ``()``)."""
    if not shape:
        return [[x[i, j] for j in range(3)] for i in range(3)]
    return [[np.array(x[..., i, j]) for j in range(3)] for i in range(3)]


def _cross_rows(a: list[np.ndarray], b: list[np.ndarray]) -> list[np.ndarray]:
    """:func:`cross` of vectors given as their three coordinate arrays."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


#: Columns of the 27 errors (:data:`~orthoglide_env.model.errors.ERROR_NAMES`) that move leg
#: ``i``: its encoder offset, length, the two tilts and two offsets of its actuator axis,
#: and the three coordinates of its R2 centre on the platform.
DRHO_COLUMN, LENGTH_COLUMN, TILT_COLUMN, OFFSET_COLUMN, ATTACH_COLUMN = 0, 3, 6, 12, 18
#: The five errors that move leg ``i``'s R1 centre (row ``i``): its encoder offset, then
#: the two tilts and the two offsets of its actuator axis.
CARRIAGE_COLUMNS: np.ndarray = np.array(
    [[DRHO_COLUMN + i, TILT_COLUMN + 2 * i, TILT_COLUMN + 2 * i + 1, OFFSET_COLUMN + 2 * i,
      OFFSET_COLUMN + 2 * i + 1] for i in range(3)])
#: The leg each of the 27 errors belongs to: every error moves one leg's loop only.
ERROR_LEGS: np.ndarray = np.concatenate([np.arange(3), np.arange(3), np.repeat(np.arange(3), 2),
                                         np.repeat(np.arange(3), 2), np.repeat(np.arange(3), 3)])


def axis_direction_derivatives(machine: MachineParams) -> np.ndarray:
    """Derivative of each actuator direction ``u_i`` over its two tilts, in closed form:
    ``(*batch, 3 legs, 2, 3)``.  With ``u_i = R_LEG[i] l_i`` and ``l_i = (1, tan a, tan b)
    / N``: ``dl/da = (I - l l^T) e_1 sec^2(a) / N`` (``b`` with ``e_2``)."""
    tilt = machine.axis_tilt  # (*batch, 3, 2)
    local = np.concatenate([np.ones((*tilt.shape[:-1], 1)), np.tan(tilt)], axis=-1)
    norm = np.linalg.norm(local, axis=-1, keepdims=True)
    local = local / norm
    dlocal = (np.eye(3)[1:] - local[..., None, :] * local[..., 1:, None]) * (
        1.0 / (np.cos(tilt) ** 2 * norm))[..., None]
    return np.einsum("ijk,...ilk->...ilj", R_LEG, dlocal)


def carriage_gradients(machine: MachineParams, rho: np.ndarray, weights: np.ndarray,
                       legs: np.ndarray | None = None) -> np.ndarray:
    """``weights . dA/dtheta`` for the R1 centre ``A`` of leg ``legs`` at commands ``rho``
    (``(*batch, *postures, 3)``) over the errors that move it, at fixed commands:
    ``weights`` ``(..., K, 3)`` and ``legs`` ``(..., K)`` broadcast against the batch and
    postures (``None``: the three legs in order; ``rho`` ``(..., R, 3)`` with ``legs``
    ``(R, 1)``: one leg per posture), giving ``(..., K, 5)``, the columns
    ``CARRIAGE_COLUMNS[legs]`` of the 27 (the others are zero).

    ``A_i = o_i + (L + r + drho_i + rho_i) u_i``: each column in closed form."""
    parts = carriage_parts(machine, rho, weights, legs)
    lead = np.broadcast_shapes(*(part.shape[:-1] for part in parts))
    return np.concatenate([np.broadcast_to(part, (*lead, part.shape[-1])) for part in parts],
                          axis=-1)


def carriage_parts(machine: MachineParams, rho: np.ndarray, weights: np.ndarray,
                   legs: np.ndarray | None, kinds: tuple[bool, bool, bool] = (True, True, True)
                   ) -> list[np.ndarray | None]:
    """:func:`carriage_gradients`' columns by kind, each broadcasting to its shape: the
    encoder offset's (..., K, 1), the two tilts' (..., K, 2) and the two offsets'; None for
    a kind not in ``kinds`` (a fit that leaves the axes' tilts and offsets fixed needs only
    the encoder offsets', and the tilts' cost the most)."""
    g, rho = geometry(machine, rho)
    weights = np.asarray(weights, dtype=float)
    extra = rho.ndim - 1 - len(machine.batch_shape)
    s = _slide(machine) + g.drho + rho
    u = g.u
    du = axis_direction_derivatives(machine).reshape(
        *machine.batch_shape, *(1,) * extra, 3, 2, 3) if kinds[1] else None
    if legs is None:
        across = np.swapaxes(R_LEG[..., 1:], -1, -2)
    else:
        legs = np.broadcast_to(legs, np.broadcast_shapes(weights.shape[:-1], np.shape(legs)))
        s = np.take_along_axis(s, legs, axis=-1)
        u = np.take_along_axis(u, legs[..., None], axis=-2)
        if du is not None:
            du = np.take_along_axis(du, legs[..., None, None], axis=-3)
        across = np.swapaxes(R_LEG[legs][..., 1:], -1, -2)  # (..., K, 2, 3)
    return [dot(weights, u)[..., None] if kinds[0] else None,
            s[..., None] * dot(weights[..., None, :], du) if du is not None else None,
            dot(weights[..., None, :], across) if kinds[2] else None]


def tcp_sensitivity(machine: MachineParams, rho: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Derivative of the TCP over the machine's 27 errors at fixed commands ``rho``, the
    TCP being ``p = direct(machine, rho)``: shape ``(*batch, *postures, 3, 27)``.

    By the implicit function theorem on the loop closure ``f_i = |C_i - A_i|^2 - L_i^2 =
    0``: ``dp/dtheta = -(df/dp)^-1 df/dtheta`` with ``df/dp = 2 (C_i - A_i)`` and, at
    fixed ``p``, ``df/dtheta = 2 (C_i - A_i) . (dC_i - dA_i) - 2 L_i dL_i``, every column
    in closed form.  Each error is in one leg's loop (:data:`ERROR_LEGS`), so ``df/dtheta``
    has one entry per column and the solve is a column of the inverse times it."""
    inverse, row = tcp_sensitivity_factors(machine, rho, p)
    return np.take(inverse, ERROR_LEGS, axis=-1) * row[..., None, :]


def tcp_sensitivity_factors(machine: MachineParams, rho: np.ndarray, p: np.ndarray,
                            columns: np.ndarray | None = None
                            ) -> tuple[np.ndarray, np.ndarray]:
    """The factors of :func:`tcp_sensitivity`: ``(df/dp)^-1`` (``(..., 3, 3)``) and the
    entry of ``-df/dtheta`` of each error in its leg's row (``(..., 27)``); column ``e`` of
    the sensitivity is column ``ERROR_LEGS[e]`` of the first times entry ``e`` of the
    second.  Products with the sensitivity can use them without its 27 columns of 3.
    ``columns``: the errors wanted (default all): the axes' tilts and offsets are computed
    only where one of theirs is (a fit of the encoder offsets and lengths needs neither,
    and the tilts cost the most), and left at zero where not; every entry computed has
    the bits it has among all 27."""
    rho = np.asarray(rho, dtype=float)
    p = np.asarray(p, dtype=float)
    v = leg_vectors(machine, rho, p)  # (..., 3 legs, 3)
    g, _ = geometry(machine, p)
    legs = np.arange(3)
    kinds = (True, True, True) if columns is None else tuple(
        bool(np.isin(CARRIAGE_COLUMNS[:, part], columns).any())
        for part in (slice(0, 1), slice(1, 3), slice(3, 5)))
    row = (np.empty if all(kinds) else np.zeros)((*v.shape[:-2], 27))
    # CARRIAGE_COLUMNS' entries (:func:`carriage_gradients`) by kind, written as slices:
    # the encoder offsets', then each leg's two tilts and two offsets in turn (joining
    # them and a fancy-indexed write cost as much as computing them).
    offset, tilts, shifts = carriage_parts(machine, rho, v, None, kinds)  # (..., 3 legs, 1|2)
    shape = row.shape[:-1]
    if offset is not None:
        row[..., DRHO_COLUMN:DRHO_COLUMN + 3] = 2 * offset[..., 0]
    if tilts is not None:
        row[..., TILT_COLUMN:TILT_COLUMN + 6] = (2 * tilts).reshape(*shape, 6)
    if shifts is not None:
        row[..., OFFSET_COLUMN:OFFSET_COLUMN + 6] = np.broadcast_to(
            2 * shifts, (*shape, 3, 2)).reshape(*shape, 6)
    row[..., LENGTH_COLUMN + legs] = 2 * g.lengths
    row[..., ATTACH_COLUMN + 3 * legs[:, None] + legs] = -2 * v
    return inverse_3x3(2 * v), row


def sensitivity_along(inverse: np.ndarray, row: np.ndarray, weights: np.ndarray,
                      columns: np.ndarray | None = None) -> np.ndarray:
    """``weights . dp/dtheta`` (``(..., 27)``) from the :func:`tcp_sensitivity_factors`
    ``inverse`` and ``row`` and the ``weights`` (``(..., 3)``) of the TCP's coordinates:
    the weights go through the 3 x 3 inverse first, so the 27 columns are formed once,
    not three times.  ``columns``: only these of the 27 (``row`` holding their entries
    alone), each with the bits it has among all 27."""
    through = (weights[..., 0, None] * inverse[..., 0, :] + weights[..., 1, None]
               * inverse[..., 1, :] + weights[..., 2, None] * inverse[..., 2, :])
    legs = ERROR_LEGS if columns is None else ERROR_LEGS[columns]
    return np.take(through, legs, axis=-1) * row


def inverse_3x3(m: np.ndarray) -> np.ndarray:
    """Inverses of 3 x 3 matrices ``(..., 3, 3)`` by their adjugates: the columns are the
    cross products of the rows over the determinant (a batched LAPACK solve costs ~3x more
    on tens of thousands of small systems)."""
    r0, r1, r2 = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    adjugate = np.stack([cross(r1, r2), cross(r2, r0), cross(r0, r1)], axis=-1)
    return adjugate / dot(r0, adjugate[..., :, 0])[..., None, None]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis (of length 3), written out: numpy's reduction over a
    short last axis costs ~5x more, and this sums in the same order (the same bits)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross costs ~10x more on small arrays)."""
    a, b = np.broadcast_arrays(a, b)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def skew(x: np.ndarray) -> np.ndarray:
    """Matrices ``[x]x`` (``(..., 3, 3)``) with ``[x]x y = x cross y``."""
    x = np.asarray(x, dtype=float)
    out = np.zeros((*x.shape, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -x[..., 2], x[..., 1], -x[..., 0]
    return out - np.swapaxes(out, -1, -2)


def leg_vectors(machine: MachineParams, rho: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Vectors A_i -> C_i (carriage to platform) in world, shape ``(..., 3, 3)``."""
    return platform_points(machine, p) - carriage_points(machine, rho)


def leg_angles(machine: MachineParams, rho: np.ndarray, p: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Passive joint angles ``(theta, beta)`` of each leg, shapes ``(..., 3)``.

    ``theta`` turns R1 about the leg's local Z; ``beta`` turns the parallelogram bars about
    their hinge axis (local Y after R1).  With both zero the bars point along local -X,
    from the carriage toward the platform:
    ``v = -|v| (cos theta cos beta, sin theta cos beta, -sin beta)`` in the leg frame.
    The coupler turns by ``-beta`` and R2 by ``-theta`` because the platform only translates.
    """
    v = np.einsum("lji,...lj->...li", R_LEG, leg_vectors(machine, rho, p))
    theta = np.arctan2(-v[..., 1], -v[..., 0])
    beta = np.arcsin(np.clip(v[..., 2] / np.linalg.norm(v, axis=-1), -1.0, 1.0))
    return theta, beta


def check_reachable(machine: MachineParams, p: np.ndarray) -> np.ndarray:
    """Inverse kinematics that also enforces the control limits; returns ``rho``."""
    rho = inverse(machine, p)
    design = machine.design
    bad = ~within_limits(rho, design)
    if np.any(bad):
        raise UnreachableError(f"TCP needs joint coordinate {rho[bad].flat[0]:.3f} mm, outside "
                               f"the control limits [{design.rho_min:g}, {design.rho_max:g}] mm")
    return rho


# --- the paper's test postures -----------------------------------------------------------
PAPER_POSTURES: tuple[str, ...] = ("Zero", "XMax", "XMin", "YMax", "YMin", "ZMax", "ZMin")


def paper_posture(name: str, design: MachineDesign) -> np.ndarray:
    """Control coordinates of a paper posture, computed on ``design``'s nominal model (as
    the controller does: it only knows the nominal geometry).

    ``XMax``: the TCP on the x axis with ``rho_x = rho_max`` (:func:`axis_postures`);
    likewise ``Min`` with ``rho_min`` and the Y, Z postures by permutation.
    """
    if name == "Zero":
        return np.zeros(3)
    if name not in PAPER_POSTURES:
        raise ValueError(f"unknown posture '{name}'; choose from {list(PAPER_POSTURES)}")
    limit = design.rho_max if name.endswith("Max") else design.rho_min
    return axis_postures("XYZ".index(name[0]), np.array([limit]), design)[0]


def axis_postures(leg: int, along: np.ndarray, design: MachineDesign) -> np.ndarray:
    """Control coordinates (N, 3) that put the nominal TCP on the axis of ``leg`` with that
    leg's coordinate at each of ``along`` (N,), mm: ``rho_leg = L sin a`` and the other two
    ``L cos a - L`` (the TCP at ``(L sin a, 0, 0)`` for the x leg), the family of the
    paper's Max and Min postures."""
    alpha = np.arcsin(np.asarray(along, dtype=float) / design.L)
    rho = np.repeat((design.L * np.cos(alpha) - design.L)[:, None], 3, axis=1)
    rho[:, leg] = design.L * np.sin(alpha)
    return rho


def _slide(machine: MachineParams) -> float:
    """Distance ``L + r`` from an actuator axis's origin to its R1 centre at Zero."""
    return machine.design.L + machine.design.r


def _require(condition: np.ndarray, message: str) -> None:
    if not np.all(condition):
        raise UnreachableError(message)
