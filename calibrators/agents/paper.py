"""``paper``: the paper's procedure, as a technician does it.

For each leg in turn: engage that leg's two gauges and lift the other four (so no bar
pushes a gauge past its travel), then Zero -> Max -> Min three times and a last Zero,
reading at every posture (section 4 of the paper).  Then stop.  ``paper-once`` goes
through it once: what the repetitions buy (drift seen by the revisits of Zero, noise
averaged) is the difference.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from calibrators.agents.base import PlannedAgent, action, register
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.kinematics import paper_posture

#: Times each leg's Zero -> Max -> Min is gone through (section 4 of the paper).
REPETITIONS: int = 3


def leg_sequence(leg: int, repetitions: int = REPETITIONS) -> list[str]:
    """The paper's postures for one leg: Zero -> Max -> Min ``repetitions`` times, then
    Zero."""
    name = "XYZ"[leg]
    return [*(("Zero", f"{name}Max", f"{name}Min") * repetitions), "Zero"]


@register
class PaperAgent(PlannedAgent):
    name = "paper"
    repetitions = REPETITIONS

    def make_plan(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        slots = self.env.slots
        legs = tuple(slots[s].leg if s < len(slots) else -1 for s in observation["slot"])
        engaged = tuple(bool(e) for e in observation["engaged"])
        return [dict(a) for a in paper_plan(legs, engaged, self.repetitions, self.env.design)]


@lru_cache(maxsize=64)
def paper_plan(legs: tuple[int, ...], engaged: tuple[bool, ...], repetitions: int,
               design: MachineDesign) -> tuple[dict[str, Any], ...]:
    """The paper's procedure for stands on ``legs`` (-1: none) engaged as ``engaged``, at
    the paper postures of ``design``: the same on every machine of a sweep, so made
    once."""
    current = list(engaged)
    plan: list[dict[str, Any]] = []
    for leg in range(3):
        if leg not in legs:
            raise ValueError(f"the paper's procedure needs a stand on the {'xyz'[leg]} leg")
        for k, g in enumerate(legs):
            want = g == leg
            if g != -1 and current[k] != want:
                plan.append(action(Op.ENGAGE if want else Op.LIFT, stand=k))
                current[k] = want
        plan += [action(Op.MOVE, paper_posture(p, design))
                 for p in leg_sequence(leg, repetitions)]
    plan.append(action(Op.STOP))
    return tuple(plan)


@register
class PaperOnceAgent(PaperAgent):
    """``paper-once``: the paper's procedure gone through once per leg (Zero -> Max -> Min
    -> Zero), beside ``paper``'s three times, to measure what the repetitions buy."""

    name = "paper-once"
    repetitions = 1
