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
    return np.stack(_paper_tcp(_coordinates(rho), _coordinates(drho), _coordinates(lengths),
                               nominal), axis=-1)


def _coordinates(x: np.ndarray | float) -> list[np.ndarray]:
    """The three coordinates of ``x`` (``(..., 3)``, or a scalar for all three)."""
    x = np.asarray(x, dtype=float)
    return [x] * 3 if x.ndim == 0 else [x[..., i] for i in range(3)]


def _paper_tcp(rho: list[np.ndarray], drho: list[np.ndarray], lengths: list[np.ndarray],
               nominal: float) -> list[np.ndarray]:
    """:func:`direct_paper` coordinate by coordinate (the arithmetic of its vector form, in
    the same order: the same bits), each coordinate of the TCP an array over the
    broadcast shape of the inputs' coordinates."""
    q = [nominal + rho[i] + drho[i] for i in range(3)]
    for x in q:
        _require(np.abs(x) > 1e-9, "an actuator carriage sits at the axis intersection")
    # The vector form squares arrays of coordinates (``x**2`` of an array is ``x * x``)
    # even for one machine at one posture, whose coordinates here are lone numbers (whose
    # ``x**2`` calls pow): products keep its bits.  ``qb`` is a lone number there too.
    a = [(q[i] * q[i] - lengths[i] * lengths[i]) / (2 * q[i]) for i in range(3)]
    b = [1.0 / q[i] for i in range(3)]
    qa = b[0] * b[0] + b[1] * b[1] + b[2] * b[2]
    qb = 2 * (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) - 2.0
    qc = a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
    disc = qb**2 - 4 * qa * qc
    _require(disc >= 0, "the legs cannot be assembled at these joint coordinates")
    t = 2 * qc / (-qb + np.sqrt(disc))
    return [a[i] + t * b[i] for i in range(3)]


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
    return g.o + scaled(g.u, s)


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
    drho = _coordinates(g.drho)
    p = _paper_tcp(_coordinates(rho), drho, _coordinates(g.lengths), machine.design.L)
    if machine.is_paper_model:
        return np.stack(p, axis=-1)
    shape = np.broadcast_shapes(*(x.shape for x in p))
    slide = [_slide(machine) + drho[i] + rho[..., i] for i in range(3)]
    if np.prod(shape) == 1:
        # One posture (a single env's step): Python floats, whose arithmetic costs a
        # fraction of one-element arrays', in the same IEEE operations (the same bits).
        one = _newton_one(
            [x.item() for x in p], [[g.attach[..., i, j].item() for j in range(3)]
                                    for i in range(3)],
            [[(g.o[..., i, j] + slide[i] * g.u[..., i, j]).item() for j in range(3)]
             for i in range(3)],
            [x.item() for x in _coordinates(g.lengths**2)], tol, max_iter)
        return np.array(one).reshape((*shape, 3))
    # Every coordinate of every leg as one contiguous array over the whole batch, flat:
    # numpy then runs each operation below as one long loop, with the same arithmetic in
    # the same order as the vector form.

    def flat(x: np.ndarray) -> np.ndarray:
        return broadcast_copy(x, shape).reshape(-1)

    carriage = [[flat(g.o[..., i, j] + slide[i] * g.u[..., i, j]) for j in range(3)]
                for i in range(3)]
    attach = [[flat(g.attach[..., i, j]) for j in range(3)] for i in range(3)]
    lengths2 = [flat(x) for x in _coordinates(g.lengths**2)]
    q = [flat(x) for x in p]  # new arrays, iterated in place
    # Newton in cache-sized runs of postures: each posture's iterates are its own, so the
    # runs give the bits of one pass over all.
    for start in range(0, len(q[0]), NEWTON_RUN):
        run = slice(start, start + NEWTON_RUN)
        _newton([x[run] for x in q], [[x[run] for x in line] for line in attach],
                [[x[run] for x in line] for line in carriage], [x[run] for x in lengths2],
                tol, max_iter)
    return np.stack([x.reshape(shape) for x in q], axis=-1)


def broadcast_copy(x: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A new contiguous float array of ``shape`` holding ``x`` broadcast to it: the values
    of ``np.ascontiguousarray(np.broadcast_to(x, shape))`` without ``broadcast_to``'s
    Python-level checks, which cost more than the copy on a lab's small batches (a step
    makes a few dozen of these)."""
    out = np.empty(shape)
    out[...] = x
    return out


#: Postures per run of :func:`direct`'s Newton iterations: their two dozen working arrays
#: stay in a core's cache (2 MB on the reference machine) while the run iterates.
NEWTON_RUN: int = 4096


def _newton(q: list[np.ndarray], attach: list[list[np.ndarray]],
            carriage: list[list[np.ndarray]], lengths2: list[np.ndarray], tol: float,
            max_iter: int) -> None:
    """Newton's iterations on the loop closures ``|q + attach_i - carriage_i|^2 =
    lengths2_i`` from the TCPs ``q`` (three flat coordinate arrays, updated in place)."""
    moving = np.ones(q[0].shape, dtype=bool)
    v = [[np.empty_like(x) for x in q] for _ in range(3)]
    f = [np.empty_like(x) for x in q]
    cross_rows = [[np.empty_like(x) for x in q] for _ in range(3)]
    step = [np.empty_like(x) for x in q]
    det, part, other = (np.empty_like(q[0]) for _ in range(3))
    big = np.empty_like(moving)
    for _ in range(max_iter):
        for i in range(3):
            for j in range(3):
                np.add(q[j], attach[i][j], out=v[i][j])
                v[i][j] -= carriage[i][j]
            _dot_into(v[i], v[i], f[i], part)
            f[i] -= lengths2[i]
        # Newton's step solves (2 v) step = f by Cramer's rule, the cross products of the
        # rows over the determinant: ~5x faster than batched LAPACK solves of tens of
        # thousands of 3 x 3 systems, and these are well conditioned (legs far from
        # parallel).  The rows' factor 2 is a power of two, exact in every product: the
        # step is (f . cross products) / (2 det) of the rows v, the bits of the rows 2 v.
        for k, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
            for j, (x, y) in enumerate(((1, 2), (2, 0), (0, 1))):
                np.multiply(v[a][x], v[b][y], out=cross_rows[k][j])
                np.multiply(v[a][y], v[b][x], out=part)
                cross_rows[k][j] -= part
        _dot_into(v[0], cross_rows[0], det, part)
        det *= 2
        for j in range(3):
            _dot_into(f, [cross_rows[k][j] for k in range(3)], step[j], part)
            step[j] /= det
        # A converged posture stops moving, so its result does not depend on the batch
        # it was solved in (one machine or many give the same bits).
        for j in range(3):
            np.subtract(q[j], step[j], out=q[j], where=moving)
        np.abs(step[0], out=part)
        np.maximum(part, np.abs(step[1], out=other), out=part)
        np.maximum(part, np.abs(step[2], out=other), out=part)
        moving &= np.greater_equal(part, tol, out=big)
        if not moving.any():
            return
    raise UnreachableError("direct kinematics did not converge: posture near a singularity")


def _newton_one(q: list[float], attach: list[list[float]], carriage: list[list[float]],
                lengths2: list[float], tol: float, max_iter: int) -> list[float]:
    """:func:`_newton` for one posture, on Python floats: each operation of the arrays'
    form in the same order, so the TCP has the bits a batch would give it."""
    for _ in range(max_iter):
        v = [[(q[j] + attach[i][j]) - carriage[i][j] for j in range(3)] for i in range(3)]
        f = [v[i][0] * v[i][0] + v[i][1] * v[i][1] + v[i][2] * v[i][2] - lengths2[i]
             for i in range(3)]
        rows = [_cross_rows(v[1], v[2]), _cross_rows(v[2], v[0]), _cross_rows(v[0], v[1])]
        det = (v[0][0] * rows[0][0] + v[0][1] * rows[0][1] + v[0][2] * rows[0][2]) * 2
        step = [(f[0] * rows[0][j] + f[1] * rows[1][j] + f[2] * rows[2][j]) / det
                for j in range(3)]
        q = [q[j] - step[j] for j in range(3)]
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < tol:
            return q
    raise UnreachableError("direct kinematics did not converge: posture near a singularity")


def _dot_into(a: list[np.ndarray], b: list[np.ndarray], out: np.ndarray, part: np.ndarray
              ) -> None:
    """``a . b`` of vectors given as their three coordinate arrays into ``out`` (``part``:
    scratch of its shape), summed in :func:`dot`'s order."""
    np.multiply(a[0], b[0], out=out)
    out += np.multiply(a[1], b[1], out=part)
    out += np.multiply(a[2], b[2], out=part)


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


def carriage_parts(machine: MachineParams, rho: np.ndarray, weights: np.ndarray,
                   legs: np.ndarray | None, kinds: tuple[bool, bool, bool] = (True, True, True)
                   ) -> list[np.ndarray | None]:
    """``weights . dA/dtheta`` for the R1 centre ``A`` of leg ``legs`` at commands ``rho``
    (``(*batch, *postures, 3)``) over the errors that move it, at fixed commands, by kind
    (``A_i = o_i + (L + r + drho_i + rho_i) u_i``, each in closed form): ``weights``
    ``(..., K, 3)`` and ``legs`` ``(..., K)`` broadcast against the batch and postures
    (``None``: the three legs in order), giving the columns ``CARRIAGE_COLUMNS[legs]`` of
    the 27 (the others are zero), each broadcasting to its shape: the encoder offset's
    (..., K, 1), the two tilts' (..., K, 2) and the two offsets'; None for
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
    the bits it has among all 27.  :func:`sensitivity_parts` gives them coordinate by
    coordinate."""
    kinds = (True, True, True) if columns is None else tuple(
        bool(np.isin(CARRIAGE_COLUMNS[:, part], columns).any())
        for part in (slice(0, 1), slice(1, 3), slice(3, 5)))
    parts = sensitivity_parts(machine, rho, p, kinds)  # type: ignore[arg-type]
    inverse = np.stack([np.stack(line, axis=-1) for line in parts.inverse], axis=-2)
    row = (np.empty if all(kinds) else np.zeros)((*inverse.shape[:-2], 27))
    for e, entry in enumerate(parts.entries):
        if entry is not None:
            row[..., e] = entry
    return inverse, row


class SensitivityParts(NamedTuple):
    """:func:`tcp_sensitivity_factors`' factors coordinate by coordinate, each a contiguous
    array over the batch and the postures (or broadcasting to it)."""

    #: ``[j][k]``: entry ``(j, k)`` of ``(df/dp)^-1``.
    inverse: list[list[np.ndarray]]
    #: Entry ``e`` of ``-df/dtheta`` for each of the 27 errors; None where not computed
    #: (zero in the factors).
    entries: list[np.ndarray | None]


def sensitivity_parts(machine: MachineParams, rho: np.ndarray, p: np.ndarray,
                      kinds: tuple[bool, bool, bool] = (True, True, True)
                      ) -> SensitivityParts:
    """:func:`tcp_sensitivity_factors` at commands ``rho`` and TCPs ``p``
    (``(*batch, *postures, 3)``) as one array per coordinate: the arithmetic of the
    vector form, each entry the same operations in the same order (the same bits),
    without its strided ``(..., 3, 3)`` temporaries (a scoring grid's tens of thousands
    of postures run at about twice the speed).  ``kinds``: the carriages' encoder offsets',
    axis tilts' and axis offsets' entries, each computed only when wanted."""
    g, rho = geometry(machine, rho)
    at_p, p = geometry(machine, p)
    s = _slide(machine) + g.drho + rho
    slide = [s[..., i] for i in range(3)]
    u = [[g.u[..., i, j] for j in range(3)] for i in range(3)]
    # The leg vectors A_i -> C_i: ``(p + attach) - (o + s u)``.
    v = [[(p[..., j] + at_p.attach[..., i, j]) - (g.o[..., i, j] + slide[i] * u[i][j])
          for j in range(3)] for i in range(3)]
    # (df/dp)^-1 of the rows 2 v by its adjugate, whose columns are the rows' cross products.
    r = [[2 * x for x in line] for line in v]
    adjugate = [_cross_rows(r[1], r[2]), _cross_rows(r[2], r[0]), _cross_rows(r[0], r[1])]
    det = r[0][0] * adjugate[0][0] + r[0][1] * adjugate[0][1] + r[0][2] * adjugate[0][2]
    inverse = [[adjugate[k][j] / det for k in range(3)] for j in range(3)]
    entries: list[np.ndarray | None] = [None] * 27
    for i in range(3):
        entries[LENGTH_COLUMN + i] = 2 * at_p.lengths[..., i]
        for j in range(3):
            entries[ATTACH_COLUMN + 3 * i + j] = -2 * v[i][j]
        if kinds[0]:
            entries[DRHO_COLUMN + i] = 2 * _dot_rows(v[i], u[i])
    if kinds[1]:
        extra = rho.ndim - 1 - len(machine.batch_shape)
        du = axis_direction_derivatives(machine).reshape(
            *machine.batch_shape, *(1,) * extra, 3, 2, 3)
        for i in range(3):
            for k in range(2):
                entries[TILT_COLUMN + 2 * i + k] = 2 * (slide[i] * _dot_rows(
                    v[i], [du[..., i, k, j] for j in range(3)]))
    if kinds[2]:
        for i in range(3):
            for k in range(2):
                entries[OFFSET_COLUMN + 2 * i + k] = 2 * _dot_rows(
                    v[i], [R_LEG[i, j, k + 1] for j in range(3)])
    return SensitivityParts(inverse, entries)


def _dot_rows(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """:func:`dot` of vectors given as their three coordinate arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def sensitivity_along(inverse: np.ndarray, row: np.ndarray, weights: np.ndarray,
                      columns: np.ndarray | None = None) -> np.ndarray:
    """``weights . dp/dtheta`` (``(..., 27)``) from the :func:`tcp_sensitivity_factors`
    ``inverse`` and ``row`` and the ``weights`` (``(..., 3)``) of the TCP's coordinates:
    the weights go through the 3 x 3 inverse first, so the 27 columns are formed once,
    not three times.  ``columns``: only these of the 27 (``row`` holding their entries
    alone), each with the bits it has among all 27."""
    # Column by column of the inverse: the products of (..., 1) and (..., 3) operands went
    # through numpy's buffers three numbers at a time (the same products and sums, in the
    # same order; ~4x less time).
    through = np.empty(np.broadcast_shapes(weights.shape, inverse.shape[:-1]))
    w = [weights[..., k] for k in range(3)]
    for j in range(3):
        np.add(w[0] * inverse[..., 0, j] + w[1] * inverse[..., 1, j],
               w[2] * inverse[..., 2, j], out=through[..., j])
    legs = ERROR_LEGS if columns is None else ERROR_LEGS[columns]
    return np.take(through, legs, axis=-1) * row


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis (of length 3), written out: numpy's reduction over a
    short last axis costs ~5x more, and this sums in the same order (the same bits)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def scaled(vectors: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """``factors[..., None] * vectors`` (``(...)`` and ``(..., 3)``, broadcast) coordinate
    by coordinate: numpy runs the product of (..., 1) and (..., 3) operands through its
    buffers three numbers at a time, and each coordinate's is one long loop (the same
    products, ~2x less time)."""
    return _coordinatewise(np.multiply, vectors, factors)


def divided(vectors: np.ndarray, divisors: np.ndarray) -> np.ndarray:
    """``vectors / divisors[..., None]`` coordinate by coordinate (see :func:`scaled`)."""
    return _coordinatewise(np.divide, vectors, divisors)


def _coordinatewise(op: np.ufunc, vectors: np.ndarray, scalars: np.ndarray) -> np.ndarray:
    """``op(vectors, scalars[..., None])`` in floating point, one coordinate at a time into
    a C-ordered array."""
    vectors, scalars = np.asarray(vectors, dtype=float), np.asarray(scalars, dtype=float)
    out = np.empty((*np.broadcast_shapes(vectors.shape[:-1], scalars.shape),
                    vectors.shape[-1]))
    for k in range(vectors.shape[-1]):
        op(vectors[..., k], scalars, out=out[..., k])
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross costs ~10x more on small arrays), each
    coordinate written into its place (no stacking of the three)."""
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape, dtype=np.result_type(a, b))
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        np.subtract(a[..., i] * b[..., j], a[..., j] * b[..., i], out=out[..., k])
    return out


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
