"""``random``: random operations within the budget, kept safe by the nominal model.

The floor any designed experiment must beat.  At every step it picks, at random, a move to
a random posture of the joint cube (60 %), lifting or engaging a random stand (20 %), or
re-mounting a random stand on a random free slot (20 %).  It uses what a careful
technician knows, the nominal machine: a move is only made to a posture the nominal model
reaches with every part :data:`~orthoglide_env.lab.slot_table.CLEARANCE` clear of the others
and no engaged gauge pressed within :data:`MARGIN` of its travel, and a gauge is only
engaged where that holds.  An engaged platform gauge allows only postures where it reads
(within its travel of where it was zeroed): past its face the whole platform would run
into it.  It works until the budget runs out.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import gymnasium as gym
import numpy as np

from calibrators.agents.base import Agent, action, register
from orthoglide_env.instruments.dial import pressed_past_travel
from orthoglide_env.instruments.gauges import Gauge
from orthoglide_env.instruments.rays import exact_ray_distances, exact_target_boxes
from orthoglide_env.instruments.slots import on_platform
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.lab.operations import Op, slot_catalogue
from orthoglide_env.lab.slot_table import CLEARANCE
from orthoglide_env.model.boxes import collision_boxes
from orthoglide_env.model.collisions import clearance
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import UnreachableError, direct

#: A posture is safe for an engaged gauge when the nominal tip stays this far (mm) from
#: the end of its travel, and its target this far from pressing it: more than the
#: machine errors move a bar at mid-leg.
MARGIN: float = 2.0
TRIES: int = 50


def is_safe(rho: np.ndarray, slots: list[int], design: MachineDesign) -> bool:
    """Whether the nominal machine of ``design`` reaches ``rho`` with parts apart and the
    gauges at ``slots`` (engaged; indices in the design's slot catalogue) neither pressed
    nor within the margin of being pressed, the platform gauges on their faces within
    their travel."""
    nominal = MachineParams(design=design)
    try:
        p = direct(nominal, rho)
    except UnreachableError:
        return False
    boxes = collision_boxes(nominal, rho, p)
    if clearance(nominal, rho, boxes) < CLEARANCE:
        return False
    if not slots:
        return True
    gauges, platform, travel = _set_up(design, tuple(slots))
    centre, rot, half = exact_target_boxes(gauges, boxes)
    if pressed_past_travel(gauges, centre, rot, half + MARGIN).any():
        return False
    t = exact_ray_distances(nominal, gauges, rho, boxes)
    return not (np.any(t < MARGIN) or np.any(platform & ~(t <= travel)))


@lru_cache(maxsize=256)
def _set_up(design: MachineDesign, slots: tuple[int, ...]
            ) -> tuple[list[Gauge], np.ndarray, np.ndarray]:
    """The gauges at ``slots`` set up on the nominal machine of ``design``, whether each is
    on the platform, and their travels (mm).  The same for every posture tried with those
    gauges engaged, and their set-up cost half of a check: made once per set of slots."""
    nominal = MachineParams(design=design)
    specs = [slot_catalogue(design)[s] for s in slots]
    gauges = installed_on(nominal, install(specs, nominal))
    return (gauges, np.array([on_platform(spec.part) for spec in specs]),
            np.array([g.travel for g in gauges]))


@register
class RandomAgent(Agent):
    name = "random"

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        super().reset(env, observation, rng)
        self.n_slots = len(self.env.slots)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        slots = [int(s) for s in observation["slot"]]
        engaged = [k for k, e in enumerate(observation["engaged"]) if e and slots[k] < self.n_slots]
        choice = self.rng.random()
        design = self.env.design
        if choice < 0.6:
            for _ in range(TRIES):
                rho = self.rng.uniform(design.rho_min, design.rho_max, 3)
                if is_safe(rho, [slots[k] for k in engaged], design):
                    return action(Op.MOVE, rho)
        stand = int(self.rng.integers(len(slots)))
        if choice < 0.8 and slots[stand] < self.n_slots:
            if stand in engaged:
                return action(Op.LIFT, stand=stand)
            if is_safe(observation["joints"], [slots[k] for k in [*engaged, stand]], design):
                return action(Op.ENGAGE, stand=stand)
        free = sorted(set(range(self.n_slots)) - set(slots))
        slot = int(self.rng.choice(free))
        if is_safe(np.zeros(3), [slots[k] for k in engaged if k != stand] + [slot], design):
            return action(Op.REMOUNT, stand=stand, slot=slot)
        return action(Op.LIFT, stand=stand) if slots[stand] < self.n_slots else action(
            Op.MOVE, np.zeros(3))
