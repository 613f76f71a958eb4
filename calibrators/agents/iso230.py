"""``iso230-2``: the drives measured as ISO 230-2 measures an axis, then the gauges.

A lab with a laser interferometer (``OrthoglideLab-v1``, ``instruments`` with
``interferometer``) measures each drive directly: the retroreflector rides on the
carriage, one actuator moves at a time, and every reading is the carriage's deviation
from its command.  The procedure, the same on every machine:

1. lift every stand's plunger (a drive's whole stroke would push bar gauges past their
   travel);
2. for each drive x, y, z: set the interferometer up along it (``align``, at Zero), then
   :func:`runs_for` bidirectional runs over :data:`TARGETS` targets spread over the
   stroke: each run approaches every target going up, then every target coming down,
   each direction started from a little beyond its end (:data:`OVERSHOOT_MM`) so that
   the first target too is approached in the run's direction (backlash shows as the
   reversal).  The targets are spread unevenly (ISO 230-2 asks for it: equal spacing
   would sample the screw's periodic error at one phase);
3. back at Zero, let every plunger down again (their zeros were kept) and read them there,
   and hand the rest of the budget to :data:`GAUGES`, which plans the gauges' experiment
   from there (:func:`~calibrators.agents.instrument_first.gauges_down`).

ISO 230-2 asks for 5 runs in each direction; an hour cannot hold them on three drives
with the time table's set-ups, so :func:`runs_for` takes as many as leave
:data:`GAUGE_SHARE` of the budget to the gauges (at least one run, at most five).

A budget shorter than the programme with one run per drive (:func:`least_budget_s`, about
49 minutes on the prototype) is refused before the lab starts, naming that least budget: a
lab books the time a whole test of the three drives takes, as a certificate of ISO 230-2
reports every axis it names, rather than cut the test at a drive or leave the gauges no
time.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibrators.agents.base import action, register
from calibrators.agents.instrument_first import GAUGES as GAUGES
from calibrators.agents.instrument_first import InstrumentFirst, gauges_down
from calibrators.agents.instrument_first import programme_seconds as programme_clock
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign

#: Targets per drive: ISO 230-2's at least 5 per metre and 5 in all, and more: about two
#: of the pitch table's 10 mm node spacings apart, which its prior (the lab's lead curve) bridges.
#: (17, one per node, removed no more of the lead error's variance on three machines,
#: 0.91 against 0.90, and left the gauges 6 minutes less of the hour.)
TARGETS: int = 9
#: Runs in each direction the standard asks for.
ISO_RUNS: int = 5
#: The targets keep this far (mm) inside the stroke, and each direction starts this far
#: beyond its first target.
INSET_MM: float = 6.0
OVERSHOOT_MM: float = 3.0
#: The share of the budget left to the gauges after the drives.  An assumption: the
#: geometry still needs the gauges, and a quarter of an hour buys most of what active's
#: first readings buy.
GAUGE_SHARE: float = 0.25


def targets_of(design: MachineDesign) -> np.ndarray:
    """The :data:`TARGETS` targets along a drive of ``design`` (mm, control coordinates):
    spread over the stroke less :data:`INSET_MM` at either end, each inner one moved by
    up to 0.2 of a spacing in a fixed irregular pattern (the fractional parts of
    multiples of the golden ratio), so the spacings differ."""
    low, high = design.rho_min + INSET_MM, design.rho_max - INSET_MM
    base = np.linspace(low, high, TARGETS)
    jitter = (np.arange(TARGETS) * 0.618034) % 1.0 - 0.5
    jitter[[0, -1]] = 0.0
    return base + 0.4 * jitter * (high - low) / (TARGETS - 1)


def run_postures(targets: np.ndarray) -> list[float]:
    """One bidirectional run: below the first target, up through every target, above
    the last, down through every target."""
    return [targets[0] - OVERSHOOT_MM, *targets, targets[-1] + OVERSHOOT_MM,
            *targets[::-1]]


def drive_steps(stands: int, design: MachineDesign, runs: int) -> list[dict[str, Any]]:
    """The procedure's lab actions on the drives: lift the ``stands``, and per drive a
    set-up and ``runs`` runs; then back to Zero, every plunger down and read there."""
    steps = [action(Op.LIFT, stand=k) for k in range(stands)]
    targets = targets_of(design)
    for axis in range(3):
        steps.append(action(Op.ALIGN, axis=axis))
        for _ in range(runs):
            for value in run_postures(targets):
                rho = np.zeros(3)
                rho[axis] = value
                steps.append(action(Op.MOVE, rho))
    steps.append(action(Op.MOVE, np.zeros(3)))
    return steps + gauges_down(stands)


def programme_seconds(design: MachineDesign, stands: int, runs: int) -> float:
    """The lab time (s) :func:`drive_steps` takes from a reset at Zero, charged as the lab
    charges it (:func:`~calibrators.agents.instrument_first.programme_seconds`)."""
    return programme_clock(drive_steps(stands, design, runs))


def runs_for(budget_s: float, design: MachineDesign, stands: int) -> int:
    """How many bidirectional runs per drive fit in ``budget_s`` with :data:`GAUGE_SHARE`
    of it left to the gauges, the programme timed by :func:`programme_seconds` (the lab's
    own charge, lifts and engagements included): at most :data:`ISO_RUNS`, at least one."""
    room = (1 - GAUGE_SHARE) * budget_s
    return max((runs for runs in range(2, ISO_RUNS + 1)
                if programme_seconds(design, stands, runs) <= room), default=1)


def least_budget_s(design: MachineDesign, stands: int) -> float:
    """The shortest budget (s) that holds the programme: one run on each drive."""
    return programme_seconds(design, stands, 1)


@register
class Iso230Agent(InstrumentFirst):
    """The drives by ISO 230-2 with the interferometer, then :data:`GAUGES` with the
    time left (see the module docstring)."""

    name = "iso230-2"
    needs_instruments = ("interferometer",)

    least_holds = ("the laser's soak, a set-up and one ISO 230-2 run on each of the three "
                   "drives")

    def least_budget_s(self, design: MachineDesign, stands: int) -> float:
        return least_budget_s(design, stands)

    def programme(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        left = float(self.env.budget_s) - float(observation["time"][0])
        stands = len(observation["slot"])
        self.runs = runs_for(left, self.env.design, stands)
        return drive_steps(stands, self.env.design, self.runs)
