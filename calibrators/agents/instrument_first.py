"""A standard procedure with an instrument, then the gauges with the time left.

The reference procedures a lab follows (``iso230-2``, ``ballbar``) read their instrument
by a fixed programme, the same on every machine, and leave the rest of the budget to
:data:`GAUGES`, which plans the gauges' experiment from where the programme left the
lab.  A subclass says which instruments it needs (``needs_instruments``) and writes its
programme (:meth:`InstrumentFirst.programme`)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from calibrators.agents.base import Agent, action
from orthoglide_env.lab.operations import Op

#: The agent whose experiment follows the programme, with the time left.
GAUGES: str = "active"


def back_to_the_gauges(stands: int) -> list[dict[str, Any]]:
    """The programme's last actions: the instrument off, at Zero, every plunger down.
    Any operation but a move takes a bar or a probe off, and the way back to Zero would
    pull a bar out or leave a step gauge's faces, so a lift of the first stand comes
    first."""
    return ([action(Op.LIFT, stand=0), action(Op.MOVE, np.zeros(3))]
            + [action(Op.ENGAGE, stand=k) for k in range(stands)])


class InstrumentFirst(Agent):
    """Play :meth:`programme`'s actions, then :attr:`gauges`'s."""

    #: The agent that plays the gauges' part (a written plan takes one that decides it
    #: at the start: :mod:`calibrators.workflow.plan`).
    gauges: str = GAUGES

    def programme(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        """The fixed programme's actions, from the lab as reset (``self.env`` is set)."""
        raise NotImplementedError

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        super().reset(env, observation, rng)
        owned = list(getattr(self.env, "instruments", ()))
        missing = [n for n in self.needs_instruments if n not in owned]
        if missing:
            raise ValueError(f"agent '{self.name}' needs a lab with the {missing[0]} "
                             f"(instruments {owned})")
        from calibrators.agents.names import get_agent  # (names imports the subclasses)
        self.queue = self.programme(observation)
        self.inner = get_agent(self.gauges)
        # The programme is the procedure's instrument work: the gauges do the rest.
        self.inner.plans_instruments = False
        self.started = False

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        if self.queue:
            return self.queue.pop(0)
        if not self.started:
            self.inner.reset(self.env, observation, self.rng)
            self.started = True
        return self.inner.act(observation, info)
