"""The expert a design-view policy imitates: ``optimal``'s greedy choice from any state.

:class:`PlanExpert` chooses among the operations open in the design view
(:class:`~orthoglide_env.wrappers.DesignLab`) from the nominal model and where each reading
was taken, never the truth nor the values read: the re-mounts of the ``optimal`` plan once
their time has come, else the move of the highest expected fall of the predicted TCP error
per second, the lab world's drift, backlash and indicator curves weighed as ``optimal``
weighs them (:mod:`calibrators.planning.world_terms`), else stop.  Played alone it is the
``optimal`` plan made closed-loop in the lab's clock and stands; it labels any state a
policy reaches, so a policy learns from it by DAgger (``examples/train_masked.py
--imitate``).  It cannot label ``active``'s choices: those rest on the values read (its
filter lets a plunger down where its estimate, not the prior, keeps it safe), which the
view does not observe; :mod:`calibrators.planning.active_expert` keeps that filter beside
the view and labels them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calibrators.agents.optimal import fixed_plan
from calibrators.planning.active_filter import planner_at
from calibrators.planning.pricing import PricedMoves
from orthoglide_env.lab.design_belief import DesignBelief
from orthoglide_env.lab.operations import Op


@dataclass(frozen=True)
class Remount:
    """A re-mount of the ``optimal`` plan: stand ``stand`` to slot ``slot`` once the lab's
    clock reaches ``time_s``."""

    time_s: float
    stand: int
    slot: int


def remount_schedule(lab: Any, belief: DesignBelief) -> tuple[Remount, ...]:
    """The re-mounts of the ``optimal`` plan for the lab ``lab`` (an ``OrthoglideLab-v0``:
    its conditions) from ``belief``'s state as the episode opens (stands, plungers, clock,
    reading sigma, budget, design); the plan is made once per set-up and process
    (seconds)."""
    steps, _ = fixed_plan(tuple(int(s) for s in belief.slots),
                          tuple(bool(e) for e in belief.engaged), belief.sigma,
                          belief.budget_s - belief.time_s, belief.design, lab.conditions,
                          criterion="I")
    return tuple(Remount(belief.time_s + s.time_s, s.stand, s.slot) for s in steps
                 if s.op == Op.REMOUNT)


class PlanExpert:
    """The ``optimal`` planner's greedy choice from any state of the design view: a
    :class:`~calibrators.planning.search.Planner` (world terms included) that follows the
    view's operations as a plan does, each reading counted with its a-priori probability
    (never its value), and chooses the next move as ``optimal`` would from there."""

    def __init__(self, lab: Any, belief: DesignBelief) -> None:
        self.planner = planner_at(lab, belief)
        self.planner.expect_readings()  # the lab reads every stand as the episode opens
        self.remounts = remount_schedule(lab, belief)

    def follow(self, action: int, belief: DesignBelief) -> None:
        """Take in operation ``action`` of the view, done: ``belief`` is the view's after
        it (the lab's clock, its stands)."""
        planner = self.planner
        if action < belief.n_postures:
            seconds, after, reads = planner._moves()
            planner.move(action, PricedMoves(np.zeros(len(seconds)), seconds, after, reads))
            planner.expect_readings()
        elif action < belief.n_actions - 1:
            stand, slot = divmod(action - belief.n_postures, belief.n_slots)
            if belief.slots[stand] == slot and planner.slots[stand] != slot:
                planner.remount(stand, slot)
                planner.expect_readings()
        for stand in np.flatnonzero(belief.faulted):
            if planner.slots[stand] >= 0:
                planner.retire(int(stand))
        planner.time_s = belief.time_s

    def action_mask(self, belief: DesignBelief) -> np.ndarray:
        """The operations open to the expert: the view's (:meth:`DesignBelief.action_mask
        <orthoglide_env.lab.design_belief.DesignBelief.action_mask>`)."""
        return belief.action_mask()

    def choose(self, belief: DesignBelief) -> int:
        """The expert's operation: a due re-mount of the ``optimal`` plan first, else the
        planner's best move among the open ones, else stop."""
        mask = self.action_mask(belief)
        due: dict[int, int] = {}
        for remount in self.remounts:
            if remount.time_s <= belief.time_s:
                due[remount.stand] = remount.slot
        for stand, slot in due.items():
            index = belief.n_postures + stand * belief.n_slots + slot
            if belief.slots[stand] != slot and mask[index]:
                return index
        choice = self.planner.best_move()
        if choice is None:
            return belief.n_actions - 1
        if mask[choice[0]]:
            return int(choice[0])
        # The planner's best is a move the view does not offer (no stand reads there more
        # likely than not): its best among those offered.
        rate = self.planner.affordable_rates(self.planner.priced_moves())
        rate = np.where(mask[:belief.n_postures], rate, -np.inf)
        best = int(np.argmax(rate))
        return best if rate[best] > 0 else belief.n_actions - 1
