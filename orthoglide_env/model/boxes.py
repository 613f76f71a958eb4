"""The moving parts as boxes: the bars, couplers, platform and carriages at a posture
(the simulator's links, :data:`BOX_NAMES`), which the gauges' rays and the collision
check (:mod:`orthoglide_env.model.collisions`) both use.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import LEG_NAMES, R_LEG, MachineParams
from orthoglide_env.model.kinematics import (
    carriage_points,
    cross,
    divided,
    dot,
    leg_angles,
    platform_points,
    scaled,
)

#: Names of the moving boxes (the simulator's link names): the bars, the couplers, the
#: platform and the carriages.
BOX_NAMES: tuple[str, ...] = (*(f"{leg}_{bar}" for leg in LEG_NAMES for bar in ("bar1", "bar2")),
                              *(f"{leg}_coupler" for leg in LEG_NAMES), "platform",
                              *(f"{leg}_carriage" for leg in LEG_NAMES))
PLATFORM_BOX: int = BOX_NAMES.index("platform")
#: Index of the x leg's carriage; the y and z legs' follow.
CARRIAGE_BOX: int = BOX_NAMES.index("x_carriage")
#: The leg of each bar box, and the side of the leg's parallelogram it is on (made once:
#: making them took about 14 µs a call, 4 % of the boxes of a lab's batch of 25).
_BAR_LEGS: np.ndarray = np.repeat(np.arange(3), 2)
_BAR_SIDES: np.ndarray = np.tile([1, -1], 3)
_IDENTITY: np.ndarray = np.eye(3)


def collision_boxes(machine: MachineParams, rho: np.ndarray, p: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every moving box, in the order of :data:`BOX_NAMES`: centres ``(..., 13, 3)``,
    rotations ``(..., 13, 3, 3)``, half extents ``(..., 13, 3)``."""
    legs, bars = _BAR_LEGS, _BAR_SIDES
    a = carriage_points(machine, rho)
    c = platform_points(machine, p)
    design = machine.design
    centre, rot, half = bar_boxes(a[..., legs, :], c[..., legs, :], legs, bars, design)
    theta, _ = leg_angles(machine, rho, p)
    cos, sin = np.cos(theta), np.sin(theta)
    zeros, ones = np.zeros_like(theta), np.ones_like(theta)
    rz = np.stack([np.stack([cos, -sin, zeros], -1), np.stack([sin, cos, zeros], -1),
                   np.stack([zeros, zeros, ones], -1)], -2)
    coupler_rot = R_LEG @ rz
    shape = (*np.shape(theta)[:-1], 3, 3)
    platform = platform_box(np.asarray(p)[..., None, :], design)
    carriages = carriage_boxes(a, np.arange(3), design)
    centres = np.concatenate([centre, c, platform[0], carriages[0]], axis=-2)
    rots = np.concatenate([rot, coupler_rot, platform[1], carriages[1]], axis=-3)
    halves = np.concatenate([
        half, np.broadcast_to(np.array(design.short_link_size) / 2, shape), platform[2],
        carriages[2],
    ], axis=-2)
    return centres, rots, halves


def bar_boxes(a: np.ndarray, c: np.ndarray, legs: np.ndarray, bars: np.ndarray,
              design: MachineDesign) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bar boxes from the joint centres ``a`` (carriage) and ``c`` (platform) of their legs,
    shaped as ``design`` says."""
    r_axis = R_LEG[legs][..., :, 2]
    v = c - a
    length = np.sqrt(dot(v, v))
    along = divided(v, length)
    hinge = cross(r_axis, along)
    hinge = divided(hinge, np.sqrt(dot(hinge, hinge)))
    normal = cross(along, hinge)
    rot = np.stack([along, hinge, normal], axis=-1)
    half = np.stack([length / 2 - design.bar_clearance,
                     *(np.full_like(length, s / 2) for s in design.bar_section)], axis=-1)
    centre = (a + c) / 2 + (bars * design.d / 2)[..., None] * r_axis
    return centre, rot, half


def carriage_boxes(a: np.ndarray, legs: np.ndarray, design: MachineDesign
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Carriage boxes of ``legs`` from their R1 centres ``a`` (``(..., n, 3)``): a carriage
    keeps its nominal orientation and starts the design's ``carriage_setback`` behind R1
    (away from the platform)."""
    rot = R_LEG[legs]
    centre = a + (design.carriage_setback + design.carriage_size[0] / 2) * rot[..., 0]
    lead = centre.shape[:-1]
    return (centre, np.broadcast_to(rot, (*lead, 3, 3)),
            np.broadcast_to(np.array(design.carriage_size) / 2, (*lead, 3)))


def platform_box(p: np.ndarray, design: MachineDesign
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The platform's box with the TCP at ``p`` (``(..., 3)``): it only translates."""
    lead = np.shape(p)[:-1]
    return (np.asarray(p), np.broadcast_to(_IDENTITY, (*lead, 3, 3)),
            np.broadcast_to(np.full(3, design.platform_size / 2), (*lead, 3)))


def to_box_frame(rot: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``rot^T @ vector`` over the last axes, broadcast: a world vector in a box's frame.

    Written out: on broadcast batches (rays against every box of thousands of machines)
    this is several times faster than ``einsum``, and every element is summed in the same
    order whatever the batch."""
    rot, vector = np.asarray(rot), np.asarray(vector)
    return (rot[..., 0, :] * vector[..., 0, None] + rot[..., 1, :] * vector[..., 1, None]
            + rot[..., 2, :] * vector[..., 2, None])


def bar_normal_pullback(weights: np.ndarray, a: np.ndarray, c: np.ndarray, legs: np.ndarray,
                        face: np.ndarray) -> np.ndarray:
    """``weights . dn/dv``: the derivative of a bar box's face normal ``n`` (face 1: the
    hinge axis, 2: the normal of :func:`bar_boxes`) over ``v = c - a``, pulled back along
    ``weights`` (``(..., 3)``), without forming the 3 x 3 derivatives.  With ``u = v / |v|``,
    ``h = w / |w|``, ``w = r x u`` and ``m = u x h``: ``du = (I - u u^T) dv / |v|``, ``dh =
    (I - h h^T) [r]x du / |w|``, ``dm = -[h]x du + [u]x dh``, and ``z^T [x]x = (z x x)^T``."""
    r_axis = R_LEG[legs][..., :, 2]
    v = c - a
    length = np.sqrt(dot(v, v))
    along = divided(v, length)
    w = cross(r_axis, along)
    size = np.sqrt(dot(w, w))
    hinge = divided(w, size)

    def through_along(z: np.ndarray) -> np.ndarray:
        return divided(z - scaled(along, dot(z, along)), length)

    def through_hinge(z: np.ndarray) -> np.ndarray:
        return divided(through_along(cross(z - scaled(hinge, dot(z, hinge)), r_axis)), size)

    normal = through_hinge(cross(weights, along)) - through_along(cross(weights, hinge))
    return np.where((np.asarray(face) == 1)[..., None], through_hinge(weights), normal)
