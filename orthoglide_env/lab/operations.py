"""The lab: what a technician can do around the machine, and what each thing costs.

One place for the facts of the calibration lab:

* :data:`TIME`: the seconds every operation takes (the time table);
* :func:`slot_catalogue`: where a gauge stand can be mounted on a design's machine (the
  lab's slot catalogue), :data:`SLOTS` the prototype's;
* :class:`Op`: the operations of the lab env's action;
* the laser tracker's specification.

The numbers are those a lab would recognise for a small prototype; change them here and
every env, agent and benchmark follows.

======================  ========  ==========================================================
operation               seconds   why
======================  ========  ==========================================================
drive                   |drho|/20 carriages move together at a careful 20 mm/s
settle and read         5         the machine settles, the operator reads the dials
lift / engage a gauge   3         one flick of the plunger's lever
re-mount a stand        120       loosen the magnetic base, move it, aim at the bar at the
                                  Zero posture (the machine drives there first), slide the
                                  gauge to mid-travel, zero the dial
tracker point           3         the tracker's averaged reading of the settled reflector
length reference        60        on top of a re-mount at a reference slot: wipe the gauge
                                  block, hold it to the platform's face (gloved: a hand
                                  warms it), zero the dial on it, take it away
overtravel              120       an engaged gauge pushed past its travel: check it,
                                  re-install and re-zero it (it reads nothing until then)
interferometer set-up   600       (``align``, a lab with the interferometer) mount the
                                  retroreflector on a carriage, align the beam with its
                                  drive, zero the count at Zero; assumption: 20-40 min on a
                                  machine tool, less on a 160 mm drive with a swivel mirror
interferometer soak     600       before the first set-up: the material sensor settles
                                  (at least 10 min, Agilent Laser and Optics User's Manual,
                                  ch. 12)
interferometer target   2         on top of a move's settle and read while it is set up:
                                  the dwell it averages over; assumption: 2-4 s per
                                  ISO 230-2 target
ballbar set-up          300       (``pivot``, a lab with the ballbar) drive to the centre,
                                  fix the centre pivot's magnetic mount under the tool cup,
                                  centre it, fit the bar of the chosen length; assumption:
                                  a whole ISO 230-4 test with a QC20-W is sold as about
                                  10-15 minutes, the set-up a part of it
step-gauge set-up       300       (``place``, a lab with the step gauge) drive to face 0,
                                  lay the gauge along the axis on its stand, square it,
                                  fix the probe under the platform and zero it on face 0;
                                  assumption: as a ballbar's set-up, the gauge's stand
                                  positioning it (KOBA-step: "positioning guaranteed by
                                  multipurpose accessories"); kept in the room: no soak
step-gauge face         2         on top of a move's settle and read while it is set up:
                                  the probe's dwell on the face; assumption
======================  ========  ==========================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from functools import lru_cache
from types import SimpleNamespace

import numpy as np

from orthoglide_env.instruments.slots import PAPER_LAYOUT, GaugeSpec
from orthoglide_env.model.design import PROTOTYPE, MachineDesign


@dataclass(frozen=True)
class TimeTable:
    """Seconds of every lab operation (see the module's table)."""

    drive_speed_mm_s: float = 20.0
    settle_and_read_s: float = 5.0
    lift_s: float = 3.0
    remount_s: float = 120.0
    tracker_point_s: float = 3.0
    overtravel_s: float = 120.0
    reference_s: float = 60.0
    interferometer_setup_s: float = 600.0
    interferometer_soak_s: float = 600.0
    interferometer_target_s: float = 2.0
    ballbar_setup_s: float = 300.0
    step_gauge_setup_s: float = 300.0
    step_gauge_face_s: float = 2.0

    def move(self, start: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Seconds to drive from ``start`` to ``target`` (axes together) and settle; shapes
        ``(..., 3)``, one time per leading index."""
        travel = np.max(np.abs(np.asarray(target, float) - np.asarray(start, float)), axis=-1)
        return travel / self.drive_speed_mm_s + self.settle_and_read_s


TIME = TimeTable()
#: The lab time an experiment has unless told otherwise (s): an hour, the comparison's
#: equal budget for every agent.
DEFAULT_BUDGET_S: float = 3600.0


@lru_cache(maxsize=8)
def slot_catalogue(design: MachineDesign, reference: bool = False) -> tuple[GaugeSpec, ...]:
    """The slot catalogue of a design (kinds of target in
    :mod:`orthoglide_env.instruments.slots`):

    * every bar (leg), both measuring axes across it, at every place of the design's
      ``slot_positions`` (fractions from the platform end; closer to either end the tip
      leaves the bar's flat face as the leg turns) (``x-leg/y@0.5``);
    * every carriage, both measuring axes across its drive (``x-carriage/y``);
    * the platform's three faces (``platform/x``);
    * with ``reference`` (a lab that has the gauge block), the same faces read against it
      (``reference/x``).

    The bar slots come first, in their historical order, so their indices are stable.  A
    lab's slot indices are its design's catalogue (``settings.slots``, an env's ``slots``);
    made once per design."""
    across = [(leg, axis) for leg in range(3) for axis in range(3) if axis != leg]
    return (tuple(GaugeSpec(leg, axis, at) for leg, axis in across for at in design.slot_positions)
            + tuple(GaugeSpec.carriage(leg, axis) for leg, axis in across)
            + tuple(GaugeSpec.platform(axis) for axis in range(3))
            + tuple(GaugeSpec.reference(axis) for axis in range(3) if reference))


#: The prototype's slot catalogue (the lab's slot indices on the prototype).
SLOTS: tuple[GaugeSpec, ...] = slot_catalogue(PROTOTYPE)
SLOT_NAMES: tuple[str, ...] = tuple(s.slot for s in SLOTS)


def slot_index(name_or_spec: str | GaugeSpec, *, design: MachineDesign,
               reference: bool = False) -> int:
    """Index in the slot catalogue of ``design`` (the prototype's is :data:`SLOTS`; with
    ``reference`` slots when told) of a slot given by name (``x-leg/y@0.5``,
    ``x-carriage/y``, ``platform/x``, ``reference/x``) or spec."""
    key = name_or_spec if isinstance(name_or_spec, str) else name_or_spec.slot
    names = [s.slot for s in slot_catalogue(design, reference)]
    try:
        return names.index(key)
    except ValueError:
        raise ValueError(f"no slot '{key}'; slots are bars x/y/z with a measuring axis across "
                         f"them at {design.slot_positions} (e.g. '{names[0]}'), "
                         "carriages with an axis across their drive (e.g. 'x-carriage/y'), "
                         "platform faces (e.g. 'platform/x') and, in a lab with the gauge "
                         "block, reference faces (e.g. 'reference/x')") from None


#: The stands of the paper's experiment, mounted at the start of an episode (their indices
#: in the prototype's catalogue).
PAPER_SLOTS: tuple[int, ...] = tuple(slot_index(s, design=PROTOTYPE) for s in PAPER_LAYOUT)

#: Laser tracker: repeatability of a coordinate (mm), and how its station is placed
#: relative to the machine (unknown to the lab: 6 nuisance parameters): any rotation,
#: and a position about two metres off.
TRACKER_SIGMA: float = 0.005
TRACKER_DISTANCE: float = 2000.0


class Op(IntEnum):
    """Operations of the lab env's action."""

    MOVE = 0  # drive to ``rho``, settle, read every engaged gauge (and the tracker)
    LIFT = 1  # lift gauge ``stand``'s plunger: it reads nothing and cannot be pressed
    ENGAGE = 2  # let it down on its bar again (same zero: the stand did not move)
    REMOUNT = 3  # move stand ``stand`` to ``slot`` (at Zero), new installation, new zero
    STOP = 4  # the experiment is over
    ALIGN = 5  # set the interferometer up along drive ``axis`` (``OrthoglideLab-v1``)
    PIVOT = 6  # set the ballbar's pivot at the TCP of ``rho``, bar ``bar`` (``-v2``)
    PLACE = 7  # lay the step gauge along ``axis``, face 0 at the TCP of ``rho`` (``-v3``)


#: The codes of :class:`Op` as plain ints (``CODE.MOVE``), to compare arrays of codes
#: with: numpy compares an array with an IntEnum member several times slower than with an
#: int (Python 3.11's enum class answers numpy's look-ups of the array protocols in
#: Python), and a lab's step makes dozens of such masks.
CODE = SimpleNamespace(**{op.name: int(op) for op in Op})

#: The operations of ``OrthoglideLab-v0``'s action (every one before ``ALIGN``).
V0_OPS: int = int(Op.ALIGN)
#: Those of ``OrthoglideLab-v1``'s (every one before ``PIVOT``).
V1_OPS: int = int(Op.PIVOT)
#: Those of ``OrthoglideLab-v2``'s (every one before ``PLACE``).
V2_OPS: int = int(Op.PLACE)


OP_NAMES: tuple[str, ...] = tuple(op.name.lower() for op in Op)

