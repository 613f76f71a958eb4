"""``tracker``: the baseline a lab with money picks: a laser tracker on the platform.

Lifts every gauge (nothing can then be pressed), visits a 3 x 3 x 3 grid of postures
spread over the joint cube in a serpentine order (short drives), reads the reflector at
each, and stops.  The tracker's frame is unknown to the estimator, which fits it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibrators.agents.base import PlannedAgent, action, register
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign

#: The grid keeps this far (mm) inside the joint range at either end: clear of the
#: near-singular corner (the prototype's (60, 60, 60)) where some machines cannot assemble.
INSET: float = 10.0


def levels_of(design: MachineDesign) -> tuple[float, float, float]:
    """Grid levels of each joint (mm): ``design``'s joint range less :data:`INSET` at either
    end, and its middle (the prototype's: -90, -20, 50)."""
    low, high = design.rho_min + INSET, design.rho_max - INSET
    return low, (low + high) / 2, high


def serpentine_grid(levels: tuple[float, ...]) -> np.ndarray:
    """Every combination of ``levels`` on three joints, each row reversing the last so
    consecutive postures differ in one joint."""
    points = []
    for i, x in enumerate(levels):
        ys = levels if i % 2 == 0 else levels[::-1]
        for j, y in enumerate(ys):
            zs = levels if (i * len(levels) + j) % 2 == 0 else levels[::-1]
            points += [(x, y, z) for z in zs]
    return np.array(points)


@register
class TrackerAgent(PlannedAgent):
    name = "tracker"
    needs_tracker = True

    def make_plan(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        lifts = [action(Op.LIFT, stand=k) for k, e in enumerate(observation["engaged"]) if e]
        moves = [action(Op.MOVE, rho) for rho in serpentine_grid(levels_of(self.env.design))]
        return [*lifts, *moves, action(Op.STOP)]
