"""The length reference read after another agent's experiment: ``AGENT+reference``.

No gauge on a leg sees a drive's scale: a carriage that runs long moves the platform
without turning a bar.  A lab with the gauge block (``reference=True``) can read it: a
stand re-mounted at ``reference/x`` is zeroed against the block held to the platform's
face at Zero, and then reads the bare face when the platform has come the block's length
toward it (:mod:`orthoglide_env.instruments.slots`).  The readings' difference is the
platform's travel less the block's length.

``AGENT+reference`` runs ``AGENT`` with :attr:`ReferenceAfter.reserved_s` of the budget held
back (an agent that plans to the budget, ``optimal`` or ``active``, stops that much
earlier), then this procedure, the same on every machine:

1. lift every stand's plunger but stand 0's (the platform is about to travel 50 mm, which
   would push bar gauges past their travel);
2. for each axis x, y, z: re-mount stand 0 at ``reference/AXIS`` (the zeroing reading at
   Zero is through the block), then read the bare face at :data:`POSTURES` about the
   block's length back along that axis: the plunger at four places of its travel (the
   dial's own error is correlated over its travel: spread, not repeated) and the
   platform across the axis by a few mm (which shows the stand's tilt, whose cosine
   lengthens the block as the ray sees it).

The agent needs a lab with the block: ``compare`` and ``calibrate`` build one for it.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from calibrators.agents.base import Agent, PlannedAgent, action
from orthoglide_env.lab.operations import TIME, Op, slot_index
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.world.table import REFERENCE_LENGTH_MM

#: The name's suffix that adds the procedure to an agent.
REFERENCE_SUFFIX: str = "+reference"
#: Where the bare face is read, about ``-REFERENCE_LENGTH_MM`` along the reference's axis:
#: (along, across, across) offsets in mm.  Along spreads the plunger over 3 of its 10 mm;
#: across slides the tip over the face.
POSTURES: tuple[tuple[float, float, float], ...] = (
    (-1.5, 0.0, 0.0), (-0.5, 4.0, 0.0), (0.5, 0.0, 4.0), (1.5, -4.0, -4.0))


def reference_steps(stands: int, design: MachineDesign) -> list[dict[str, Any]]:
    """The procedure's lab actions (after the agent's experiment, its last step a stop),
    for a lab of ``stands`` stands, every one mounted, on machines of ``design``."""
    steps = [action(Op.LIFT, stand=k) for k in range(1, stands)]
    for axis in range(3):
        slot = slot_index(f"reference/{'xyz'[axis]}", design=design, reference=True)
        steps.append(action(Op.REMOUNT, stand=0, slot=slot))
        for along, *across in POSTURES:
            rho = np.zeros(3)
            rho[axis] = along - REFERENCE_LENGTH_MM
            rho[[k for k in range(3) if k != axis]] = across
            steps.append(action(Op.MOVE, rho))
    return [*steps, action(Op.STOP)]


def reference_seconds(stands: int, design: MachineDesign) -> float:
    """What :func:`reference_steps` costs at most by the time table: from the farthest
    corner of ``design``'s travel, every lift and move as long as it can be."""
    far = float(TIME.move(np.full(3, design.rho_min), np.full(3, design.rho_max)))
    seconds = (stands - 1) * TIME.lift_s
    for _ in range(3):
        seconds += far + TIME.remount_s + TIME.reference_s
        seconds += float(TIME.move(np.zeros(3), np.full(3, -REFERENCE_LENGTH_MM - 4)))
        seconds += (len(POSTURES) - 1) * float(TIME.move(np.zeros(3), np.full(3, 8.0)))
    return seconds


class ReferenceAfter(Agent):
    """``inner``'s experiment with :func:`reference_seconds` held back, then the reference
    procedure (see the module docstring)."""

    needs_reference = True

    def __init__(self, inner: Agent) -> None:
        if inner.needs_reference:
            raise ValueError(f"agent '{inner.name}' already reads the length reference")
        self.inner = inner
        self.name = inner.name + REFERENCE_SUFFIX  # type: ignore[misc]
        self.needs_tracker = inner.needs_tracker  # type: ignore[misc]
        self.shares_a_plan = inner.shares_a_plan  # type: ignore[misc]

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        Agent.reset(self, env, observation, rng)
        if not getattr(self.env, "reference", False):
            raise ValueError(f"agent '{self.name}' needs a lab with the gauge block "
                             "(reference=True)")
        stands, design = len(observation["slot"]), self.env.design
        reach = REFERENCE_LENGTH_MM + max(abs(p[0]) for p in POSTURES)
        if design.rho_min > -reach:
            raise ValueError(f"agent '{self.name}': the carriages of this design reach "
                             f"{-design.rho_min:g} mm back from Zero, the reference needs "
                             f"{reach:g} mm")
        self.inner.reserved_s = reference_seconds(stands, design)
        self.inner.reset(env, observation, rng)
        self.queue: list[dict[str, Any]] | None = None
        self.stands, self.design = stands, design

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        if self.queue is None:
            step = self.inner.act(observation, info)
            if int(step["op"]) != Op.STOP:
                return step
            self.queue = reference_steps(self.stands, self.design)
        return self.queue.pop(0)


class PlannedReferenceAfter(ReferenceAfter, PlannedAgent):
    """:class:`ReferenceAfter` of an agent that decides its experiment at reset: the whole
    plan, the procedure included, is known then (``orthoglide plan`` can write it)."""

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        ReferenceAfter.reset(self, env, observation, rng)
        self.plan = self.make_plan(observation)

    def make_plan(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        plan = list(self.inner.plan)  # type: ignore[attr-defined]
        if plan and int(plan[-1]["op"]) == Op.STOP:
            plan.pop()
        return plan + reference_steps(self.stands, self.design)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        return PlannedAgent.act(self, observation, info)


def with_reference(inner: Agent) -> ReferenceAfter:
    """``inner`` followed by the reference procedure."""
    return (PlannedReferenceAfter if isinstance(inner, PlannedAgent) else ReferenceAfter)(inner)
