"""A policy that chooses among ``active``'s short list: ``active``'s own next operation and
its next best moves by gain per second, as ``active``'s filter (the values read, never the
truth) prices them.

The filtered design view (:class:`~calibrators.planning.active_expert.FilteredDesignLab`)
opens every move where ``active``'s filter lets a dial read: some 1,500 operations, of
which a policy imitating ``active`` matched only 21-34 % on the states it reached itself.
:class:`ShortlistDesignLab` keeps that view's observation, actions and reward but opens
only :data:`SHORTLIST_MOVES` of them, and stop: ``active``'s choice
(:meth:`~calibrators.planning.design_expert.PlanExpert.choose`: a due re-mount, else the
filter's best move, else stop) and the moves of the next highest rates among those the
filter offers.  A policy in it cannot take a move that ``active``'s pricing ranks low, and
what it learns is where to depart from the greedy order.  :class:`LookaheadExpert` labels
where: the move of the short list after which ``active``'s greedy plan, played out to the
budget's end with its readings expected (never their values), leaves the lowest predicted
error.  Its file records
``flicks="shortlist"`` and ``policy:FILE`` narrows its mask the same way
(:class:`ShortlistFilter`, registered in
:data:`~calibrators.agents.policy.FLICK_FILTERS`).  A decision then costs ``active``'s
pricing plus the network's pass.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibrators.agents.policy import FLICK_FILTERS
from calibrators.planning.active_expert import ActiveExpert, FilteredDesignLab
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.search import Planner
from orthoglide_env.envs.lab import OrthoglideLabEnv
from orthoglide_env.lab.design_belief import DesignBelief

#: Moves open to the policy at a decision: ``active``'s choice and the next best by gain
#: per second (assumption: a design choice, the width of the short list; 3 keeps
#: ``active``'s runner-up and third while every one is among the moves its pricing under
#: ``lab`` prices exactly, its world shortlist).
SHORTLIST_MOVES: int = 3


def shortlist_mask(expert: ActiveExpert, belief: DesignBelief,
                   moves: int = SHORTLIST_MOVES) -> np.ndarray:
    """The operations open among ``active``'s short list from ``belief``'s state (bool, one
    per view action): ``expert``'s choice, the ``moves - 1`` other moves of the highest
    positive gain per second that the filter opens (:meth:`ActiveFilter.action_mask
    <calibrators.planning.active_filter.ActiveFilter.action_mask>`), and stop."""
    if moves < 1:
        raise ValueError(f"a short list holds at least 1 move, got {moves}")
    opened = expert.action_mask(belief)
    chosen = expert.choose(belief)
    rate, _ = expert.planner.top_rates(moves)
    n = belief.n_postures
    rate = np.where(opened[:n] & (rate > 0), rate, -np.inf)
    if chosen < n:
        rate[chosen] = -np.inf
    # The highest rates first, ties to the lower index (a stable sort of the negated rates).
    others = [int(p) for p in np.argsort(-rate, kind="stable")[:moves - 1]
              if np.isfinite(rate[p])]
    mask = np.zeros(belief.n_actions, dtype=bool)
    mask[[chosen, *others, belief.n_actions - 1]] = True
    return mask


def played_out(planner: Planner, posture: int) -> float:
    """The criterion (predicted mean-square TCP error after rigid motion) that ``planner``'s
    greedy plan leaves at the budget's end after move ``posture``, on a copy, every reading
    expected with its probability."""
    trial = planner.fork()
    seconds, after, reads = trial._moves()
    trial.move(posture, PricedMoves(np.zeros(len(seconds)), seconds, after, reads))
    trial.expect_readings()
    while trial.greedy_move():
        pass
    return trial._criterion_value()


class LookaheadExpert:
    """The short list's move that plans past the next reading: of the moves
    :func:`shortlist_mask` opens, the one whose greedy play-out (:func:`played_out`)
    leaves the lowest predicted error; ``active``'s choice when it is a re-mount or stop.
    It labels the states of a :class:`ShortlistDesignLab` for imitation, from the view's
    ``active`` expert (its filter: the values read, never the truth)."""

    def __init__(self, expert: ActiveExpert) -> None:
        self.expert = expert

    def choose(self, belief: DesignBelief) -> int:
        chosen = self.expert.choose(belief)
        n = belief.n_postures
        if chosen >= n:
            return chosen
        moves = [int(p) for p in np.flatnonzero(shortlist_mask(self.expert, belief)[:n])]
        if len(moves) == 1:
            return chosen
        # The stable argmin: a tie goes to the move of the lower index.
        return moves[int(np.argmin([played_out(self.expert.planner, p) for p in moves]))]

    def follow(self, action: int, belief: DesignBelief) -> None:
        """Nothing: the view's filter has seen every lab action."""


class ShortlistDesignLab(FilteredDesignLab):
    """The filtered design view whose mask opens ``active``'s short list only
    (:func:`shortlist_mask`); its ``flicks`` is ``"shortlist"``."""

    flicks = "shortlist"

    def action_masks(self) -> np.ndarray:
        """Which actions are open now: :func:`shortlist_mask`."""
        return shortlist_mask(self.expert, self.belief)


class ShortlistFilter:
    """What ``policy:FILE`` of ``flicks="shortlist"`` keeps beside its belief: ``active``'s
    expert (its filter, the values read), whose flicks its moves take and whose short
    list is its mask.  Made from the lab, the view's belief and the lab's first
    observation, as :data:`~calibrators.agents.policy.FLICK_FILTERS` asks."""

    def __init__(self, lab: Any, belief: DesignBelief, observation: dict[str, np.ndarray]
                 ) -> None:
        self.expert = ActiveExpert(lab, belief, observation)

    def action_mask(self, belief: DesignBelief) -> np.ndarray:
        """:func:`shortlist_mask`."""
        return shortlist_mask(self.expert, belief)

    def operations(self, action: int, belief: DesignBelief) -> list[dict[str, object]]:
        """The filter's (:meth:`ActiveFilter.operations
        <calibrators.planning.active_filter.ActiveFilter.operations>`)."""
        return self.expert.filter.operations(action, belief)

    def observe(self, operation: dict[str, object], observation: dict[str, np.ndarray],
                info: dict[str, Any]) -> None:
        """The filter's (:meth:`ActiveFilter.observe
        <calibrators.planning.active_filter.ActiveFilter.observe>`)."""
        self.expert.filter.observe(operation, observation, info)


def shortlist_design_lab_env(reward: str = "mse", per: str = "step", version: int = 0,
                             **kwargs: Any) -> ShortlistDesignLab:
    """``OrthoglideLab-v0`` (``kwargs``: the lab env's) in the filtered design view of
    ``version`` whose mask opens ``active``'s short list (:class:`ShortlistDesignLab`)."""
    return ShortlistDesignLab(OrthoglideLabEnv(**kwargs), reward=reward, per=per,
                              version=version)


FLICK_FILTERS["shortlist"] = ShortlistFilter
