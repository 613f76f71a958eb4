"""Collisions between moving parts, computed from the exact geometry.

The exact backend has no physics engine to ask for contacts, so it checks the same parts
the PyBullet machine checks (:func:`crash_pairs`) with the separating-axis test on
their boxes: two boxes are apart when one of fifteen axes (the three face normals of
each and the nine cross products of their edges) separates their projections.

The largest gap over those axes is a lower bound on the distance between the boxes (a
projection never lengthens a segment), so :func:`clearance` also measures how far a
posture is from a crash.  The base has no collision geometry in either backend: its
rails are drawn only (see ``urdf_writer._base``).
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.model.boxes import BOX_NAMES, collision_boxes, to_box_frame
from orthoglide_env.model.errors import LEG_NAMES, MachineParams
from orthoglide_env.model.kinematics import direct


def crash_pairs() -> list[tuple[str, str]]:
    """Pairs of parts (the simulator's link names) that touch only in a crash: parts of
    different legs (bars, couplers, carriages), and the platform with every bar and
    carriage.  Parts of one leg, and couplers with the platform, touch by design.  Both
    backends check exactly these."""
    legs = [[f"{leg}_{p}" for p in ("bar1", "bar2", "coupler", "carriage")] for leg in LEG_NAMES]
    pairs = [(a, b) for i in range(3) for j in range(i + 1, 3) for a in legs[i] for b in legs[j]]
    return pairs + [("platform", f"{leg}_{p}") for leg in LEG_NAMES
                    for p in ("bar1", "bar2", "carriage")]


#: The crash pairs' boxes (indices in :data:`BOX_NAMES`) and names (``"a/b"``).
PAIR_FIRST, PAIR_SECOND = (np.array([BOX_NAMES.index(pair[k]) for pair in crash_pairs()])
                           for k in (0, 1))
PAIR_NAMES: tuple[str, ...] = tuple(f"{a}/{b}" for a, b in crash_pairs())


#: Cyclic successors of a box axis: with right-handed axes, axis ``i`` crossed with axis
#: ``NEXT[i]`` is axis ``AFTER[i]``.
NEXT, AFTER = np.array([1, 2, 0]), np.array([2, 0, 1])


def box_gap(centre_a: np.ndarray, rot_a: np.ndarray, half_a: np.ndarray, centre_b: np.ndarray,
            rot_b: np.ndarray, half_b: np.ndarray) -> np.ndarray:
    """Largest separating-axis gap (mm) between boxes A and B, broadcast over leading
    dimensions: positive means apart by at least that much, zero or less means touching
    or overlapping.  Rotation columns are the box axes in world.

    The fifteen axes are taken in A's frame (Gottschalk's OBB test), where each gap is a
    few products of ``R = A^T B`` and of the centre offset: one 3x3 product per pair
    instead of fifteen projections, which is what makes the test cheap on thousands of
    machines at once.  Every step is elementwise, so a pair's gap does not depend on the
    batch it is computed in."""
    rot_a, rot_b = np.asarray(rot_a), np.asarray(rot_b)
    half_a, half_b = np.asarray(half_a), np.asarray(half_b)
    offset = np.asarray(centre_b) - np.asarray(centre_a)
    # r[i, j] = A_i . B_j and t[i] = A_i . offset, written out (einsum and matmul sum
    # differently depending on the array layout).
    r = (rot_a[..., 0, :, None] * rot_b[..., 0, None, :]
         + rot_a[..., 1, :, None] * rot_b[..., 1, None, :]
         + rot_a[..., 2, :, None] * rot_b[..., 2, None, :])
    t = to_box_frame(rot_a, offset)
    size = np.abs(r)
    faces_a = np.abs(t) - half_a - np.sum(size * half_b[..., None, :], axis=-1)
    faces_b = (np.abs(np.sum(t[..., :, None] * r, axis=-2))
               - np.sum(size * half_a[..., :, None], axis=-2) - half_b)
    # Edge axis A_i x B_j = r[i+1, j] A_{i+2} - r[i+2, j] A_{i+1} (indices cyclic).
    r1, r2 = r[..., NEXT, :], r[..., AFTER, :]
    along = np.abs(r1 * t[..., AFTER, None] - r2 * t[..., NEXT, None])
    reach_a = half_a[..., NEXT, None] * np.abs(r2) + half_a[..., AFTER, None] * np.abs(r1)
    reach_b = (half_b[..., None, NEXT] * size[..., :, AFTER]
               + half_b[..., None, AFTER] * size[..., :, NEXT])
    norm = np.sqrt(r1**2 + r2**2)
    # Parallel edges give no axis of their own (a face normal already covers them).
    degenerate = norm < 1e-9
    edges = np.where(degenerate, -np.inf,
                     (along - reach_a - reach_b) / np.where(degenerate, 1.0, norm))
    return np.maximum(np.maximum(faces_a.max(axis=-1), faces_b.max(axis=-1)),
                      edges.reshape(*edges.shape[:-2], 9).max(axis=-1))


def pair_gaps(machine: MachineParams, rho: np.ndarray, boxes: tuple[np.ndarray, ...] | None = None
              ) -> np.ndarray:
    """Separating-axis gap (mm) of every pair of :data:`PAIR_NAMES`, shape ``(..., pairs)``."""
    rho = np.asarray(rho, dtype=float)
    centre, rot, half = boxes or collision_boxes(machine, rho, direct(machine, rho))
    first, second = PAIR_FIRST, PAIR_SECOND
    return box_gap(centre[..., first, :], rot[..., first, :, :], half[..., first, :],
                   centre[..., second, :], rot[..., second, :, :], half[..., second, :])


def clearance(machine: MachineParams, rho: np.ndarray, boxes: tuple[np.ndarray, ...] | None = None
              ) -> np.ndarray:
    """Smallest gap (mm) over the crash pairs at ``rho``, shape ``rho.shape[:-1]``: a lower
    bound on how far the nearest two parts that must never meet are apart."""
    return np.min(pair_gaps(machine, rho, boxes), axis=-1)


def collision_mask(machine: MachineParams, rho: np.ndarray,
                   boxes: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Which crash pairs of :data:`PAIR_NAMES` are in contact (``pair_gaps <= 0``), shape
    ``(..., pairs)``: per machine of a batch and per posture.

    Two boxes whose axis-aligned bounding boxes are apart cannot touch, so only the other
    pairs go through the separating-axis test: at the postures of a calibration that is
    none of them, which keeps the check cheap on thousands of machines."""
    rho = np.asarray(rho, dtype=float)
    centre, rot, half = boxes or collision_boxes(machine, rho, direct(machine, rho))
    size = np.abs(rot)
    # Half extents of the bounding boxes, and the test per world axis, written out: numpy
    # is slow on many short axes of three.
    reach = (size[..., 0] * half[..., None, 0] + size[..., 1] * half[..., None, 1]
             + size[..., 2] * half[..., None, 2])
    between = np.abs(centre[..., PAIR_FIRST, :] - centre[..., PAIR_SECOND, :]) - (
        reach[..., PAIR_FIRST, :] + reach[..., PAIR_SECOND, :])
    apart = (between[..., 0] > 0) | (between[..., 1] > 0) | (between[..., 2] > 0)
    mask = np.zeros(apart.shape, dtype=bool)
    near = np.nonzero(~apart)
    if len(near[-1]):
        first = (*near[:-1], PAIR_FIRST[near[-1]])
        second = (*near[:-1], PAIR_SECOND[near[-1]])
        mask[near] = box_gap(centre[first], rot[first], half[first],
                             centre[second], rot[second], half[second]) <= 0.0
    return mask


def collision_names(mask: np.ndarray) -> list[str]:
    """Names (``"a/b"``) of the pairs a :func:`collision_mask` of one posture marks."""
    return [name for name, hit in zip(PAIR_NAMES, mask, strict=True) if hit]


def collisions(machine: MachineParams, rho: np.ndarray, boxes: tuple[np.ndarray, ...] | None = None
               ) -> list[str]:
    """Names (``"a/b"``, as the simulator names them) of the crash pairs in contact at one
    posture ``rho`` (shape ``(3,)``) of one machine."""
    return collision_names(collision_mask(machine, rho, boxes))
