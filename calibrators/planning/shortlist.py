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

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from calibrators.agents.policy import FLICK_FILTERS
from calibrators.planning.active_expert import ActiveExpert, FilteredDesignLab
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.search import Planner
from orthoglide_env.envs.lab import OrthoglideLabEnv
from orthoglide_env.lab.design_belief import COUNT_SCALE, FALL_FLOOR, DesignBelief

#: Moves open to the policy at a decision: ``active``'s choice and the next best by gain
#: per second (assumption: a design choice, the width of the short list; 3 keeps
#: ``active``'s runner-up and third while every one is among the moves its pricing under
#: ``lab`` prices exactly, its world shortlist).
SHORTLIST_MOVES: int = 3
#: Numbers the ranked view observes per listed operation (:func:`ranked_shortlist`).
RANK_FEATURES: int = 8


def listed_moves(expert: ActiveExpert, belief: DesignBelief, moves: int = SHORTLIST_MOVES
                 ) -> tuple[list[int], np.ndarray, PricedMoves]:
    """``active``'s short list from ``belief``'s state, in rank order: ``expert``'s choice
    (a move, a due re-mount or stop) and then the ``moves - 1`` other moves of the highest
    positive gain per second that the filter opens (:meth:`ActiveFilter.action_mask
    <calibrators.planning.active_filter.ActiveFilter.action_mask>`), as view actions; with
    the filter's gains per second (P,) and priced moves (:meth:`Pricer.top_rates
    <calibrators.planning.pricing.Pricer.top_rates>` of ``moves``)."""
    if moves < 1:
        raise ValueError(f"a short list holds at least 1 move, got {moves}")
    opened = expert.action_mask(belief)
    chosen = expert.choose(belief)
    rate, priced = expert.planner.top_rates(moves)
    n = belief.n_postures
    ranked = np.where(opened[:n] & (rate > 0), rate, -np.inf)
    if chosen < n:
        ranked[chosen] = -np.inf
    # The highest rates first, ties to the lower index (a stable sort of the negated rates).
    others = [int(p) for p in np.argsort(-ranked, kind="stable")[:moves - 1]
              if np.isfinite(ranked[p])]
    return [int(chosen), *others], rate, priced


def shortlist_mask(expert: ActiveExpert, belief: DesignBelief,
                   moves: int = SHORTLIST_MOVES) -> np.ndarray:
    """The operations open among ``active``'s short list from ``belief``'s state (bool, one
    per view action): :func:`listed_moves`, and stop."""
    listed, _, _ = listed_moves(expert, belief, moves)
    mask = np.zeros(belief.n_actions, dtype=bool)
    mask[[*listed, belief.n_actions - 1]] = True
    return mask


def ranked_shortlist(expert: ActiveExpert, belief: DesignBelief,
                     moves: int = SHORTLIST_MOVES) -> tuple[list[int], np.ndarray]:
    """The short list (:func:`listed_moves`) and what the ranked view observes of it
    (``moves`` by :data:`RANK_FEATURES`, float64; zeros past the list's end), per listed
    operation: listed; a move (not a re-mount or stop); its gain per second over the
    list's best; ``log10`` of its gain over the filter's present criterion plus
    :data:`~orthoglide_env.lab.design_belief.FALL_FLOOR`; its seconds over the time left;
    the expected share of the stands reading there; the readings taken there so far over
    :data:`~orthoglide_env.lab.design_belief.COUNT_SCALE`; whether it stays where it is.
    All from the filter's pricing (the values read and the nominal model, never the
    truth) and the belief's tally: no play-out."""
    listed, rate, priced = listed_moves(expert, belief, moves)
    n = belief.n_postures
    features = np.zeros((moves, RANK_FEATURES))
    # An unpriced move (an infinite or undefined rate or gain) offers nothing.
    rate = np.where(np.isfinite(rate), rate, 0.0)
    gains = np.where(np.isfinite(priced.gain), priced.gain, 0.0)
    rates = rate[[p for p in listed if p < n]]
    best = float(rates.max()) if rates.size and rates.max() > 0 else 1.0
    criterion = max(float(expert.planner._criterion_value()), np.finfo(float).tiny)
    left = max(belief.budget_s - belief.time_s, np.finfo(float).tiny)
    for r, p in enumerate(listed):
        if p >= n:
            features[r, 0] = 1.0
            continue
        features[r] = (1.0, 1.0, max(rate[p], 0.0) / best,
                       np.log10(min(max(gains[p], 0.0) / criterion, 1.0) + FALL_FLOOR),
                       min(priced.seconds[p] / left, 1.0), float(priced.reads[:, p].mean()),
                       belief.readings_at[p] / COUNT_SCALE, float(p == belief.here))
    return listed, features


def ranked_bounds(moves: int, readings: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of :func:`ranked_shortlist`'s features (``moves`` by
    :data:`RANK_FEATURES`, flattened), with at most ``readings`` readings at a posture
    over :data:`~orthoglide_env.lab.design_belief.COUNT_SCALE`."""
    low = np.tile([0.0, 0.0, 0.0, np.log10(FALL_FLOOR), 0.0, 0.0, 0.0, 0.0], moves)
    high = np.tile([1.0, 1.0, 1.0, np.log10(1.0 + FALL_FLOOR), 1.0, 1.0, readings, 1.0],
                   moves)
    return low, high


def rank_mask(listed: list[int], moves: int = SHORTLIST_MOVES) -> np.ndarray:
    """Which ranks of the ranked view are open (``moves + 1``,): those of the list's
    length, and stop (the last)."""
    mask = np.zeros(moves + 1, dtype=bool)
    mask[:len(listed)] = True
    mask[-1] = True
    return mask


def view_action(listed: list[int], rank: int, n_actions: int) -> int:
    """The view operation that rank ``rank`` names: the list's ``rank``-th, or stop (the
    last rank)."""
    return listed[rank] if rank < len(listed) else n_actions - 1


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


class RankedShortlistLab(ShortlistDesignLab):
    """The short list as its own action set, and seen: action ``r`` < :data:`SHORTLIST_MOVES`
    takes the list's ``r``-th operation (:func:`listed_moves`: 0 is ``active``'s choice, the
    others by the filter's gain per second), the last action stops; its mask
    (:meth:`action_masks`, :func:`rank_mask`) opens the ranks the list fills, and stop.
    Its observation is the filtered view's, then :data:`RANK_FEATURES` numbers per rank
    (:func:`ranked_shortlist`: gain per second, gain, seconds, dials and readings so far
    of each listed move, from the filter and the belief, never the truth), so that a
    network compares the listed moves by what they offer instead of recalling postures
    by index.  Its reward is the view's.  Its ``flicks`` is ``"ranked"``.

    Version history: a new class (no earlier spaces); its observation is the view of
    ``version``'s, then ``SHORTLIST_MOVES * RANK_FEATURES`` numbers (24), its action space
    ``Discrete(SHORTLIST_MOVES + 1)``."""

    flicks = "ranked"

    def __init__(self, env: gym.Env, reward: str = "mse", per: str = "step",
                 version: int = 0) -> None:
        super().__init__(env, reward=reward, per=per, version=version)
        self.listed: list[int] = []
        self.action_space = spaces.Discrete(SHORTLIST_MOVES + 1)
        space = self.observation_space
        most = self.belief.most_readings(self.env.unwrapped.settings.longest_step())
        low, high = ranked_bounds(SHORTLIST_MOVES, most / COUNT_SCALE)
        self.observation_space = spaces.Box(np.r_[space.low, low].astype(np.float32),
                                            np.r_[space.high, high].astype(np.float32),
                                            dtype=np.float32)

    def action_masks(self) -> np.ndarray:
        """Which ranks are open now: :func:`rank_mask` of the list."""
        return rank_mask(self.listed)

    def rank_of(self, operation: int) -> int:
        """The rank whose action is view operation ``operation`` of the list (stop: the
        last rank unless the list names it): how a view expert's label is a rank."""
        if operation in self.listed:
            return self.listed.index(operation)
        if operation == self.belief.n_actions - 1:
            return SHORTLIST_MOVES
        raise ValueError(f"operation {operation} is not on the short list {self.listed}")

    def _play(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        return super()._play(view_action(self.listed, action, self.belief.n_actions))

    def _observation(self) -> np.ndarray:
        seen = super()._observation()
        if self.expert is None:
            # The view's reset, before the episode's filter exists; the filtered view's
            # reset observes again once it does.
            return seen
        self.listed, features = ranked_shortlist(self.expert, self.belief)
        return np.concatenate((seen, features.ravel())).astype(np.float32)


class RankLabels:
    """A view expert's labels (``expert.choose``: a view operation) as ranks of a
    :class:`RankedShortlistLab` (``env``): the expert must choose on the list, as
    ``active`` and :class:`LookaheadExpert` do."""

    def __init__(self, expert: Any, env: RankedShortlistLab) -> None:
        self.expert, self.env = expert, env

    def choose(self, belief: DesignBelief) -> int:
        return self.env.rank_of(self.expert.choose(belief))

    def follow(self, action: int, belief: DesignBelief) -> None:
        """Nothing: the view's filter has seen every lab action."""


class RankedShortlistFilter(ShortlistFilter):
    """What ``policy:FILE`` of ``flicks="ranked"`` keeps beside its belief: the short
    list's filter (:class:`ShortlistFilter`), whose list is the policy's actions and whose
    features follow the view's observation (:class:`RankedShortlistLab`)."""

    #: The ranked view's numbers after the view's, and its actions.
    inputs: int = SHORTLIST_MOVES * RANK_FEATURES
    actions: int = SHORTLIST_MOVES + 1

    def ranked(self, belief: DesignBelief) -> tuple[np.ndarray, np.ndarray]:
        """The ranked view's features (:data:`inputs`,) and mask (:data:`actions`,) of
        ``belief``'s state; the list is kept for :meth:`view_action`."""
        self.listed, features = ranked_shortlist(self.expert, belief)
        return features.ravel(), rank_mask(self.listed)

    def view_action(self, rank: int, belief: DesignBelief) -> int:
        """The view operation of rank ``rank`` of the list last :meth:`ranked`."""
        return view_action(self.listed, rank, belief.n_actions)


def ranked_shortlist_lab_env(reward: str = "mse", per: str = "step", version: int = 0,
                             **kwargs: Any) -> RankedShortlistLab:
    """``OrthoglideLab-v0`` (``kwargs``: the lab env's) in the ranked short-list view of
    ``version`` (:class:`RankedShortlistLab`)."""
    return RankedShortlistLab(OrthoglideLabEnv(**kwargs), reward=reward, per=per,
                              version=version)


def shortlist_design_lab_env(reward: str = "mse", per: str = "step", version: int = 0,
                             **kwargs: Any) -> ShortlistDesignLab:
    """``OrthoglideLab-v0`` (``kwargs``: the lab env's) in the filtered design view of
    ``version`` whose mask opens ``active``'s short list (:class:`ShortlistDesignLab`)."""
    return ShortlistDesignLab(OrthoglideLabEnv(**kwargs), reward=reward, per=per,
                              version=version)


FLICK_FILTERS["shortlist"] = ShortlistFilter
FLICK_FILTERS["ranked"] = RankedShortlistFilter
