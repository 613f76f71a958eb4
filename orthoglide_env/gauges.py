"""Dial gauges: layout, installation, the exact reading model, noise and quantisation.

A gauge is a plunger on a magnetic stand fixed to the base.  Its ray starts at
``origin`` (the tip when the plunger is pushed fully in) and runs along ``direction``
(toward the target); the tip touches the first face of the target bar at distance
``t``.  The plunger can extend by ``travel`` mm, so the gauge is in contact when
``0 <= t <= travel``.  ``t > travel``: the tip hangs in the air (no contact); ``t < 0``:
the bar has pushed the plunger past its travel toward the stand (overtravel, which
would damage a real gauge).

Reading convention (DESIGN.md): the coordinate of the touched surface point along the
gauge's world measuring axis, relative to the gauge's zero, in mm::

    reading = sign * (t - zero),  sign = direction . e_axis  (+1 or -1 nominally)

so the difference of two readings is the surface's displacement along that axis.

Targets: a gauge measuring leg ``i`` along the leg's local Y touches the bar at
``+d/2`` along local Z, at that height; one measuring along local Z comes from below
and touches the bar at ``-d/2``.  Both are flat box faces, as DESIGN.md advises.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from .geometry import (
    AXIS_NAMES,
    BAR_CLEARANCE,
    BAR_SECTION,
    D_NOMINAL,
    LEG_NAMES,
    PLATFORM_SIZE,
    R_LEG,
    SHORT_LINK_SIZE,
    ErrorPreset,
    MachineParams,
)
from .kinematics import carriage_points, direct, leg_angles, platform_points

DEFAULT_TRAVEL: float = 10.0  # mm
DEFAULT_RESOLUTION: float = 0.01  # mm (paper, section 4)
DEFAULT_SIGMA: float = 0.02  # mm, repeatability (paper, section 4)
#: Readings of ideal (noise-free) gauges are weighted as if their repeatability were this
#: (mm): weights and identifiability thresholds need a finite sigma, and a finer one lets
#: the readings' own round-off (whitened) swamp the steps of an ill-conditioned fit.
NOISE_FLOOR: float = 1e-4
#: A reading is valid only where the contact ball (radius ~1.5 mm) sits wholly on the
#: flat face: closer to an edge a real tip rolls over it, and PyBullet's boxes are
#: rounded there by their collision margin (measured: exact again 1 mm from an edge).
TIP_EDGE_MARGIN: float = 1.5
#: The gauge body (radius, mm) and its stand behind the tip (length, mm): a bar that
#: reaches into them behind the tip presses the plunger past its travel, even when it is
#: off the flat face that gives a reading.
GAUGE_BODY_RADIUS: float = 6.0
STAND_LENGTH: float = 60.0
#: The simulator casts rays from this far behind ``origin`` so that an overtravel is seen
#: as a hit at negative ``t`` rather than from inside the bar.
RAY_BACKOFF: float = 30.0


class Status(IntEnum):
    """Why a reading is or is not valid."""

    VALID = 0
    NO_CONTACT = 1  # tip extended fully without touching
    OVERTRAVEL = 2  # plunger pushed in past its travel
    MISSED = 3  # tip off the bar's flat face, or the ray meets something else first


@dataclass(frozen=True)
class GaugeSpec:
    """Where a gauge goes, nominally: which leg, which world axis, where along the leg.

    ``at`` is the fraction of the leg from the platform end (0) to the carriage end (1) at
    the Zero posture; the paper's gauges sit in the middle (0.5).
    """

    leg: int
    axis: int
    at: float = 0.5

    def __post_init__(self) -> None:
        if self.leg not in (0, 1, 2) or self.axis not in (0, 1, 2):
            raise ValueError("gauge leg and axis must be 0, 1 or 2 (x, y, z)")
        if self.leg == self.axis:
            raise ValueError("a gauge measures a leg along one of the two axes normal to it")
        if not 0.05 <= self.at <= 0.95:
            raise ValueError("gauge position 'at' must lie in [0.05, 0.95] along the leg")

    @property
    def name(self) -> str:
        return f"{LEG_NAMES[self.leg]}-leg/{AXIS_NAMES[self.axis]}"

    @property
    def slot(self) -> str:
        """The name with the place along the leg, e.g. ``x-leg/y@0.5``: unique per slot."""
        return f"{self.name}@{float(self.at)!r}"

    @property
    def local_axis(self) -> int:
        """1 when the gauge measures along the leg's local Y, 2 along local Z."""
        return 1 if self.axis == (self.leg + 1) % 3 else 2

    @property
    def bar(self) -> int:
        """+1: the bar at +d/2 along local Z; -1: the one at -d/2."""
        return 1 if self.local_axis == 1 else -1


#: The paper's layout: two gauges at the middle of each leg, in the documented order.
PAPER_LAYOUT: tuple[GaugeSpec, ...] = tuple(
    GaugeSpec(leg, axis) for leg, axis in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
)


@dataclass(frozen=True)
class Gauge:
    """An installed gauge: its real stand pose, travel and zero."""

    spec: GaugeSpec
    origin: np.ndarray
    direction: np.ndarray
    sign: float
    travel: float = DEFAULT_TRAVEL
    zero: float = DEFAULT_TRAVEL / 2


def layout_from_names(names: list[str]) -> tuple[GaugeSpec, ...]:
    """Parse names such as ``"x-leg/y"`` or ``"x/y@0.3"`` into gauge specs."""
    specs = []
    for raw in names:
        body, _, at = raw.partition("@")
        leg, _, axis = body.replace("-leg", "").partition("/")
        if leg not in LEG_NAMES or axis not in AXIS_NAMES:
            raise ValueError(f"bad gauge name '{raw}': expected like 'x-leg/y' or 'x/y@0.5'")
        specs.append(
            GaugeSpec(LEG_NAMES.index(leg), AXIS_NAMES.index(axis), float(at) if at else 0.5)
        )
    return tuple(specs)


def ideal_rays(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec], machine: MachineParams,
    travel: float = DEFAULT_TRAVEL,
) -> tuple[np.ndarray, np.ndarray]:
    """Rays of perfectly installed gauges: each aimed at the middle of its bar's face at the
    Zero posture of ``machine``, the plunger at mid-travel.  Origins ``(*batch, n, 3)``
    and directions ``(n, 3)`` (a stand's nominal direction is a world axis)."""
    zero = np.zeros(3)
    centre, rot, half = collision_boxes(machine, zero, direct(machine, zero))
    target = [target_box(s) for s in specs]
    centre, rot, half = centre[..., target, :], rot[..., target, :, :], half[..., target, :]
    axis = np.array([s.local_axis for s in specs])
    direction = R_LEG[[s.leg for s in specs], :, axis]
    # Along the bar from its platform end (at=0) to its carriage end (at=1).
    at = np.array([s.at for s in specs])
    along = ((at - 0.5) * 2 * (half[..., 0] + BAR_CLEARANCE))[..., None] * -rot[..., :, 0]
    face = centre + along - direction * half[..., np.arange(len(specs)), axis][..., None]
    return face - direction * (travel / 2), direction


# --- the stand's installation, as an estimator sees it ------------------------------------
#: A stand is never exactly where the layout says.  Sliding it along its own measuring
#: axis only moves the zero, and turning the gauge about that axis changes nothing, so its
#: installation has four effective parameters: the ray's shift along the two other world
#: axes (mm) and its tilt toward them (rad).
STAND_PARAMS: tuple[str, ...] = ("shift", "shift", "tilt", "tilt")


def stand_axes(spec: GaugeSpec) -> tuple[int, int]:
    """The two world axes across a gauge's measuring axis, in x, y, z order."""
    a, b = (k for k in range(3) if k != spec.axis)
    return a, b


def stand_names(mounting: str, spec: GaugeSpec) -> list[str]:
    """Names of a mounting's four stand parameters, e.g. ``x-leg/y@0.5.shift_x``."""
    a, b = (AXIS_NAMES[k] for k in stand_axes(spec))
    return [f"{mounting}.shift_{a}", f"{mounting}.shift_{b}",
            f"{mounting}.tilt_{a}", f"{mounting}.tilt_{b}"]


def _across(specs: tuple[GaugeSpec, ...] | list[GaugeSpec]) -> np.ndarray:
    """Unit vectors of the two cross axes of each gauge, shape (n, 2, 3)."""
    return np.stack([np.eye(3)[list(stand_axes(s))] for s in specs])


def stand_rays(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec], origins: np.ndarray,
    directions: np.ndarray, stand: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Rays of stands installed with errors ``stand`` (shape ``(*batch, n, 4)``, in
    :data:`STAND_PARAMS` order) from the ideal ``origins`` and ``directions``."""
    across = _across(specs)
    stand = np.asarray(stand, dtype=float)
    origin = origins + np.einsum("...gk,gkj->...gj", stand[..., :2], across)
    direction = directions + np.einsum("...gk,gkj->...gj", stand[..., 2:], across)
    return origin, direction / np.linalg.norm(direction, axis=-1, keepdims=True)


def stand_errors(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec], origins: np.ndarray,
    directions: np.ndarray, ideal_origins: np.ndarray, ideal_directions: np.ndarray,
) -> np.ndarray:
    """The stand parameters (n, 4) of installed rays relative to ideal ones: the inverse of
    :func:`stand_rays` (the shift is measured where the ray crosses the plane through the
    ideal origin normal to the ideal direction).  For scoring against the truth only."""
    across = _across(specs)
    d0 = ideal_directions
    slope = np.sum(directions * d0, axis=-1, keepdims=True)
    s = np.sum((ideal_origins - origins) * d0, axis=-1, keepdims=True) / slope
    crossing = origins + s * directions - ideal_origins
    tilt = np.einsum("gj,gkj->gk", directions / slope, across)
    return np.concatenate([np.einsum("gj,gkj->gk", crossing, across), tilt], axis=-1)


def face_distances(
    machine: MachineParams, specs: tuple[GaugeSpec, ...] | list[GaugeSpec],
    origins: np.ndarray, directions: np.ndarray, rho: np.ndarray,
) -> np.ndarray:
    """Distance along each ray to the plane of the face its gauge is aimed at, at every
    posture: shape ``(*batch, *postures, n)`` for ``rho`` of shape
    ``(*batch, *postures, 3)`` and rays ``(*batch, n, 3)``.

    This is the reading model of an estimator: the plane is smooth in every parameter
    (no edges, no occlusion, no travel), and on a valid reading it is exactly the
    simulator's ray distance (the tip sits on that face)."""
    rho = np.asarray(rho, dtype=float)
    p = direct(machine, rho)
    legs = np.array([s.leg for s in specs])
    bars = np.array([s.bar for s in specs])
    a = carriage_points(machine, rho)[..., legs, :]
    c = platform_points(machine, p)[..., legs, :]
    centre, rot, half = _boxes(a, c, legs, bars)
    face = np.array([s.local_axis for s in specs])
    normal = np.einsum("...gjk,gk->...gj", rot, np.eye(3)[face])
    thickness = half[..., np.arange(len(specs)), face]
    extra = centre.ndim - 2 - (np.ndim(origins) - 2)
    shape = (*np.shape(origins)[:-2], *(1,) * extra, len(specs), 3)
    o = np.reshape(origins, shape)
    d = np.reshape(np.broadcast_to(directions, np.broadcast_shapes(np.shape(directions),
                                                                  np.shape(origins))), shape)
    nd = np.sum(normal * d, axis=-1)
    return (np.sum(normal * (centre - o), axis=-1) - thickness * np.sign(nd)) / nd


def install(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec],
    machine: MachineParams | None = None,
    *,
    travel: float = DEFAULT_TRAVEL,
    preset: ErrorPreset | None = None,
    rng: np.random.Generator | None = None,
) -> list[Gauge]:
    """Install gauges on ``machine`` (default nominal) as the paper does: each aimed at
    the middle of its bar's face at the Zero posture, plus the preset's installation
    errors (stand position and tilt) when ``preset`` and ``rng`` are given.

    The zero is provisional; :func:`zero_gauges` sets the gauges up at the Zero posture.
    """
    if travel <= 0:
        raise ValueError("gauge travel must be positive")
    machine = machine if machine is not None else MachineParams()
    gauges = []
    if not specs:
        return gauges
    for spec, origin, direction in zip(specs, *ideal_rays(specs, machine, travel), strict=True):
        if preset is not None and rng is not None:
            origin = origin + rng.normal(0.0, preset.gauge_position, 3)
            tilt = rng.normal(0.0, preset.gauge_tilt, 3)
            direction = direction + np.cross(tilt, direction)
            direction /= np.linalg.norm(direction)
        # The reading runs along the world axis, whichever side the stand is on.
        sign = float(np.sign(direction[spec.axis]))
        gauges.append(Gauge(spec, origin, direction, sign, travel))
    return gauges


def zero_gauges(gauges: list[Gauge], t_at_zero: np.ndarray) -> list[Gauge]:
    """Set up each gauge at the Zero posture as a technician does: slide it in its holder
    until the plunger sits at mid-travel, then zero the dial there.

    ``t_at_zero`` are the ray distances measured at Zero before the adjustment; a gauge
    whose ray misses its target (NaN) cannot be set up and raises ``ValueError``.
    """
    t_at_zero = np.asarray(t_at_zero, dtype=float)
    if np.isnan(t_at_zero).any():
        names = [g.spec.name for g, t in zip(gauges, t_at_zero, strict=True) if np.isnan(t)]
        raise ValueError(f"gauge(s) {names} do not touch their bar at the Zero posture")
    return [
        replace(g, origin=g.origin + (t - g.travel / 2) * g.direction, zero=g.travel / 2)
        for g, t in zip(gauges, t_at_zero, strict=True)
    ]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross costs ~10x more on small arrays)."""
    a, b = np.broadcast_arrays(a, b)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _boxes(
    a: np.ndarray, c: np.ndarray, legs: np.ndarray, bars: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bar boxes from the joint centres ``a`` (carriage) and ``c`` (platform) of their legs."""
    r_axis = R_LEG[legs][..., :, 2]
    v = c - a
    length = np.linalg.norm(v, axis=-1)
    along = v / length[..., None]
    hinge = cross(r_axis, along)
    hinge /= np.linalg.norm(hinge, axis=-1, keepdims=True)
    normal = cross(along, hinge)
    rot = np.stack([along, hinge, normal], axis=-1)
    half = np.stack(
        [length / 2 - BAR_CLEARANCE, *(np.full_like(length, s / 2) for s in BAR_SECTION)], axis=-1
    )
    centre = (a + c) / 2 + (bars * D_NOMINAL / 2)[..., None] * r_axis
    return centre, rot, half


def ray_box_interval(
    origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, rot: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where the line ``origin + t * direction`` enters and leaves a box (slab method);
    ``t_in > t_out`` when it misses."""
    o = np.einsum("...ji,...j->...i", rot, origin - centre)
    d = np.einsum("...ji,...j->...i", rot, np.broadcast_to(direction, o.shape))
    inside = np.abs(o) <= half
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / d
        t2 = (half - o) / d
    # A ray parallel to a slab is inside it everywhere or nowhere.
    lo = np.where(d == 0, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    hi = np.where(d == 0, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    return np.max(lo, axis=-1), np.min(hi, axis=-1)


def ray_box_distance(
    origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, rot: np.ndarray, half: np.ndarray
) -> np.ndarray:
    """Distance along the ray at which it enters the box; NaN on a miss.

    The ray is the whole line ``origin + t * direction``: negative ``t`` is reported, so an
    overtravel (box between the tip and the stand) is seen.
    """
    t_in, t_out = ray_box_interval(origin, direction, centre, rot, half)
    return np.where(t_out >= t_in, t_in, np.nan)


def on_flat_face(
    point: np.ndarray, centre: np.ndarray, rot: np.ndarray, half: np.ndarray,
    margin: float = TIP_EDGE_MARGIN, face: np.ndarray | int | None = None,
) -> np.ndarray:
    """Whether a contact point on a box's surface lies ``margin`` inside its face's edges,
    and, when ``face`` (box axis 0, 1 or 2) is given, on that face.

    A gauge reads only on the face it is aimed at: near a bar's end its ray can enter
    through the end face at grazing incidence, where a real tip slides off the edge (and
    PyBullet's rounded box edges disagree with the sharp box by ~1 mm)."""
    local = np.einsum("...ji,...j->...i", rot, point - centre)
    ratio = np.abs(local) / half
    touched = np.argmax(ratio, axis=-1)
    inner = np.abs(local) <= half - margin
    ok = np.all(inner | (np.arange(3) == touched[..., None]), axis=-1)
    return ok if face is None else ok & (touched == face)


def collision_boxes(
    machine: MachineParams, rho: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every moving collision box, in the order of :data:`BOX_NAMES`: centres
    ``(..., 10, 3)``, rotations ``(..., 10, 3, 3)``, half extents ``(..., 10, 3)``."""
    legs = np.repeat(np.arange(3), 2)
    bars = np.tile([1, -1], 3)
    a = carriage_points(machine, rho)
    c = platform_points(machine, p)
    centre, rot, half = _boxes(a[..., legs, :], c[..., legs, :], legs, bars)
    theta, _ = leg_angles(machine, rho, p)
    cos, sin = np.cos(theta), np.sin(theta)
    zeros, ones = np.zeros_like(theta), np.ones_like(theta)
    rz = np.stack([np.stack([cos, -sin, zeros], -1), np.stack([sin, cos, zeros], -1),
                   np.stack([zeros, zeros, ones], -1)], -2)
    coupler_rot = R_LEG @ rz
    shape = (*np.shape(theta)[:-1], 3, 3)
    centres = np.concatenate([centre, c, np.asarray(p)[..., None, :]], axis=-2)
    rots = np.concatenate([rot, coupler_rot, np.broadcast_to(np.eye(3), (*shape[:-2], 1, 3, 3))],
                          axis=-3)
    halves = np.concatenate([
        half,
        np.broadcast_to(np.array(SHORT_LINK_SIZE) / 2, shape),
        np.broadcast_to(np.full(3, PLATFORM_SIZE / 2), (*shape[:-2], 1, 3)),
    ], axis=-2)
    return centres, rots, halves


#: Names of the moving collision boxes (the simulator's link names).
BOX_NAMES: tuple[str, ...] = tuple(
    [f"{leg}_{bar}" for leg in LEG_NAMES for bar in ("bar1", "bar2")]
    + [f"{leg}_coupler" for leg in LEG_NAMES] + ["platform"]
)


def target_box(spec: GaugeSpec) -> int:
    """Index in :data:`BOX_NAMES` of the bar a gauge touches."""
    return 2 * spec.leg + (0 if spec.bar > 0 else 1)


def exact_ray_distances(
    machine: MachineParams, gauges: list[Gauge], rho: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Exact tip distances ``t`` of every gauge, shape ``(..., n_gauges)``.

    NaN when the ray misses the bar's flat face, or when another part lies on the ray
    before the bar within the window a gauge can see (``-RAY_BACKOFF`` to
    ``travel + RAY_BACKOFF``).  A bar behind the tip (``t < 0``) is an overtravel
    whatever else is on the ray: it presses the gauge.  ``boxes``: the
    :func:`collision_boxes` at ``rho`` when already computed.
    """
    rho = np.asarray(rho, dtype=float)
    if not gauges:
        return np.empty((*rho.shape[:-1], 0))
    origins = np.array([g.origin for g in gauges])[:, None, :]
    directions = np.array([g.direction for g in gauges])[:, None, :]
    target = np.array([target_box(g.spec) for g in gauges])
    centre, rot, half = boxes or collision_boxes(machine, rho, direct(machine, rho))
    t_in, t_out = ray_box_interval(
        origins, directions, centre[..., None, :, :], rot[..., None, :, :, :],
        half[..., None, :, :],
    )  # (..., gauges, boxes)
    pick = (..., np.arange(len(gauges)), target)
    t = np.where(t_out[pick] >= t_in[pick], t_in[pick], np.nan)
    hit = origins[:, 0] + np.nan_to_num(t)[..., None] * directions[:, 0]
    face = np.array([g.spec.local_axis for g in gauges])
    t = np.where(on_flat_face(hit, centre[..., target, :], rot[..., target, :, :],
                              half[..., target, :], face=face), t, np.nan)
    others = np.arange(len(BOX_NAMES)) != target[:, None]
    reach = np.array([g.travel for g in gauges]) + RAY_BACKOFF
    in_window = (t_out >= -RAY_BACKOFF) & (t_in <= t_out) & (t_in < t[..., None])
    occluded = np.any(in_window & others, axis=-1) & (t >= 0)
    return np.where(occluded | (t > reach), np.nan, t)


def exact_target_boxes(
    gauges: list[Gauge], boxes: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box of every gauge's target bar among the :func:`collision_boxes` ``boxes``."""
    centre, rot, half = boxes
    target = [target_box(g.spec) for g in gauges]
    return centre[..., target, :], rot[..., target, :, :], half[..., target, :]


def pressed_past_travel(
    gauges: list[Gauge], centre: np.ndarray, rot: np.ndarray, half: np.ndarray
) -> np.ndarray:
    """Whether each gauge's target bar presses it past its travel: the bar's box, grown by
    the body radius, meets the gauge axis behind the fully pushed-in tip (``t < 0``) and
    in front of the stand's end."""
    if not gauges:
        return np.zeros(0, dtype=bool)
    origins = np.array([g.origin for g in gauges])
    directions = np.array([g.direction for g in gauges])
    # The body is a cylinder around the gauge axis: grow the box across the axis only.
    along = np.einsum("...ji,...j->...i", rot, directions)
    grown = half + GAUGE_BODY_RADIUS * np.sqrt(np.clip(1 - along**2, 0.0, 1.0))
    t_in, t_out = ray_box_interval(origins, directions, centre, rot, grown)
    return (t_in <= t_out) & (t_in < 0) & (t_out > -STAND_LENGTH)


def status_of(gauges: list[Gauge], t: np.ndarray) -> np.ndarray:
    """Status codes for ray distances ``t`` (NaN means the ray missed the target)."""
    travel = np.array([g.travel for g in gauges])
    status = np.full(np.shape(t), Status.VALID, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        status[t > travel] = Status.NO_CONTACT
        status[t < 0] = Status.OVERTRAVEL
    status[np.isnan(t)] = Status.MISSED
    return status


def readings_from_distances(gauges: list[Gauge], t: np.ndarray) -> np.ndarray:
    """Ideal readings (mm) from ray distances; NaN where the gauge is not in contact."""
    sign = np.array([g.sign for g in gauges])
    zero = np.array([g.zero for g in gauges])
    reading = sign * (t - zero)
    return np.where(status_of(gauges, t) == Status.VALID, reading, np.nan)


def exact_readings(machine: MachineParams, gauges: list[Gauge], rho: np.ndarray) -> np.ndarray:
    """Ideal (noise-free, unquantised) readings of the exact model; NaN if not valid."""
    return readings_from_distances(gauges, exact_ray_distances(machine, gauges, rho))


def model_readings(machine: MachineParams, gauges: list[Gauge], rho: np.ndarray) -> np.ndarray:
    """Readings of the exact model *without* the travel limits (NaN only where the ray
    misses the bar): what a calibrator's model predicts while it iterates over estimates
    whose gauges would be out of travel."""
    t = exact_ray_distances(machine, gauges, rho)
    return np.array([g.sign for g in gauges]) * (t - np.array([g.zero for g in gauges]))


def installed_on(machine: MachineParams, gauges: list[Gauge]) -> list[Gauge]:
    """The gauges set up and zeroed by the exact model at the Zero posture of ``machine``."""
    return zero_gauges(gauges, exact_ray_distances(machine, gauges, np.zeros(3)))


def model_gauges(
    machine: MachineParams, specs: tuple[GaugeSpec, ...] | list[GaugeSpec]
) -> list[Gauge]:
    """Ideal gauges installed and zeroed on ``machine``: what a calibrator's model assumes
    for its current estimate (it cannot know the installation errors)."""
    return installed_on(machine, install(specs, machine))


#: A dial gauge's repeatability and display step are small against its travel: at most
#: this fraction of it.  A noisy, quantised reading then stays inside the env's
#: observation box (half a travel of margin is >= 25 sigma).
MAX_NOISE_FRACTION: float = 1 / 50
#: Finest display step accepted (mm): no dial gauge resolves a nanometre, and dividing a
#: reading by a subnormal step overflows to infinity.
MIN_RESOLUTION: float = 1e-6


def check_noise(
    sigma: object, resolution: object, travel: float = DEFAULT_TRAVEL, *,
    names: tuple[str, str] = ("gauge_sigma", "gauge_resolution"),
) -> GaugeNoise:
    """The noise of a dial gauge with ``travel`` mm of travel, or ``ValueError`` naming the
    bad value (``names``: what the caller calls sigma and resolution).

    Repeatability ``sigma`` and display step ``resolution`` (mm, 0 = ideal) must be real
    numbers in [0, travel * MAX_NOISE_FRACTION]; a non-zero step at least MIN_RESOLUTION.
    """
    limit = travel * MAX_NOISE_FRACTION
    rule = (f"a dial gauge's repeatability and resolution lie in [0, travel/"
            f"{1 / MAX_NOISE_FRACTION:g}] = [0, {limit:g}] mm")
    for name, value in zip(names, (sigma, resolution), strict=True):
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"{name} must be a number (mm), got {value!r}")
        if not (np.isfinite(value) and 0 <= value <= limit):
            raise ValueError(f"{name} {value:g} mm is out of range: {rule}")
    if 0 < resolution < MIN_RESOLUTION:  # type: ignore[operator]
        raise ValueError(f"{names[1]} {resolution:g} mm is finer than any dial gauge's: "
                         f"use 0 (ideal) or at least {MIN_RESOLUTION:g} mm")
    return GaugeNoise(float(sigma), float(resolution))  # type: ignore[arg-type]


@dataclass(frozen=True)
class GaugeNoise:
    """Repeatability noise (normal, ``sigma`` mm) and display resolution (mm); 0 = ideal."""

    sigma: float = DEFAULT_SIGMA
    resolution: float = DEFAULT_RESOLUTION

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma) and self.sigma >= 0):
            raise ValueError("gauge sigma must be a finite number >= 0")
        if not (np.isfinite(self.resolution) and self.resolution >= 0):
            raise ValueError("gauge resolution must be a finite number >= 0")

    def apply(self, readings: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy, quantised readings (NaN stays NaN).  Noise is drawn for every gauge so
        the random stream does not depend on which readings are valid."""
        draws = rng.normal(0.0, 1.0, np.shape(readings))
        noisy = np.asarray(readings, dtype=float) + draws * self.sigma
        if self.resolution > 0:
            noisy = np.round(noisy / self.resolution) * self.resolution
        return noisy

    @property
    def effective_sigma(self) -> float:
        """Standard deviation of one reading: noise plus uniform quantisation error."""
        return float(np.hypot(self.sigma, self.resolution / np.sqrt(12)))
