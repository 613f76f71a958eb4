"""Gauge rays against the machine's boxes: the slab test, the box and face each gauge is
aimed at, and the tip's distance along its ray, exactly (edges, occlusion and travel, as
the simulator sees it) or to the plane of its face (smooth, as an estimator models it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthoglide_env.instruments.gauges import Gauge, GaugeArray, as_gauge_array, spec_arrays
from orthoglide_env.instruments.slots import GaugeSpec, Part
from orthoglide_env.model.boxes import (
    BOX_NAMES,
    bar_boxes,
    carriage_boxes,
    collision_boxes,
    platform_box,
    to_box_frame,
)
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import (
    broadcast_copy,
    carriage_points,
    direct,
    dot,
    platform_points,
)

#: A reading is valid only where the contact ball (radius ~1.5 mm) sits wholly on the
#: flat face: closer to an edge a real tip rolls over it, and PyBullet's boxes are
#: rounded there by their collision margin (measured: exact again 1 mm from an edge).
TIP_EDGE_MARGIN: float = 1.5
#: The simulator casts rays from this far behind ``origin`` so that an overtravel is seen
#: as a hit at negative ``t`` rather than from inside the bar.
RAY_BACKOFF: float = 30.0


def ray_box_interval(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, rot: np.ndarray,
                     half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the line ``origin + t * direction`` enters and leaves a box (slab method);
    ``t_in > t_out`` when it misses.  Broadcast over leading dimensions."""
    origin, direction = np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)
    centre, rot, half = (np.asarray(a, dtype=float) for a in (centre, rot, half))
    shape = np.broadcast_shapes(origin.shape[:-1], direction.shape[:-1], centre.shape[:-1],
                                rot.shape[:-2], half.shape[:-1])
    # Coordinates first, each a contiguous array of the full shape: numpy then runs every
    # operation below as one long loop instead of one loop per three numbers (rays
    # against every box of thousands of machines is ~10x faster).  Same arithmetic, in
    # the same order, as to_box_frame.  The three slabs at once, row i of each array the
    # slab of box axis i: a third of the calls of a loop over them (a look of a lab's
    # batch is mostly calls on short arrays), each number computed as the loop did.
    v = _components(origin - centre, shape)
    d = _components(direction, shape)
    r = broadcast_copy(_leading(rot, 2), (3, 3, *shape))
    h = _components(half, shape)
    o = r[0] * v[0] + r[1] * v[1] + r[2] * v[2]
    d = r[0] * d[0] + r[1] * d[1] + r[2] * d[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-h - o) / d
        t2 = (h - o) / d
    # A ray parallel to a slab is inside it everywhere or nowhere.
    inside = np.abs(o) <= h
    parallel = d == 0
    lo = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    hi = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    t_in = np.maximum(np.maximum(lo[0], lo[1]), lo[2])
    t_out = np.minimum(np.minimum(hi[0], hi[1]), hi[2])
    return t_in, t_out


def _components(vector: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The three coordinates of ``vector`` (``(..., 3)``) as one contiguous array
    ``(3, *shape)``."""
    return broadcast_copy(_leading(vector, 1), (3, *shape))


def _leading(x: np.ndarray, tail: int) -> np.ndarray:
    """``x`` with its last ``tail`` axes moved to the front, as ``np.moveaxis`` moves them
    (a view), without its checks of the axes (a tenth of a single env's look)."""
    axes = range(x.ndim)
    return x.transpose(*axes[x.ndim - tail:], *axes[:x.ndim - tail])


def ray_box_distance(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, rot: np.ndarray,
                     half: np.ndarray) -> np.ndarray:
    """Distance along the ray at which it enters the box; NaN on a miss.

    The ray is the whole line ``origin + t * direction``: negative ``t`` is reported, so an
    overtravel (box between the tip and the stand) is seen.
    """
    t_in, t_out = ray_box_interval(origin, direction, centre, rot, half)
    return np.where(t_out >= t_in, t_in, np.nan)


def on_flat_face(point: np.ndarray, centre: np.ndarray, rot: np.ndarray, half: np.ndarray,
                 margin: float = TIP_EDGE_MARGIN, face: np.ndarray | int | None = None
                 ) -> np.ndarray:
    """Whether a contact point on a box's surface lies ``margin`` inside its face's edges,
    and, when ``face`` (box axis 0, 1 or 2) is given, on that face.

    A gauge reads only on the face it is aimed at: near a bar's end its ray can enter
    through the end face at grazing incidence, where a real tip slides off the edge (and
    PyBullet's rounded box edges disagree with the sharp box by ~1 mm)."""
    local = to_box_frame(rot, point - centre)
    ratio = np.abs(local) / half
    touched = np.argmax(ratio, axis=-1)
    inner = np.abs(local) <= half - margin
    ok = np.all(inner | (np.arange(3) == touched[..., None]), axis=-1)
    return ok if face is None else ok & (touched == face)


def target_boxes(machine: MachineParams, gauges: GaugeArray, rho: np.ndarray, p: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box each of ``gauges`` (one set, batch shape ``()``) touches, at control
    coordinates ``rho`` with the TCP at ``p``: centres ``(..., G, 3)``, rotations
    ``(..., G, 3, 3)``, half extents ``(..., G, 3)``.  What :func:`exact_target_boxes`
    picks out of :func:`collision_boxes`, made from the same pieces for these boxes only
    (an estimator's model evaluates it for thousands of parameter vectors)."""
    legs = np.maximum(gauges.leg, 0)
    return boxes_at(gauges, carriage_points(machine, rho)[..., legs, :],
                    platform_points(machine, p)[..., legs, :], np.asarray(p)[..., None, :],
                    machine.design)


def boxes_at(gauges: GaugeArray, a: np.ndarray, c: np.ndarray, p: np.ndarray,
             design: MachineDesign) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box each of ``gauges`` (``(G,)``) touches, from the R1 centre ``a`` and R2
    centre ``c`` of its leg (``(..., G, 3)``; a platform gauge has no leg, any leg's will
    do) and the TCP ``p`` (broadcasting to them), the links shaped as ``design`` says: see
    :func:`target_boxes`."""
    legs = np.maximum(gauges.leg, 0)
    bars = bar_boxes(a, c, legs, np.where(gauges.face == 1, 1, -1), design)
    part = gauges.part
    tails = (1, 2, 1)  # the trailing axes of a centre, a rotation and a half extent
    if (part == Part.BAR).all():
        # Every gauge on a bar (the paper's procedure, and every fit of it): the bars'
        # boxes as the selection below shapes them, without the carriages' and the
        # platform's that it would drop.
        lead = np.broadcast_shapes(np.shape(a), np.shape(c), np.shape(p))[:-1]
        return tuple(  # type: ignore[return-value]
            np.ascontiguousarray(np.broadcast_to(b, (*lead, *b.shape[b.ndim - tail:])))
            for b, tail in zip(bars, tails, strict=True))
    carriages = carriage_boxes(a, legs, design)
    platform = platform_box(np.broadcast_to(p, np.broadcast_shapes(np.shape(p), np.shape(a))),
                             design)
    return tuple(  # type: ignore[return-value]
        np.where((part == Part.BAR).reshape(-1, *(1,) * tail), b,
                 np.where((part == Part.CARRIAGE).reshape(-1, *(1,) * tail), c, f))
        for b, c, f, tail in zip(bars, carriages, platform, tails, strict=True))


def exact_target_boxes(gauges: GaugeArray | Sequence[Gauge],
                       boxes: tuple[np.ndarray, np.ndarray, np.ndarray]
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box of every gauge's target among the :func:`collision_boxes` ``boxes``:
    centres ``(..., G, 3)``, rotations ``(..., G, 3, 3)``, half extents ``(..., G, 3)``."""
    centre, rot, half = boxes
    target = as_gauge_array(gauges).for_postures(centre.ndim - 2).target
    return _pick(centre, target, 1), _pick(rot, target, 2), _pick(half, target, 1)


def _pick(values: np.ndarray, index: np.ndarray, tail: int) -> np.ndarray:
    """``values[..., index, :, ...]`` with a different ``index`` per leading element:
    ``values`` of shape ``(..., boxes, *tail)`` (``tail`` trailing axes) and ``index``
    ``(..., G)``, broadcast against the leading dimensions, give ``(..., G, *tail)``."""
    index = index.reshape(*index.shape, *(1,) * tail)
    return np.take_along_axis(values, index, axis=-1 - tail)


def exact_ray_distances(
    machine: MachineParams, gauges: GaugeArray | Sequence[Gauge], rho: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    targets: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Exact tip distances ``t`` of every gauge, shape ``(*batch, *postures, G)`` for
    ``rho`` of shape ``(*batch, *postures, 3)`` and gauges of batch shape ``batch`` (or one
    gauge set, shared by every machine).

    NaN when the ray misses the target's flat face, or when another part lies on the ray
    before the target within the window a gauge can see (``-RAY_BACKOFF`` to
    ``travel + RAY_BACKOFF``).  A target behind the tip (``t < 0``) is an overtravel
    whatever else is on the ray: it presses the gauge.  ``boxes``: the
    :func:`collision_boxes` at ``rho`` when already computed, ``targets`` their
    :func:`exact_target_boxes`.
    """
    rho = np.asarray(rho, dtype=float)
    centre, rot, half = boxes or collision_boxes(machine, rho, direct(machine, rho))
    g = as_gauge_array(gauges).for_postures(centre.ndim - 2)
    t_in, t_out = ray_box_interval(  # (..., gauges, boxes)
        g.origin[..., None, :], g.direction[..., None, :], centre[..., None, :, :],
        rot[..., None, :, :, :], half[..., None, :, :])
    target = g.target
    t_in_target = _pick(t_in, target[..., None], 0)[..., 0]
    t_out_target = _pick(t_out, target[..., None], 0)[..., 0]
    t = np.where(t_out_target >= t_in_target, t_in_target, np.nan)
    hit = g.origin + np.nan_to_num(t)[..., None] * g.direction
    if targets is None:
        targets = exact_target_boxes(g, (centre, rot, half))
    t = np.where(on_flat_face(hit, *targets, face=g.face), t, np.nan)
    others = np.arange(len(BOX_NAMES)) != target[..., None]
    reach = g.travel + RAY_BACKOFF
    in_window = (t_out >= -RAY_BACKOFF) & (t_in <= t_out) & (t_in < t[..., None])
    occluded = np.any(in_window & others, axis=-1) & (t >= 0)
    return np.where(occluded | (t > reach), np.nan, t)


def face_distances(machine: MachineParams, specs: tuple[GaugeSpec, ...] | list[GaugeSpec],
                   origins: np.ndarray, directions: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Distance along each ray to the plane of the face its gauge is aimed at, at every
    posture: shape ``(*batch, *postures, n)`` for ``rho`` of shape
    ``(*batch, *postures, 3)`` and rays ``(*batch, n, 3)``.

    This is the reading model of an estimator: the plane is smooth in every parameter
    (no edges, no occlusion, no travel), and on a valid reading it is exactly the
    simulator's ray distance (the tip sits on that face)."""
    rho = np.asarray(rho, dtype=float)
    g = spec_arrays(specs)
    centre, rot, half = target_boxes(machine, g, rho, direct(machine, rho))
    extra = centre.ndim - 2 - (np.ndim(origins) - 2)
    shape = (*np.shape(origins)[:-2], *(1,) * extra, len(specs), 3)
    o = np.reshape(origins, shape)
    d = np.reshape(np.broadcast_to(directions, np.broadcast_shapes(np.shape(directions),
                                                                  np.shape(origins))), shape)
    return plane_distances(centre, rot, half, g.face, o, d)


def plane_distances(centre: np.ndarray, rot: np.ndarray, half: np.ndarray, face: np.ndarray,
                    origins: np.ndarray, directions: np.ndarray,
                    normal: np.ndarray | None = None) -> np.ndarray:
    """Distance along each ray ``origins + t directions`` (``(..., G, 3)``) to the plane of
    face ``face`` (box axis, ``(G,)``) of its box (centres ``(..., G, 3)``, rotations
    ``(..., G, 3, 3)``, half extents ``(..., G, 3)``), on the side the ray comes from;
    ``normal``: the faces' :func:`face_normals`, when known."""
    if normal is None:
        normal = face_normals(rot, face)
    thickness = half[..., np.arange(len(face)), face]
    nd = dot(normal, directions)
    return (dot(normal, centre - origins) - thickness * np.sign(nd)) / nd


def face_normals(rot: np.ndarray, face: np.ndarray) -> np.ndarray:
    """The normal of face ``face`` (box axis, ``(G,)``) of each box (rotations
    ``(..., G, 3, 3)``): ``(..., G, 3)``."""
    return np.einsum("...gjk,gk->...gj", rot, np.eye(3)[face])
