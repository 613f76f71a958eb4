"""The gauge slots: where a gauge can go, what it touches there, and how a slot is named.

A slot (:class:`GaugeSpec`) is a target part, a leg, a world measuring axis and, on a
bar, a place along it.  Targets (:class:`Part`), every one a flat box face (a ray
against a box face is exact to round-off):

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
* the **length reference** (``reference/x``): a platform gauge set up against a gauge
  block (:data:`~orthoglide_env.world.table.REFERENCE`).  At Zero the block is held to
  the platform's face and the dial zeroed on the block's far face; the block is then taken
  away, so the stand stands one block length further back and reads the bare face once the
  platform has come that far toward it.  Its readings at Zero are through the block, every
  other one on the face: the difference measures the platform's travel against the
  block's length, which is what a drive's scale error changes and no gauge on a leg sees.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from orthoglide_env.model.boxes import CARRIAGE_BOX, PLATFORM_BOX
from orthoglide_env.model.errors import AXIS_NAMES, LEG_NAMES


class Part(IntEnum):
    """What a gauge touches."""

    BAR = 0  # a leg's parallelogram bar
    CARRIAGE = 1  # a leg's carriage (drive block carrying R1)
    PLATFORM = 2  # a face of the platform
    REFERENCE = 3  # a face of the platform, zeroed against the gauge block at Zero


def on_platform(part: np.ndarray | int) -> np.ndarray:
    """Whether a gauge of ``part`` touches a platform face (a platform or reference gauge)."""
    part = np.asarray(part)
    # Plain ints: numpy compares an array with an IntEnum member several times slower.
    return (part == int(Part.PLATFORM)) | (part == int(Part.REFERENCE))


#: The leg of a platform gauge: it has none.
NO_LEG: int = -1
#: A platform gauge touches its face this far (mm) off the face's centre, toward the
#: negative of both other axes (see the module docstring).
PLATFORM_AIM: float = 10.0


def face_of(part: np.ndarray | int, leg: np.ndarray | int, axis: np.ndarray | int
            ) -> np.ndarray:
    """The axis of its target's box whose face a gauge touches: a bar's and a carriage's
    box lie in the leg frame (the world axis after the leg's is its local Y: 1, the other
    local Z: 2), the platform's in the world frame (the measuring axis)."""
    local = np.where(np.asarray(axis) == (np.asarray(leg) + 1) % 3, 1, 2)
    return np.where(on_platform(part), axis, local)


def target_index(part: np.ndarray | int, leg: np.ndarray | int, face: np.ndarray | int
                 ) -> np.ndarray:
    """Index in :data:`BOX_NAMES` of the box a gauge touches: the bar at +d/2 along local
    Z (measured along local Y, from the side) or the one at -d/2 (along local Z, from
    below), the leg's carriage, or the platform."""
    part, leg = np.asarray(part), np.asarray(leg)
    bar = 2 * leg + (np.asarray(face) == 2)
    return np.where(part == int(Part.BAR), bar,
                    np.where(part == int(Part.CARRIAGE), CARRIAGE_BOX + leg, PLATFORM_BOX))


@dataclass(frozen=True)
class GaugeSpec:
    """Where a gauge goes, nominally: what it touches (``part``), which leg, which world
    axis it measures along, where along the leg.

    ``at`` is the fraction of the leg from the platform end (0) to the carriage end (1) at
    the Zero posture; the paper's gauges sit in the middle (0.5).  A carriage or platform
    gauge has one place per face (``at`` stays 0.5); a platform gauge has no leg
    (:data:`NO_LEG`), nor has a reference gauge.  :meth:`carriage`, :meth:`platform` and
    :meth:`reference` make those.
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
        if self.part in (Part.PLATFORM, Part.REFERENCE):
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
        # A gauge is a key of the notebooks' groupings, read by read: its hash is kept
        # (the fields' hash, as the dataclass's own, and the same in every process: no
        # field hashes a string).
        object.__setattr__(self, "_hash", hash((self.leg, self.axis, self.at, self.part)))

    def __hash__(self) -> int:
        return self._hash

    @classmethod
    def carriage(cls, leg: int, axis: int) -> GaugeSpec:
        """A gauge on leg ``leg``'s carriage, measuring along world ``axis`` (across the
        drive)."""
        return cls(leg, axis, part=Part.CARRIAGE)

    @classmethod
    def platform(cls, axis: int) -> GaugeSpec:
        """A gauge on the platform's face normal to world ``axis``."""
        return cls(NO_LEG, axis, part=Part.PLATFORM)

    @classmethod
    def reference(cls, axis: int) -> GaugeSpec:
        """A gauge on the platform's face normal to world ``axis``, zeroed against the
        gauge block (the length reference)."""
        return cls(NO_LEG, axis, part=Part.REFERENCE)

    @property
    def name(self) -> str:
        """``x-leg/y`` (a bar), ``x-carriage/y``, ``platform/x`` or ``reference/x``."""
        axis = AXIS_NAMES[self.axis]
        if self.part == Part.PLATFORM:
            return f"platform/{axis}"
        if self.part == Part.REFERENCE:
            return f"reference/{axis}"
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
PAPER_LAYOUT: tuple[GaugeSpec, ...] = tuple(GaugeSpec(leg, axis) for leg, axis in (
    (0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)))


def layout_from_names(names: list[str]) -> tuple[GaugeSpec, ...]:
    """Parse names such as ``"x-leg/y"``, ``"x/y@0.3"``, ``"x-carriage/y"``,
    ``"platform/x"`` or ``"reference/x"`` into gauge specs."""
    specs = []
    for raw in names:
        body, _, at = raw.partition("@")
        where, _, axis = body.partition("/")
        leg, _, kind = where.partition("-")
        part = {"": Part.BAR, "leg": Part.BAR, "carriage": Part.CARRIAGE}.get(kind)
        if where in ("platform", "reference") and not at:
            leg, part = LEG_NAMES[0], Part[where.upper()]
        if leg not in LEG_NAMES or axis not in AXIS_NAMES or part is None or (
                at and part != Part.BAR):
            raise ValueError(f"bad gauge name '{raw}': expected like 'x-leg/y', 'x/y@0.5', "
                             "'x-carriage/y', 'platform/x' or 'reference/x'")
        axis_index = AXIS_NAMES.index(axis)
        specs.append(GaugeSpec(NO_LEG, axis_index, part=part) if on_platform(part) else GaugeSpec(
            LEG_NAMES.index(leg), axis_index, float(at) if at else 0.5, part))
    return tuple(specs)
