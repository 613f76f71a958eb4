"""``step-gauge``: the step gauge along each world axis, then the gauges.

A lab with a step gauge (``OrthoglideLab-v3``, ``instruments`` with ``step-gauge``) lays it
along each world axis in turn and reads its faces with a probe on the platform, as a
machine tool's positioning along an axis is checked against a step gauge.  The procedure,
the same on every machine:

1. lift every stand's plunger (the gauge's 160 mm would push bar gauges past their
   travel);
2. for each world axis x, y, z: lay the gauge along it through Zero (``place``) with
   face 0 at the back end of the stroke (:func:`start_mm`), zeroing the probe there, then
   :func:`runs_for` runs, each up through every face in reach (:func:`faces_in_reach`)
   and down through them again (both directions: backlash shows as the reversal);
3. back at Zero, let every plunger down again (their zeros were kept) and read them there,
   and hand the rest of the budget to :data:`GAUGES`, which plans the gauges' experiment
   from there (:func:`~calibrators.agents.instrument_first.gauges_down`).

On the world axis through Zero each drive carries its own axis one to one (the x leg's
carriage follows ``x`` exactly where ``y`` and ``z`` are fixed), so the gauge along an
axis reads that drive's lead error over its whole stroke.

A budget shorter than the programme with one run per axis (:func:`least_budget_s`, about
23 minutes on the prototype) is refused before the lab starts, naming that least budget,
as ``iso230-2`` refuses its own: cut at an axis, the programme would leave a drive's lead
error unread and the gauges no time.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from calibrators.agents.base import action, register
from calibrators.agents.instrument_first import GAUGES as GAUGES
from calibrators.agents.instrument_first import InstrumentFirst, back_to_the_gauges
from calibrators.agents.instrument_first import programme_seconds as programme_clock
from orthoglide_env.instruments.step_gauge import face_lengths
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams, within_limits
from orthoglide_env.model.kinematics import inverse

#: Runs in each direction at most (ISO 230-2's five, as ``iso230-2`` takes).
MAX_RUNS: int = 5
#: The share of the budget left to the gauges after the step gauge.  Half: the gauge reads
#: the TCP, which the machine's unknown geometry (errors of a millimetre) moves by
#: micrometres along the stroke as the lead error does, and the gauges' experiment pins
#: that geometry.  (A quarter, as ``iso230-2`` leaves, removed 0.88 of the lead error's
#: variance on two machines under ``lab``; a half, 0.91.)
GAUGE_SHARE: float = 0.5


def start_mm(design: MachineDesign) -> float:
    """Where face 0 lies on each world axis (mm from Zero): at the back end of the drive
    that carries the axis, ``rho_min`` (its pitch table's reference, where the lead error
    is the encoder offset's), so the gauge spans the stroke from there and its set-up's
    zero takes no part of the lead error.  (On the axis through Zero a drive carries its
    own axis one to one.)"""
    return design.rho_min


def face_command(design: MachineDesign, axis: int, face: int) -> np.ndarray:
    """The command (mm) that puts the nominal machine's TCP at ``face`` of the gauge laid
    along world ``axis`` through Zero from :func:`start_mm`."""
    point = np.zeros(3)
    point[axis] = start_mm(design) + face_lengths()[face]
    return inverse(MachineParams(design=design), point)


def faces_in_reach(design: MachineDesign) -> int:
    """How many faces, from face 0 on, the machine reaches on every axis within its
    control limits: the whole gauge on the prototype (its 160 mm are the stroke), fewer
    on a machine of a shorter stroke."""
    count = 0
    while count < len(face_lengths()) and all(
            np.all(within_limits(face_command(design, axis, count), design))
            for axis in range(3)):
        count += 1
    if count < 2:
        raise ValueError(f"a step gauge along an axis through Zero reaches {count} face(s) "
                         f"within the control limits {design.rho_min:g} .. "
                         f"{design.rho_max:g} mm: it needs two")
    return count


def run_faces(design: MachineDesign) -> list[int]:
    """One run after face 0: up through every face in reach, then down through them."""
    count = faces_in_reach(design)
    return [*range(1, count), *range(count - 2, -1, -1)]


@lru_cache(maxsize=64)
def programme_seconds(design: MachineDesign, stands: int, runs: int) -> float:
    """The lab time (s) :func:`gauge_steps` takes from a reset at Zero, charged as the lab
    charges it (:func:`~calibrators.agents.instrument_first.programme_seconds`).  Kept
    per design, stand count and run count: a programme is hundreds of inverse kinematics
    solves, and every episode's :func:`runs_for` asks for the same few."""
    return programme_clock(gauge_steps(stands, design, runs))


def runs_for(budget_s: float, design: MachineDesign, stands: int) -> int:
    """How many runs per axis fit in ``budget_s`` with :data:`GAUGE_SHARE` of it left to
    the gauges, the programme timed by :func:`programme_seconds` (the lab's own charge:
    lifts, set-ups, the way back to Zero and the zeros' reading included): at most
    :data:`MAX_RUNS`, at least one."""
    room = (1 - GAUGE_SHARE) * budget_s
    return max((runs for runs in range(2, MAX_RUNS + 1)
                if programme_seconds(design, stands, runs) <= room), default=1)


def least_budget_s(design: MachineDesign, stands: int) -> float:
    """The shortest budget (s) that holds the programme: one run along each axis."""
    return programme_seconds(design, stands, 1)


def gauge_steps(stands: int, design: MachineDesign, runs: int) -> list[dict[str, Any]]:
    """The procedure's lab actions on the step gauge: lift the ``stands``, and per axis a
    set-up and ``runs`` runs; then back to Zero, every plunger down and read there."""
    steps = [action(Op.LIFT, stand=k) for k in range(stands)]
    for axis in range(3):
        steps.append(action(Op.PLACE, face_command(design, axis, 0), axis=axis))
        for _ in range(runs):
            steps += [action(Op.MOVE, face_command(design, axis, face))
                      for face in run_faces(design)]
    return steps + back_to_the_gauges(stands)


@register
class StepGaugeAgent(InstrumentFirst):
    """The step gauge along each world axis, then :data:`GAUGES` with the time left (see
    the module docstring)."""

    name = "step-gauge"
    needs_instruments = ("step-gauge",)
    least_holds = "a set-up and one run along each of the three axes"

    def least_budget_s(self, design: MachineDesign, stands: int) -> float:
        return least_budget_s(design, stands)

    def programme(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        stands = len(observation["slot"])
        self.runs = runs_for(float(self.env.budget_s) - float(observation["time"][0]),
                             self.env.design, stands)
        return gauge_steps(stands, self.env.design, self.runs)
