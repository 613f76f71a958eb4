"""``ballbar``: ISO 230-4's circular tests with the ballbar, then the gauges.

A lab with a ballbar (``OrthoglideLab-v2``, ``instruments`` with ``ballbar``) tests the
machine's contouring in the three coordinate planes.  The procedure, the same on every
machine:

1. lift every stand's plunger (a circle would push bar gauges past their travel);
2. set the pivot up (``pivot``) at :data:`CENTRE_MM` with the :data:`LENGTH_MM` bar (the
   largest whole circle the prototype's workspace holds); then, for each plane XY, YZ,
   ZX about the same pivot (the bar stays in), run the circle anticlockwise and
   clockwise, each through :data:`POINTS` points from a start a little before the
   first (:data:`OVERSHOOT_DEG`: ISO 230-4's overshoot arc, so every point is approached
   in the run's direction); the clockwise run's points lie between the anticlockwise
   run's, so the two also sample the circle twice as finely;
3. back at Zero, let every plunger down again (their zeros were kept) and read them there,
   and hand the rest of the budget to :data:`GAUGES`, which plans the gauges' experiment
   from there (:func:`~calibrators.agents.instrument_first.gauges_down`).

The readings are taken at rest (the bar also reads statically): the time table's settle
per point, where a real test samples on the fly at its feed; the dynamic errors a real
test also shows (servo mismatch, reversal spikes) are not in this lab's model.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibrators.agents.base import action, register
from calibrators.agents.instrument_first import GAUGES as GAUGES
from calibrators.agents.instrument_first import InstrumentFirst, back_to_the_gauges
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import inverse
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM

#: The circles' centre (mm, the TCP's world coordinates): the middle of the prototype's
#: reachable cube (-100 .. +60 mm of each drive about Zero), where a 50 mm circle stays
#: about 10 mm inside every drive's travel.
CENTRE_MM: float = -20.0
#: The bar: the 50 mm radius (a 100 mm circle does not fit the prototype's workspace).
LENGTH_MM: float = 50.0
#: Points per circle and direction (every 15 degrees).
POINTS: int = 24
#: The overshoot arc before the first point of each run (degrees).
OVERSHOOT_DEG: float = 7.5
#: The planes, as the pairs of world axes they span, each run anticlockwise as seen from
#: the third axis' positive side (ISO 230-4's XY, YZ, ZX).
PLANES: tuple[tuple[int, int], ...] = ((0, 1), (1, 2), (2, 0))


def circle_postures(design: MachineDesign, plane: tuple[int, int], clockwise: bool
                    ) -> np.ndarray:
    """The commands (mm, ``(POINTS + 1, 3)``) of one run on the nominal machine of
    ``design``: the overshoot start, then :data:`POINTS` points round the circle in
    ``plane``; a clockwise run's points lie halfway between an anticlockwise run's."""
    step = 2 * np.pi / POINTS
    first = step / 2 if clockwise else 0.0
    sign = -1.0 if clockwise else 1.0
    angles = first + sign * np.concatenate([[-np.radians(OVERSHOOT_DEG)],
                                            step * np.arange(POINTS)])
    points = np.full((len(angles), 3), CENTRE_MM)
    points[:, plane[0]] += LENGTH_MM * np.cos(angles)
    points[:, plane[1]] += LENGTH_MM * np.sin(angles)
    return inverse(MachineParams(design=design), points)


def circle_steps(stands: int, design: MachineDesign) -> list[dict[str, Any]]:
    """The procedure's lab actions on the ballbar: lift the ``stands``, set the pivot up,
    and per plane a run each way; then back to Zero, every plunger down and read there."""
    steps = [action(Op.LIFT, stand=k) for k in range(stands)]
    nominal = MachineParams(design=design)
    centre = inverse(nominal, np.full(3, CENTRE_MM))
    steps.append(action(Op.PIVOT, centre, bar=BALLBAR_LENGTHS_MM.index(LENGTH_MM)))
    # The bar goes in at the first run's overshoot start and stays in through every run:
    # each point lies on the sphere of its length about the pivot (a 15 degree chord
    # leaves it 0.4 mm short of its length, inside its travel).
    for plane in PLANES:
        for clockwise in (False, True):
            steps += [action(Op.MOVE, rho) for rho in circle_postures(design, plane,
                                                                       clockwise)]
    return steps + back_to_the_gauges(stands)


@register
class BallbarAgent(InstrumentFirst):
    """ISO 230-4's circles with the ballbar, then :data:`GAUGES` with the time left (see
    the module docstring)."""

    name = "ballbar"
    needs_instruments = ("ballbar",)

    def programme(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        return circle_steps(len(observation["slot"]), self.env.design)
