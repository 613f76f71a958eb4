"""``tracker``: the baseline a lab with money picks: a laser tracker on the platform.

Lifts every gauge (nothing can then be pressed), visits a 3 x 3 x 3 grid of postures
spread over the joint cube in a serpentine order (short drives), reads the reflector at
each, and stops.  The tracker's frame is unknown to the estimator, which fits it.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from calibrators.agents.base import PlannedAgent, action, register
from orthoglide_env.lab.operations import Op

#: Grid levels of each joint (mm): the joint range less 10 mm at either end, which keeps
#: clear of the near-singular (60, 60, 60) corner where some machines cannot assemble.
LEVELS: tuple[float, ...] = (-90.0, -20.0, 50.0)


def serpentine_grid(levels: tuple[float, ...] = LEVELS) -> np.ndarray:
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

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        super().reset(env, observation, rng)
        self.plan = [action(Op.LIFT, stand=k) for k, e in enumerate(observation["engaged"]) if e]
        self.plan += [action(Op.MOVE, rho) for rho in serpentine_grid()]
        self.plan.append(action(Op.STOP))
