"""Dial gauges: layout, installation, the exact reading model, noise and quantisation.

A gauge is a plunger on a magnetic stand fixed to the base.  Its ray starts at
``origin`` (the tip when the plunger is pushed fully in) and runs along ``direction``
(toward the target); the tip touches the first face of the target at distance
``t``.  The plunger can extend by ``travel`` mm, so the gauge is in contact when
``0 <= t <= travel``.  ``t > travel``: the tip hangs in the air (no contact); ``t < 0``:
the target has pushed the plunger past its travel toward the stand (overtravel, which
would damage a real gauge).

Reading convention (the README's Conventions): the coordinate of the touched surface point along the
gauge's world measuring axis, relative to the gauge's zero, in mm::

    reading = sign * (t - zero),  sign = direction . e_axis  (+1 or -1 nominally)

so the difference of two readings is the surface's displacement along that axis.

Targets (:class:`Part`), every one a flat box face (a ray against a box face is exact to round-off):

* a leg's **bar**: a gauge measuring leg ``i`` along the leg's local Y touches the bar at
  ``+d/2`` along local Z, at that height; one measuring along local Z comes from below
  and touches the bar at ``-d/2``.  The place along the bar is the slot's ``at``.
* a leg's **carriage**, the block the drive moves and that carries R1: measured across
  the drive, along local Y from the +Y side (the rail runs beside the carriage on its -Y
  side) or along local Z from below, aimed at the middle of the face at Zero.  The
  carriage moves along its guideway, so the face slides under the tip and the reading is
  the guideway's sideways run: its direction error (``axis_tilt``) times the travel, seen
  without the legs in between.  The tip stays on the 70 mm face for about +-33 mm of the
  carriage's travel around Zero.  No gauge measures along the drive: it would read the
  encoder's own travel (the tilt only to second order) and hold the carriage within its
  10 mm of travel.
* the **platform**: its face normal to x, y or z on the side away from the legs (the
  -x, -y, -z faces; the +faces carry the legs' couplers), touched :data:`PLATFORM_AIM` off
  the face's centre toward the negative of both other axes (the centre of the -z face
  carries the tool; the same place on every face keeps the three slots alike under
  x -> y -> z).  It reads the platform's displacement along that axis, so it only allows
  moves within its travel toward the stand; across the axis the face slides under the tip.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from enum import IntEnum
from functools import lru_cache
from typing import Any, overload

import numpy as np

from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import (
    AXIS_NAMES,
    LEG_NAMES,
    R_LEG,
    ErrorPreset,
    MachineParams,
)
from orthoglide_env.model.kinematics import (
    carriage_points,
    cross,
    direct,
    dot,
    leg_angles,
    platform_points,
)

#: The prototype's gauges' travel (mm), the default where no design says otherwise.
DEFAULT_TRAVEL: float = PROTOTYPE.gauge_travel
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


class Part(IntEnum):
    """What a gauge touches."""

    BAR = 0  # a leg's parallelogram bar
    CARRIAGE = 1  # a leg's carriage (drive block carrying R1)
    PLATFORM = 2  # a face of the platform


#: The leg of a platform gauge: it has none.
NO_LEG: int = -1
#: A platform gauge touches its face this far (mm) off the face's centre, toward the
#: negative of both other axes (see the module docstring).
PLATFORM_AIM: float = 10.0


class Status(IntEnum):
    """Why a reading is or is not valid."""

    VALID = 0
    NO_CONTACT = 1  # tip extended fully without touching
    OVERTRAVEL = 2  # plunger pushed in past its travel
    MISSED = 3  # tip off the target's flat face, or the ray meets something else first


def local_axis(leg: np.ndarray | int, axis: np.ndarray | int) -> np.ndarray:
    """The leg-frame axis a gauge on ``leg`` measuring along world ``axis`` measures along:
    1 (local Y) or 2 (local Z)."""
    return np.where(np.asarray(axis) == (np.asarray(leg) + 1) % 3, 1, 2)


def face_of(part: np.ndarray | int, leg: np.ndarray | int, axis: np.ndarray | int
            ) -> np.ndarray:
    """The axis of its target's box whose face a gauge touches: a bar's and a carriage's
    box lie in the leg frame (local Y or Z: 1 or 2), the platform's in the world frame
    (the measuring axis)."""
    return np.where(np.asarray(part) == Part.PLATFORM, axis, local_axis(leg, axis))


def target_index(part: np.ndarray | int, leg: np.ndarray | int, face: np.ndarray | int
                 ) -> np.ndarray:
    """Index in :data:`BOX_NAMES` of the box a gauge touches: the bar at +d/2 along local
    Z (measured along local Y, from the side) or the one at -d/2 (along local Z, from
    below), the leg's carriage, or the platform."""
    part, leg = np.asarray(part), np.asarray(leg)
    bar = 2 * leg + (np.asarray(face) == 2)
    return np.where(part == Part.BAR, bar,
                    np.where(part == Part.CARRIAGE, CARRIAGE_BOX + leg, PLATFORM_BOX))


@dataclass(frozen=True)
class GaugeSpec:
    """Where a gauge goes, nominally: what it touches (``part``), which leg, which world
    axis it measures along, where along the leg.

    ``at`` is the fraction of the leg from the platform end (0) to the carriage end (1) at
    the Zero posture; the paper's gauges sit in the middle (0.5).  A carriage or platform
    gauge has one place per face (``at`` stays 0.5); a platform gauge has no leg
    (:data:`NO_LEG`).  :meth:`carriage` and :meth:`platform` make those.
    """

    leg: int
    axis: int
    at: float = 0.5
    part: Part = Part.BAR

    def __post_init__(self) -> None:
        if self.part not in tuple(Part):
            raise ValueError(f"gauge part must be one of {[p.name.lower() for p in Part]}")
        object.__setattr__(self, "part", Part(self.part))
        if self.axis not in (0, 1, 2):
            raise ValueError("gauge axis must be 0, 1 or 2 (x, y, z)")
        if self.part == Part.PLATFORM:
            if self.leg != NO_LEG:
                raise ValueError(f"a platform gauge has no leg (leg {NO_LEG})")
        elif self.leg not in (0, 1, 2):
            raise ValueError("gauge leg must be 0, 1 or 2 (x, y, z)")
        elif self.leg == self.axis:
            raise ValueError(f"a gauge measures a {self.part.name.lower()} along one of the "
                             "two axes normal to its leg")
        if self.part == Part.BAR and not 0.05 <= self.at <= 0.95:
            raise ValueError("gauge position 'at' must lie in [0.05, 0.95] along the leg")
        if self.part != Part.BAR and self.at != 0.5:
            raise ValueError("a carriage or platform gauge has one place per face: 'at' is "
                             "for bars")

    @classmethod
    def carriage(cls, leg: int, axis: int) -> GaugeSpec:
        """A gauge on leg ``leg``'s carriage, measuring along world ``axis`` (across the
        drive)."""
        return cls(leg, axis, part=Part.CARRIAGE)

    @classmethod
    def platform(cls, axis: int) -> GaugeSpec:
        """A gauge on the platform's face normal to world ``axis``."""
        return cls(NO_LEG, axis, part=Part.PLATFORM)

    @property
    def name(self) -> str:
        """``x-leg/y`` (a bar), ``x-carriage/y`` or ``platform/x``."""
        axis = AXIS_NAMES[self.axis]
        if self.part == Part.PLATFORM:
            return f"platform/{axis}"
        kind = "leg" if self.part == Part.BAR else "carriage"
        return f"{LEG_NAMES[self.leg]}-{kind}/{axis}"

    @property
    def slot(self) -> str:
        """The name with a bar gauge's place along the leg, e.g. ``x-leg/y@0.5``: unique per
        slot (a carriage or platform face has one place: its name)."""
        return f"{self.name}@{float(self.at)!r}" if self.part == Part.BAR else self.name

    @property
    def face(self) -> int:
        """The axis of the target's box whose face the gauge touches (see :func:`face_of`)."""
        return int(face_of(self.part, self.leg, self.axis))

    @property
    def approach(self) -> float:
        """+1 when the plunger points along the world axis it measures along, -1 against
        it: only a carriage gauge along local Y comes from the +Y side."""
        return -1.0 if self.part == Part.CARRIAGE and self.face == 1 else 1.0

    @property
    def bar(self) -> int:
        """The bar a bar gauge touches: +1 the bar at +d/2 along local Z, -1 the one at
        -d/2."""
        return 1 if self.face == 1 else -1


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


@dataclass(frozen=True)
class GaugeArray:
    """Installed gauges as arrays: one gauge set (batch shape ``()``) or one set per machine
    of a batch (:attr:`MachineParams.batch_shape`).

    Every field has the batch dimensions first, then one entry per gauge ``G``: ``origin``
    and ``direction`` ``(*batch, G, 3)``, the rest ``(*batch, G)``.  ``leg``, ``axis``,
    ``at`` and ``part`` (bars unless given) are each gauge's :class:`GaugeSpec`, so a
    gauge set converts back to :class:`Gauge` objects without loss (:meth:`to_gauges`).
    Every function of this module that takes a ``list[Gauge]`` also takes a
    ``GaugeArray``; the list is converted, so there is one computation for one machine and
    for many.
    """

    origin: np.ndarray
    direction: np.ndarray
    sign: np.ndarray
    travel: np.ndarray
    zero: np.ndarray
    leg: np.ndarray
    axis: np.ndarray
    at: np.ndarray
    part: np.ndarray | int = Part.BAR

    def __post_init__(self) -> None:
        shape = np.shape(self.origin)
        if len(shape) < 2 or shape[-1] != 3:
            raise ValueError(f"gauge origins must have shape (*batch, G, 3), got {list(shape)}")
        for name, tail, dtype in (("origin", (3,), float), ("direction", (3,), float),
                                  ("sign", (), float), ("travel", (), float),
                                  ("zero", (), float), ("leg", (), np.intp),
                                  ("axis", (), np.intp), ("at", (), float),
                                  ("part", (), np.intp)):
            value = np.asarray(getattr(self, name), dtype=dtype)
            object.__setattr__(self, name, np.broadcast_to(value, (*shape[:-1], *tail)))

    @classmethod
    def of(cls, gauges: Sequence[Gauge]) -> GaugeArray:
        """The array form of one machine's gauges (batch shape ``()``)."""
        specs = [g.spec for g in gauges]
        return cls(
            origin=np.array([g.origin for g in gauges], dtype=float).reshape(len(gauges), 3),
            direction=np.array([g.direction for g in gauges], dtype=float).reshape(-1, 3),
            sign=[g.sign for g in gauges], travel=[g.travel for g in gauges],
            zero=[g.zero for g in gauges], leg=[s.leg for s in specs],
            axis=[s.axis for s in specs], at=[s.at for s in specs],
            part=[s.part for s in specs],
        )

    @classmethod
    def stack(cls, sets: Sequence[GaugeArray | Sequence[Gauge]]) -> GaugeArray:
        """A batch of shape ``(len(sets),)`` from gauge sets of equal size."""
        if not sets:
            raise ValueError("cannot stack an empty list of gauge sets")
        arrays = [as_gauge_array(s) for s in sets]
        return cls(**{f.name: np.stack([getattr(a, f.name) for a in arrays])
                      for f in fields(cls)})

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading shape of the batch of machines; ``()`` for one machine's gauges."""
        return self.sign.shape[:-1]

    @property
    def count(self) -> int:
        """Gauges per machine."""
        return self.sign.shape[-1]

    def __getitem__(self, index: Any) -> GaugeArray:
        """One machine's gauges (or a sub-batch) of a batch."""
        if not self.batch_shape:
            raise IndexError("one machine's gauges have no batch axis to index")
        return GaugeArray(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    def columns(self, index: np.ndarray) -> GaugeArray:
        """The gauges ``index`` of every set (along the gauge axis)."""
        at = len(self.batch_shape)
        return GaugeArray(**{f.name: np.take(getattr(self, f.name), index, axis=at)
                             for f in fields(self)})

    def with_rows(self, index: np.ndarray, rows: GaugeArray) -> GaugeArray:
        """A copy of this batch whose machines ``index`` (along the first batch axis) carry
        the gauge sets ``rows`` instead."""
        out = {}
        for f in fields(self):
            value = np.array(getattr(self, f.name))
            value[index] = getattr(rows, f.name)
            out[f.name] = value
        return GaugeArray(**out)

    @property
    def target(self) -> np.ndarray:
        """Index in :data:`BOX_NAMES` of each gauge's target box, ``(*batch, G)``."""
        return target_index(self.part, self.leg, self.face)

    @property
    def face(self) -> np.ndarray:
        """The target box's face (box axis) each gauge touches, ``(*batch, G)``."""
        return face_of(self.part, self.leg, self.axis)

    def spec(self, index: tuple[int, ...]) -> GaugeSpec:
        """The :class:`GaugeSpec` of the gauge at ``index`` (batch indices, then the
        gauge's)."""
        return GaugeSpec(int(self.leg[index]), int(self.axis[index]), float(self.at[index]),
                         Part(int(self.part[index])))

    def for_postures(self, ndim: int) -> GaugeArray:
        """The fields reshaped to broadcast against arrays of ``ndim`` leading dimensions
        (the batch, then posture dimensions) before the gauge axis."""
        batch = len(self.batch_shape)
        extra = ndim - batch
        if extra <= 0:
            return self
        return GaugeArray(**{f.name: _insert_axes(getattr(self, f.name), batch, extra)
                             for f in fields(self)})

    def to_gauges(self) -> list[Gauge]:
        """One machine's gauges as :class:`Gauge` objects."""
        if self.batch_shape:
            raise ValueError("to_gauges() converts one machine's gauges: index the batch first")
        return [
            Gauge(self.spec((k,)), origin.copy(), direction.copy(), float(sign), float(travel),
                  float(zero))
            for k, (origin, direction, sign, travel, zero) in enumerate(zip(
                self.origin, self.direction, self.sign, self.travel, self.zero, strict=True))
        ]

    def zeroed(self, t_at_zero: np.ndarray) -> GaugeArray:
        """The gauges set up at the Zero posture: see :func:`zero_gauges`."""
        t_at_zero = np.asarray(t_at_zero, dtype=float)
        if np.isnan(t_at_zero).any():
            names = [(f"machine {k[0] if len(k) == 2 else list(k[:-1])}: " if len(k) > 1
                      else "") + self.spec(k).name
                     for k in map(tuple, np.argwhere(np.isnan(t_at_zero)).tolist())]
            raise ValueError(f"gauge(s) {names} do not touch their target at the Zero posture")
        half = self.travel / 2
        return replace(self, origin=self.origin + (t_at_zero - half)[..., None] * self.direction,
                       zero=half)


def _insert_axes(value: np.ndarray, position: int, count: int) -> np.ndarray:
    """``value`` with ``count`` singleton axes inserted before axis ``position``."""
    return value.reshape(*value.shape[:position], *(1,) * count, *value.shape[position:])


def as_gauge_array(gauges: GaugeArray | Sequence[Gauge]) -> GaugeArray:
    """``gauges`` as a :class:`GaugeArray` (a list of one machine's gauges is converted)."""
    return gauges if isinstance(gauges, GaugeArray) else GaugeArray.of(gauges)


def layout_from_names(names: list[str]) -> tuple[GaugeSpec, ...]:
    """Parse names such as ``"x-leg/y"``, ``"x/y@0.3"``, ``"x-carriage/y"`` or
    ``"platform/x"`` into gauge specs."""
    specs = []
    for raw in names:
        body, _, at = raw.partition("@")
        where, _, axis = body.partition("/")
        leg, _, kind = where.partition("-")
        part = {"": Part.BAR, "leg": Part.BAR, "carriage": Part.CARRIAGE}.get(kind)
        if where == "platform" and not at:
            leg, part = LEG_NAMES[0], Part.PLATFORM
        if leg not in LEG_NAMES or axis not in AXIS_NAMES or part is None or (
                at and part != Part.BAR):
            raise ValueError(f"bad gauge name '{raw}': expected like 'x-leg/y', 'x/y@0.5', "
                             "'x-carriage/y' or 'platform/x'")
        axis_index = AXIS_NAMES.index(axis)
        specs.append(
            GaugeSpec.platform(axis_index) if part == Part.PLATFORM
            else GaugeSpec(LEG_NAMES.index(leg), axis_index, float(at) if at else 0.5, part)
        )
    return tuple(specs)


def spec_arrays(specs: Sequence[GaugeSpec]) -> GaugeArray:
    """The specs of ``specs`` as the index fields of a :class:`GaugeArray` (its rays are
    placeholders); made once per set of specs (an estimator's model asks at every step)."""
    return _spec_arrays(tuple(specs))


@lru_cache(maxsize=256)
def _spec_arrays(specs: tuple[GaugeSpec, ...]) -> GaugeArray:
    n = len(specs)
    return GaugeArray(origin=np.zeros((n, 3)), direction=np.zeros((n, 3)), sign=0.0,
                      travel=0.0, zero=0.0, leg=[s.leg for s in specs],
                      axis=[s.axis for s in specs], at=[s.at for s in specs],
                      part=[s.part for s in specs])


def ideal_rays(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec], machine: MachineParams,
    travel: float = DEFAULT_TRAVEL,
) -> tuple[np.ndarray, np.ndarray]:
    """Rays of perfectly installed gauges: each aimed at its place on its target's face at
    the Zero posture of ``machine`` (a bar's ``at``, a carriage face's middle, the
    platform face's :data:`PLATFORM_AIM`), the plunger at mid-travel.  Origins
    ``(*batch, n, 3)`` and directions ``(n, 3)`` (a stand's nominal direction is a world
    axis)."""
    zero = np.zeros(3)
    g = spec_arrays(specs)
    centre, rot, half = target_boxes(machine, g, zero, direct(machine, zero))
    n = len(specs)
    face = g.face
    direction = np.array([s.approach for s in specs])[:, None] * np.eye(3)[g.axis]
    # The place on the face, in the box's frame: along a bar from its platform end
    # (at=0) to its carriage end (at=1); off a platform face's centre; a carriage face's
    # middle.
    clearance = machine.design.bar_clearance
    along = np.where(g.part == Part.BAR, (0.5 - g.at) * 2 * (half[..., 0] + clearance), 0.0)
    aside = np.where((np.arange(3) != face[:, None]) & (g.part == Part.PLATFORM)[:, None],
                     -PLATFORM_AIM, 0.0)
    local = aside + along[..., None] * np.eye(3)[0]
    place = rot[..., 0] * local[..., 0, None] + rot[..., 1] * local[..., 1, None] + (
        rot[..., 2] * local[..., 2, None])
    point = centre + place - direction * half[..., np.arange(n), face][..., None]
    return point - direction * (travel / 2), direction


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


def across_axes(specs: tuple[GaugeSpec, ...] | list[GaugeSpec]) -> np.ndarray:
    """Unit vectors of the two cross axes of each gauge, shape (n, 2, 3) (read-only: made
    once per set of specs)."""
    return _across_axes(tuple(specs))


@lru_cache(maxsize=256)
def _across_axes(specs: tuple[GaugeSpec, ...]) -> np.ndarray:
    out = np.stack([np.eye(3)[list(stand_axes(s))] for s in specs]).reshape(len(specs), 2, 3)
    out.setflags(write=False)
    return out


def stand_rays(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec], origins: np.ndarray,
    directions: np.ndarray, stand: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Rays of stands installed with errors ``stand`` (shape ``(*batch, n, 4)``, in
    :data:`STAND_PARAMS` order) from the ideal ``origins`` and ``directions``."""
    across = across_axes(specs)
    stand = np.asarray(stand, dtype=float)
    origin = origins + np.einsum("...gk,gkj->...gj", stand[..., :2], across)
    direction = directions + np.einsum("...gk,gkj->...gj", stand[..., 2:], across)
    return origin, direction / np.sqrt(dot(direction, direction))[..., None]


def stand_errors(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec], origins: np.ndarray,
    directions: np.ndarray, ideal_origins: np.ndarray, ideal_directions: np.ndarray,
) -> np.ndarray:
    """The stand parameters (n, 4) of installed rays relative to ideal ones: the inverse of
    :func:`stand_rays` (the shift is measured where the ray crosses the plane through the
    ideal origin normal to the ideal direction).  For scoring against the truth only."""
    across = across_axes(specs)
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
    g = spec_arrays(specs)
    centre, rot, half = target_boxes(machine, g, rho, direct(machine, rho))
    extra = centre.ndim - 2 - (np.ndim(origins) - 2)
    shape = (*np.shape(origins)[:-2], *(1,) * extra, len(specs), 3)
    o = np.reshape(origins, shape)
    d = np.reshape(np.broadcast_to(directions, np.broadcast_shapes(np.shape(directions),
                                                                  np.shape(origins))), shape)
    return plane_distances(centre, rot, half, g.face, o, d)


def plane_distances(centre: np.ndarray, rot: np.ndarray, half: np.ndarray, face: np.ndarray,
                    origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance along each ray ``origins + t directions`` (``(..., G, 3)``) to the plane of
    face ``face`` (box axis, ``(G,)``) of its box (centres ``(..., G, 3)``, rotations
    ``(..., G, 3, 3)``, half extents ``(..., G, 3)``), on the side the ray comes from."""
    normal = face_normals(rot, face)
    thickness = half[..., np.arange(len(face)), face]
    nd = dot(normal, directions)
    return (dot(normal, centre - origins) - thickness * np.sign(nd)) / nd


def face_normals(rot: np.ndarray, face: np.ndarray) -> np.ndarray:
    """The normal of face ``face`` (box axis, ``(G,)``) of each box (rotations
    ``(..., G, 3, 3)``): ``(..., G, 3)``."""
    return np.einsum("...gjk,gk->...gj", rot, np.eye(3)[face])


def target_boxes(
    machine: MachineParams, gauges: GaugeArray, rho: np.ndarray, p: np.ndarray
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
    bars = _boxes(a, c, legs, np.where(gauges.face == 1, 1, -1), design)
    carriages = _carriage_boxes(a, legs, design)
    platform = _platform_box(np.broadcast_to(p, np.broadcast_shapes(np.shape(p), np.shape(a))),
                             design)
    part = gauges.part
    return tuple(  # type: ignore[return-value]
        np.where((part == Part.BAR).reshape(-1, *(1,) * tail), b,
                 np.where((part == Part.CARRIAGE).reshape(-1, *(1,) * tail), c, f))
        for b, c, f, tail in zip(bars, carriages, platform, (1, 2, 1), strict=True))


def bar_normal_pullback(weights: np.ndarray, a: np.ndarray, c: np.ndarray, legs: np.ndarray,
                        face: np.ndarray) -> np.ndarray:
    """``weights . dn/dv``: the derivative of a bar box's face normal ``n`` (face 1: the
    hinge axis, 2: the normal of :func:`_boxes`) over ``v = c - a``, pulled back along
    ``weights`` (``(..., 3)``), without forming the 3 x 3 derivatives.  With ``u = v / |v|``,
    ``h = w / |w|``, ``w = r x u`` and ``m = u x h``: ``du = (I - u u^T) dv / |v|``, ``dh =
    (I - h h^T) [r]x du / |w|``, ``dm = -[h]x du + [u]x dh``, and ``z^T [x]x = (z x x)^T``."""
    r_axis = R_LEG[legs][..., :, 2]
    v = c - a
    length = np.sqrt(dot(v, v))[..., None]
    along = v / length
    w = cross(r_axis, along)
    size = np.sqrt(dot(w, w))[..., None]
    hinge = w / size

    def through_along(z: np.ndarray) -> np.ndarray:
        return (z - dot(z, along)[..., None] * along) / length

    def through_hinge(z: np.ndarray) -> np.ndarray:
        return through_along(cross(z - dot(z, hinge)[..., None] * hinge, r_axis)) / size

    normal = through_hinge(cross(weights, along)) - through_along(cross(weights, hinge))
    return np.where((np.asarray(face) == 1)[..., None], through_hinge(weights), normal)


def skew(x: np.ndarray) -> np.ndarray:
    """Matrices ``[x]x`` (``(..., 3, 3)``) with ``[x]x y = x cross y``."""
    x = np.asarray(x, dtype=float)
    out = np.zeros((*x.shape, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -x[..., 2], x[..., 1], -x[..., 0]
    return out - np.swapaxes(out, -1, -2)


def _carriage_boxes(a: np.ndarray, legs: np.ndarray, design: MachineDesign
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Carriage boxes of ``legs`` from their R1 centres ``a`` (``(..., n, 3)``): a carriage
    keeps its nominal orientation and starts the design's ``carriage_setback`` behind R1
    (away from the platform)."""
    rot = R_LEG[legs]
    centre = a + (design.carriage_setback + design.carriage_size[0] / 2) * rot[..., 0]
    lead = centre.shape[:-1]
    return (centre, np.broadcast_to(rot, (*lead, 3, 3)),
            np.broadcast_to(np.array(design.carriage_size) / 2, (*lead, 3)))


def _platform_box(p: np.ndarray, design: MachineDesign
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The platform's box with the TCP at ``p`` (``(..., 3)``): it only translates."""
    lead = np.shape(p)[:-1]
    return (np.asarray(p), np.broadcast_to(np.eye(3), (*lead, 3, 3)),
            np.broadcast_to(np.full(3, design.platform_size / 2), (*lead, 3)))


def install(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec],
    machine: MachineParams | None = None,
    *,
    travel: float | None = None,
    preset: ErrorPreset | None = None,
    rng: np.random.Generator | None = None,
) -> list[Gauge]:
    """Install gauges on ``machine`` (default nominal) as the paper does: each aimed at
    its place on its target's face at the Zero posture, plus the preset's installation
    errors (stand position and tilt) when ``preset`` and ``rng`` are given.

    The zero is provisional; :func:`zero_gauges` sets the gauges up at the Zero posture.
    ``travel``: default the machine design's gauge travel.
    """
    machine = machine if machine is not None else MachineParams()
    travel = machine.design.gauge_travel if travel is None else travel
    if travel <= 0:
        raise ValueError("gauge travel must be positive")
    if not specs:
        return []
    errors = None
    if preset is not None and rng is not None:
        errors = installation_errors(len(specs), preset, rng)
    return install_array(specs, machine, travel=travel, errors=errors).to_gauges()


def installation_errors(count: int, preset: ErrorPreset, rng: np.random.Generator
                        ) -> np.ndarray:
    """The preset's installation errors of ``count`` stands, drawn from ``rng`` stand by
    stand (position, then tilt): shape ``(count, 2, 3)``, the stand's position error (mm)
    and the rotation vector (rad) that tilts its measuring axis."""
    draws = [[rng.normal(0.0, preset.gauge_position, 3), rng.normal(0.0, preset.gauge_tilt, 3)]
             for _ in range(count)]
    return np.array(draws, dtype=float).reshape(count, 2, 3)


def install_array(
    specs: tuple[GaugeSpec, ...] | list[GaugeSpec],
    machine: MachineParams,
    *,
    travel: float | None = None,
    errors: np.ndarray | None = None,
) -> GaugeArray:
    """:func:`install` for a batch of machines: the gauges of ``specs`` aimed at their targets
    on every machine of ``machine``, moved by installation ``errors`` (shape
    ``(*batch, G, 2, 3)``, see :func:`installation_errors`) when given.  ``travel``:
    default the machine design's gauge travel."""
    travel = machine.design.gauge_travel if travel is None else travel
    specs = list(specs)
    origin, direction = ideal_rays(specs, machine, travel)
    direction = np.broadcast_to(direction, origin.shape)
    if errors is not None:
        errors = np.asarray(errors, dtype=float)
        origin = origin + errors[..., 0, :]
        direction = direction + cross(errors[..., 1, :], direction)
        direction = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    axis = np.array([s.axis for s in specs], dtype=np.intp)
    # The reading runs along the world axis, whichever side the stand is on.
    sign = np.sign(direction[..., np.arange(len(specs)), axis])
    return GaugeArray(origin=origin, direction=direction, sign=sign, travel=float(travel),
                      zero=travel / 2, leg=[s.leg for s in specs], axis=axis,
                      at=[s.at for s in specs], part=[s.part for s in specs])


@overload
def zero_gauges(gauges: GaugeArray, t_at_zero: np.ndarray) -> GaugeArray: ...
@overload
def zero_gauges(gauges: list[Gauge], t_at_zero: np.ndarray) -> list[Gauge]: ...
def zero_gauges(gauges: GaugeArray | list[Gauge], t_at_zero: np.ndarray
                ) -> GaugeArray | list[Gauge]:
    """Set up each gauge at the Zero posture as a technician does: slide it in its holder
    until the plunger sits at mid-travel, then zero the dial there.

    ``t_at_zero`` are the ray distances measured at Zero before the adjustment; a gauge
    whose ray misses its target (NaN) cannot be set up and raises ``ValueError``.  The
    result has the type of ``gauges`` (a list of one machine's, or a :class:`GaugeArray`).
    """
    if isinstance(gauges, GaugeArray):
        return gauges.zeroed(t_at_zero)
    return GaugeArray.of(gauges).zeroed(t_at_zero).to_gauges()


def _boxes(
    a: np.ndarray, c: np.ndarray, legs: np.ndarray, bars: np.ndarray, design: MachineDesign
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bar boxes from the joint centres ``a`` (carriage) and ``c`` (platform) of their legs,
    shaped as ``design`` says."""
    r_axis = R_LEG[legs][..., :, 2]
    v = c - a
    length = np.sqrt(dot(v, v))
    along = v / length[..., None]
    hinge = cross(r_axis, along)
    hinge /= np.sqrt(dot(hinge, hinge))[..., None]
    normal = cross(along, hinge)
    rot = np.stack([along, hinge, normal], axis=-1)
    half = np.stack([length / 2 - design.bar_clearance,
                     *(np.full_like(length, s / 2) for s in design.bar_section)], axis=-1)
    centre = (a + c) / 2 + (bars * design.d / 2)[..., None] * r_axis
    return centre, rot, half


def to_box_frame(rot: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``rot^T @ vector`` over the last axes, broadcast: a world vector in a box's frame.

    Written out: on broadcast batches (rays against every box of thousands of machines)
    this is several times faster than ``einsum``, and every element is summed in the same
    order whatever the batch."""
    rot, vector = np.asarray(rot), np.asarray(vector)
    return (rot[..., 0, :] * vector[..., 0, None] + rot[..., 1, :] * vector[..., 1, None]
            + rot[..., 2, :] * vector[..., 2, None])


def ray_box_interval(
    origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, rot: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where the line ``origin + t * direction`` enters and leaves a box (slab method);
    ``t_in > t_out`` when it misses.  Broadcast over leading dimensions."""
    origin, direction = np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)
    centre, rot, half = (np.asarray(a, dtype=float) for a in (centre, rot, half))
    shape = np.broadcast_shapes(origin.shape[:-1], direction.shape[:-1], centre.shape[:-1],
                                rot.shape[:-2], half.shape[:-1])
    # Coordinates first, each a contiguous array of the full shape: numpy then runs every
    # operation below as one long loop instead of one loop per three numbers (rays
    # against every box of thousands of machines is ~10x faster).  Same arithmetic, in
    # the same order, as to_box_frame.
    v = _components(origin - centre, shape)
    d = _components(direction, shape)
    r = np.ascontiguousarray(np.broadcast_to(np.moveaxis(rot, (-2, -1), (0, 1)), (3, 3, *shape)))
    h = _components(half, shape)
    t_in = t_out = None
    for i in range(3):
        o_i = r[0, i] * v[0] + r[1, i] * v[1] + r[2, i] * v[2]
        d_i = r[0, i] * d[0] + r[1, i] * d[1] + r[2, i] * d[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h[i] - o_i) / d_i
            t2 = (h[i] - o_i) / d_i
        # A ray parallel to a slab is inside it everywhere or nowhere.
        inside = np.abs(o_i) <= h[i]
        parallel = d_i == 0
        lo = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        hi = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        t_in = lo if t_in is None else np.maximum(t_in, lo)
        t_out = hi if t_out is None else np.minimum(t_out, hi)
    return t_in, t_out  # type: ignore[return-value]


def _components(vector: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The three coordinates of ``vector`` (``(..., 3)``) as one contiguous array
    ``(3, *shape)``."""
    return np.ascontiguousarray(np.broadcast_to(np.moveaxis(vector, -1, 0), (3, *shape)))


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
    local = to_box_frame(rot, point - centre)
    ratio = np.abs(local) / half
    touched = np.argmax(ratio, axis=-1)
    inner = np.abs(local) <= half - margin
    ok = np.all(inner | (np.arange(3) == touched[..., None]), axis=-1)
    return ok if face is None else ok & (touched == face)


def collision_boxes(
    machine: MachineParams, rho: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every moving box, in the order of :data:`BOX_NAMES`: centres ``(..., 13, 3)``,
    rotations ``(..., 13, 3, 3)``, half extents ``(..., 13, 3)``."""
    legs = np.repeat(np.arange(3), 2)
    bars = np.tile([1, -1], 3)
    a = carriage_points(machine, rho)
    c = platform_points(machine, p)
    design = machine.design
    centre, rot, half = _boxes(a[..., legs, :], c[..., legs, :], legs, bars, design)
    theta, _ = leg_angles(machine, rho, p)
    cos, sin = np.cos(theta), np.sin(theta)
    zeros, ones = np.zeros_like(theta), np.ones_like(theta)
    rz = np.stack([np.stack([cos, -sin, zeros], -1), np.stack([sin, cos, zeros], -1),
                   np.stack([zeros, zeros, ones], -1)], -2)
    coupler_rot = R_LEG @ rz
    shape = (*np.shape(theta)[:-1], 3, 3)
    platform = _platform_box(np.asarray(p)[..., None, :], design)
    carriages = _carriage_boxes(a, np.arange(3), design)
    centres = np.concatenate([centre, c, platform[0], carriages[0]], axis=-2)
    rots = np.concatenate([rot, coupler_rot, platform[1], carriages[1]], axis=-3)
    halves = np.concatenate([
        half, np.broadcast_to(np.array(design.short_link_size) / 2, shape), platform[2],
        carriages[2],
    ], axis=-2)
    return centres, rots, halves


#: Names of the moving boxes (the simulator's link names): the bars, the couplers, the
#: platform and the carriages.
BOX_NAMES: tuple[str, ...] = tuple(
    [f"{leg}_{bar}" for leg in LEG_NAMES for bar in ("bar1", "bar2")]
    + [f"{leg}_coupler" for leg in LEG_NAMES] + ["platform"]
    + [f"{leg}_carriage" for leg in LEG_NAMES]
)
PLATFORM_BOX: int = BOX_NAMES.index("platform")
#: Index of the x leg's carriage; the y and z legs' follow.
CARRIAGE_BOX: int = BOX_NAMES.index("x_carriage")


def _pick(values: np.ndarray, index: np.ndarray, tail: int) -> np.ndarray:
    """``values[..., index, :, ...]`` with a different ``index`` per leading element:
    ``values`` of shape ``(..., boxes, *tail)`` (``tail`` trailing axes) and ``index``
    ``(..., G)``, broadcast against the leading dimensions, give ``(..., G, *tail)``."""
    index = index.reshape(*index.shape, *(1,) * tail)
    return np.take_along_axis(values, index, axis=-1 - tail)


def exact_ray_distances(
    machine: MachineParams, gauges: GaugeArray | Sequence[Gauge], rho: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Exact tip distances ``t`` of every gauge, shape ``(*batch, *postures, G)`` for
    ``rho`` of shape ``(*batch, *postures, 3)`` and gauges of batch shape ``batch`` (or one
    gauge set, shared by every machine).

    NaN when the ray misses the target's flat face, or when another part lies on the ray
    before the target within the window a gauge can see (``-RAY_BACKOFF`` to
    ``travel + RAY_BACKOFF``).  A target behind the tip (``t < 0``) is an overtravel
    whatever else is on the ray: it presses the gauge.  ``boxes``: the
    :func:`collision_boxes` at ``rho`` when already computed.
    """
    rho = np.asarray(rho, dtype=float)
    centre, rot, half = boxes or collision_boxes(machine, rho, direct(machine, rho))
    g = as_gauge_array(gauges).for_postures(centre.ndim - 2)
    t_in, t_out = ray_box_interval(
        g.origin[..., None, :], g.direction[..., None, :], centre[..., None, :, :],
        rot[..., None, :, :, :], half[..., None, :, :],
    )  # (..., gauges, boxes)
    target = g.target
    t_in_target = _pick(t_in, target[..., None], 0)[..., 0]
    t_out_target = _pick(t_out, target[..., None], 0)[..., 0]
    t = np.where(t_out_target >= t_in_target, t_in_target, np.nan)
    hit = g.origin + np.nan_to_num(t)[..., None] * g.direction
    t = np.where(on_flat_face(hit, *exact_target_boxes(g, (centre, rot, half)), face=g.face),
                 t, np.nan)
    others = np.arange(len(BOX_NAMES)) != target[..., None]
    reach = g.travel + RAY_BACKOFF
    in_window = (t_out >= -RAY_BACKOFF) & (t_in <= t_out) & (t_in < t[..., None])
    occluded = np.any(in_window & others, axis=-1) & (t >= 0)
    return np.where(occluded | (t > reach), np.nan, t)


def exact_target_boxes(
    gauges: GaugeArray | Sequence[Gauge], boxes: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box of every gauge's target among the :func:`collision_boxes` ``boxes``:
    centres ``(..., G, 3)``, rotations ``(..., G, 3, 3)``, half extents ``(..., G, 3)``."""
    centre, rot, half = boxes
    target = as_gauge_array(gauges).for_postures(centre.ndim - 2).target
    return _pick(centre, target, 1), _pick(rot, target, 2), _pick(half, target, 1)


def pressed_past_travel(
    gauges: GaugeArray | Sequence[Gauge], centre: np.ndarray, rot: np.ndarray,
    half: np.ndarray,
) -> np.ndarray:
    """Whether each gauge's target presses it past its travel: the target's box, grown by
    the body radius, meets the gauge axis behind the fully pushed-in tip (``t < 0``) and
    in front of the stand's end.  The boxes are :func:`exact_target_boxes`, ``(..., G,
    ...)``; the result has shape ``(..., G)``."""
    g = as_gauge_array(gauges).for_postures(np.ndim(centre) - 2)
    # The body is a cylinder around the gauge axis: grow the box across the axis only.
    along = to_box_frame(rot, g.direction)
    grown = half + GAUGE_BODY_RADIUS * np.sqrt(np.clip(1 - along**2, 0.0, 1.0))
    t_in, t_out = ray_box_interval(g.origin, g.direction, centre, rot, grown)
    return (t_in <= t_out) & (t_in < 0) & (t_out > -STAND_LENGTH)


def status_of(gauges: GaugeArray | Sequence[Gauge], t: np.ndarray) -> np.ndarray:
    """Status codes for ray distances ``t`` of shape ``(*batch, *postures, G)`` (NaN means
    the ray missed the target)."""
    travel = as_gauge_array(gauges).for_postures(np.ndim(t) - 1).travel
    status = np.full(np.shape(t), Status.VALID, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        status[t > travel] = Status.NO_CONTACT
        status[t < 0] = Status.OVERTRAVEL
    status[np.isnan(t)] = Status.MISSED
    return status


def readings_from_distances(gauges: GaugeArray | Sequence[Gauge], t: np.ndarray
                            ) -> np.ndarray:
    """Ideal readings (mm) from ray distances; NaN where the gauge is not in contact."""
    return np.where(status_of(gauges, t) == Status.VALID, _reading(gauges, t), np.nan)


def _reading(gauges: GaugeArray | Sequence[Gauge], t: np.ndarray) -> np.ndarray:
    """``sign * (t - zero)`` of every gauge, whatever its status."""
    g = as_gauge_array(gauges).for_postures(np.ndim(t) - 1)
    return g.sign * (t - g.zero)


def exact_readings(machine: MachineParams, gauges: GaugeArray | Sequence[Gauge],
                   rho: np.ndarray) -> np.ndarray:
    """Ideal (noise-free, unquantised) readings of the exact model; NaN if not valid."""
    return readings_from_distances(gauges, exact_ray_distances(machine, gauges, rho))


def installed_on(machine: MachineParams, gauges: list[Gauge]) -> list[Gauge]:
    """The gauges set up and zeroed by the exact model at the Zero posture of ``machine``."""
    return zero_gauges(gauges, exact_ray_distances(machine, gauges, np.zeros(3)))


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
        return self.applied(readings, self.draws(rng, np.shape(readings)))

    @staticmethod
    def draws(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Standard normal draws for readings of ``shape``, as :meth:`apply` takes them."""
        return rng.normal(0.0, 1.0, shape)

    def applied(self, readings: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """:meth:`apply` with the standard normal ``draws`` given: a batch of machines draws
        from one stream per machine."""
        noisy = np.asarray(readings, dtype=float) + draws * self.sigma
        if self.resolution > 0:
            # A dial shows a multiple of its step: 1.14, not 114 * 0.01 = 1.1400000000000001
            # (rounding to 12 decimals gives the double nearest the shown decimal, far
            # below any step a gauge has).
            noisy = np.round(np.round(noisy / self.resolution) * self.resolution, 12)
        return noisy

    @property
    def effective_sigma(self) -> float:
        """Standard deviation of one reading: noise plus uniform quantisation error."""
        return float(np.hypot(self.sigma, self.resolution / np.sqrt(12)))
