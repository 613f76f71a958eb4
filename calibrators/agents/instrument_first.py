"""A standard procedure with an instrument, then the gauges with the time left.

The reference procedures a lab follows (``iso230-2``, ``ballbar``) read their instrument
by a fixed programme, the same on every machine, and leave the rest of the budget to
:data:`GAUGES`, which plans the gauges' experiment from where the programme left the
lab.  A subclass says which instruments it needs (``needs_instruments``), writes its
programme (:meth:`InstrumentFirst.programme`) and, where a budget can be too short for the
programme's least form, names that least budget (:meth:`InstrumentFirst.least_budget_s`):
a shorter one is refused before the lab starts (:meth:`InstrumentFirst.check_budget`)."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from calibrators.agents.base import Agent, action
from orthoglide_env.lab.clock import travel_seconds
from orthoglide_env.lab.operations import TIME, Op
from orthoglide_env.model.design import MachineDesign

#: The agent whose experiment follows the programme, with the time left.
GAUGES: str = "active"


def gauges_down(stands: int) -> list[dict[str, Any]]:
    """The programme's end, at Zero: every plunger down, then a reading there of every
    gauge, their zeros again.  The gauges' part takes in only what the lab shows from its
    start; without its zeros a stand's first reading goes on its zero, which one move
    ahead is worth too little, so the part read the stands of the legs it read first and
    never those of a third (``iso230-2`` under ``lab`` at one hour: a leg unread on 7 of
    50 machines, all of its 30-47 um tail)."""
    return ([action(Op.ENGAGE, stand=k) for k in range(stands)]
            + [action(Op.MOVE, np.zeros(3))])


def back_to_the_gauges(stands: int) -> list[dict[str, Any]]:
    """The programme's last actions: the instrument off, at Zero, every plunger down and
    read (:func:`gauges_down`).  Any operation but a move takes a bar or a probe off, and
    the way back to Zero would pull a bar out or leave a step gauge's faces, so a lift of
    the first stand comes first."""
    return [action(Op.LIFT, stand=0), action(Op.MOVE, np.zeros(3)), *gauges_down(stands)]


def programme_seconds(steps: list[dict[str, Any]]) -> float:
    """The lab time (s) a fixed programme ``steps`` takes from a reset at Zero, charged as
    the lab charges it (:func:`~orthoglide_env.lab.clock.travel_seconds` on the time
    table): each lift and engagement a flick; a move its drive, settle and dwell (the
    interferometer's while one is set up and the move reads it, the probe's while it is on
    a step gauge); an
    interferometer's set-up its drive to Zero, its work and, the first, the soak; a step
    gauge's set-up its drive and work.  One clock for the procedures' run counts and the
    lab's charge: a count summed by hand drifts from it as the programme changes."""
    rho, seconds, aligned, probing = np.zeros(3), 0.0, False, False
    for step in steps:
        op = Op(step["op"])
        if op in (Op.LIFT, Op.ENGAGE):
            # Any operation but a move takes the probe off the step gauge.
            seconds, probing = seconds + TIME.lift_s, False
            continue
        goal = np.zeros(3) if op == Op.ALIGN else np.asarray(step["rho"], dtype=float)
        seconds += float(travel_seconds(np.array([op]), rho[None], goal[None], False,
                                        laser=np.array([aligned and bool(step.get("laser",
                                                                                  1))]),
                                        soak=np.array([not aligned]),
                                        probe=np.array([probing]))[0])
        rho, aligned = goal, aligned or op == Op.ALIGN
        probing = op == Op.PLACE or (probing and op == Op.MOVE)
    return seconds


class InstrumentFirst(Agent):
    """Play :meth:`programme`'s actions, then :attr:`gauges`'s."""

    #: The agent that plays the gauges' part (a written plan takes one that decides it
    #: at the start: :mod:`calibrators.workflow.plan`).
    gauges: str = GAUGES
    #: What :meth:`least_budget_s` holds, in the refusal's words.
    least_holds: ClassVar[str] = ""

    def least_budget_s(self, design: MachineDesign, stands: int) -> float:
        """The shortest budget (s) that holds the programme's least form on ``design``
        with ``stands`` gauge stands; 0 for a programme the lab cuts where the budget
        ends."""
        return 0.0

    def check_budget(self, budget_s: float, design: MachineDesign, stands: int) -> None:
        least = self.least_budget_s(design, stands)
        if budget_s < least:
            raise ValueError(f"agent '{self.name}' needs a budget of at least {least:.1f} s "
                             f"({self.least_holds}), got {budget_s:g} s")

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
        # A lab made without the lab arguments' check (a gym.make of its own) is checked here.
        self.check_budget(float(self.env.budget_s) - float(observation["time"][0]),
                          self.env.design, len(observation["slot"]))
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
