"""The greedy search for a plan: the move or re-mount with the most gain per second next,
until the budget is spent or nothing pays.

:class:`Planner` holds an experiment being designed (its belief:
:mod:`calibrators.planning.belief`) and prices every candidate operation
(:mod:`calibrators.planning.pricing`); it takes the affordable move of the highest gain
per second (:meth:`Planner.best_move`), and every :data:`REMOUNT_CHECK_S` of the plan
weighs re-mounting a stand elsewhere against staying (:meth:`Planner.best_remount`).
:func:`greedy_plan` spends a budget so; the ``active`` agent takes one move at a time
between readings.
"""

from __future__ import annotations

import copy

import numpy as np

from calibrators.planning.belief import PlannedOperation
from calibrators.planning.instruments import best_bundle, expect, take
from calibrators.planning.pricing import PricedMoves, Pricer
from orthoglide_env.lab.operations import TIME, Op, slot_catalogue

#: Re-mounts are weighed against staying every this many seconds of the plan, each option
#: by the gain per second of its next :data:`LOOKAHEAD_MOVES` moves (after the re-mount).
REMOUNT_CHECK_S: float = 300.0
LOOKAHEAD_MOVES: int = 24
SCREENED: int = 6


class Planner(Pricer):
    """An experiment being designed (:class:`~calibrators.planning.belief.Belief`, its
    fields), with its moves priced (:class:`~calibrators.planning.pricing.Pricer`), that
    chooses and takes its next operations."""

    def fork(self) -> Planner:
        """A copy to try operations on (the table is shared, the state copied; each
        stand's rows, which a re-mount replaces, are shared)."""
        trial = copy.copy(self)
        trial.slots, trial.engaged, trial.steps = list(self.slots), list(self.engaged), []
        trial.covariance = self.covariance.copy()
        trial.stand_rows, trial.touched_rows = list(self.stand_rows), list(self.touched_rows)
        trial.silent = self.silent.copy()
        trial.spread_bound = self.spread_bound.copy()
        trial.mean = None if self.mean is None else self.mean.copy()
        trial.world = None if self.world is None else self.world.copy()
        trial.kit = None if self.kit is None else self.kit.copy()
        return trial


    def move(self, posture: int, priced: PricedMoves) -> np.ndarray:
        """Take candidate move ``posture``: the steps, the clock; returns which stands are
        down there.  (The readings are added by the caller: expected or observed.)"""
        after = priced.engaged[:, posture]
        clock = self.time_s
        for k, down in enumerate(after):
            if bool(down) != self.engaged[k]:
                op = Op.ENGAGE if down else Op.LIFT
                self.steps.append(PlannedOperation(op, stand=k, time_s=clock))
                clock += TIME.lift_s
        rho = self.table.postures[posture]
        self.steps.append(PlannedOperation(Op.MOVE, tuple(float(v) for v in rho), time_s=clock))
        if self.world is not None:
            self.world.moved(self.rho, rho)
        self.engaged = [bool(v) for v in after]
        self.rho, self.here = rho.copy(), posture
        self.time_s += float(priced.seconds[posture])
        return after


    def lookahead_rate(self, start: float | None = None, start_s: float | None = None
                       ) -> float:
        """Gain per second, since criterion value ``start`` at ``start_s`` (default now),
        of the next :data:`LOOKAHEAD_MOVES` greedy moves (readings expected), on a copy."""
        trial = self.fork()
        start = trial._criterion_value() if start is None else start
        start_s = trial.time_s if start_s is None else start_s
        for _ in range(LOOKAHEAD_MOVES):
            if not trial.greedy_move():
                break
        spent = trial.time_s - start_s
        return (start - trial._criterion_value()) / spent if spent > 0 else 0.0


    def best_move(self) -> tuple[int, PricedMoves] | None:
        """The affordable move with the most gain per second (the first of equals), with
        every move's seconds, plungers and readings and the gains that were priced
        (:meth:`top_rates`), or None when no move gains anything within the budget: the
        same move as the highest of :meth:`affordable_rates` over :meth:`priced_moves`.

        With the world's terms the shortlist's best is taken unless it would end the plan
        (:meth:`~calibrators.planning.world_terms.WorldTerms.stops`, or no gain): then every
        move is priced, so a plan ends only when no move pays, not when the shortlist's
        do not (a fresh mounting's loose bounds may shortlist moves that add more to the
        indicators' bias than they take off the geometry)."""
        rate, priced = self.top_rates(1)
        best = int(np.argmax(rate))
        if self.world is not None and self._ends(rate[best]):
            priced = self.priced_moves()
            rate = self.affordable_rates(priced)
            best = int(np.argmax(rate))
            if self._ends(rate[best]):
                return None
        return (best, priced) if rate[best] > 0 else None

    def _ends(self, rate: float) -> bool:
        """Whether a best move of gain per second ``rate`` ends the plan."""
        return rate <= 0 or (self.criterion == "I" and self.world is not None
                             and self.world.stops(rate, self.budget_s - self.time_s,
                                                  self._criterion_value()))


    def greedy_move(self) -> bool:
        """Take :meth:`best_move`, its readings expected; False when there is none."""
        choice = self.best_move()
        if choice is None:
            return False
        self.move(*choice)
        self.expect_readings()
        return True

    def _remounted(self, stand: int, slot: int) -> Planner:
        trial = self.fork()
        trial.remount(stand, slot)
        trial.expect_readings()
        return trial

    def _screening_moves(self) -> tuple[np.ndarray, PricedMoves]:
        """The :data:`LOOKAHEAD_MOVES` affordable moves of the highest rates, the lowest
        first, as ``np.argsort`` of :meth:`affordable_rates` over :meth:`priced_moves` ranks
        them, and the priced moves with their gains.  From :meth:`top_rates` when those rates
        are positive and distinct, and above every other (so the ranking is the only
        one); else from every move priced, whose ties ``np.argsort`` breaks its way."""
        rate, priced = self.top_rates(LOOKAHEAD_MOVES)
        top = np.argsort(rate)[-LOOKAHEAD_MOVES:]
        kept = rate[top]
        if (kept[0] > 0 and np.unique(kept).size == LOOKAHEAD_MOVES
                and np.sum(rate >= kept[0]) == LOOKAHEAD_MOVES):
            return top, priced
        priced = self.priced_moves()
        return np.argsort(self.affordable_rates(priced))[-LOOKAHEAD_MOVES:], priced

    def best_remount(self, screened: int | None = SCREENED) -> tuple[int, int] | None:
        """The re-mount (stand, slot) whose next moves gain more per second, re-mount
        included, than the next moves of the present configuration, or None.  Every
        re-mount is screened by the best :data:`LOOKAHEAD_MOVES` moves it opens, each
        priced alone; the ``screened`` best (None: all) are then played out greedily."""
        start = self._criterion_value()
        candidates = []
        for stand in range(len(self.slots)):
            for slot in range(len(slot_catalogue(self.design))):
                if slot in self.slots:
                    continue
                trial = self._remounted(stand, slot)
                top, priced = trial._screening_moves()
                gain = start - trial._criterion_value() + priced.gain[top].sum()
                spent = trial.time_s - self.time_s + priced.seconds[top].sum()
                candidates.append((gain / spent, stand, slot))
        best, best_rate = None, self.lookahead_rate()
        ranked = sorted(candidates)
        for _, stand, slot in ranked[-screened:] if screened else ranked:
            rate = self._remounted(stand, slot).lookahead_rate(start, self.time_s)
            if rate > best_rate:
                best, best_rate = (stand, slot), rate
        return best



def greedy_plan(planner: Planner, remounts: bool = True, screened: int | None = SCREENED
                ) -> list[PlannedOperation]:
    """Spend the planner's budget greedily, the operation with the most gain per second
    first (re-mounts weighed every :data:`REMOUNT_CHECK_S`, the ``screened`` most
    promising played out: see :meth:`Planner.best_remount`), and end with a stop."""
    checked = -np.inf
    while True:
        if planner.kit is not None and planner.time_s - checked >= REMOUNT_CHECK_S:
            # An instrument's bundle against the dials' next moves, then the re-mounts.
            bundle = best_bundle(planner, planner.lookahead_rate())
            if bundle is not None:
                take(planner, bundle)
                expect(planner, bundle)
                checked = planner.time_s
                continue
            if not remounts:
                checked = planner.time_s
        if remounts and planner.time_s - checked >= REMOUNT_CHECK_S:
            checked = planner.time_s
            choice = planner.best_remount(screened)
            if choice is not None:
                planner.remount(*choice)
                planner.expect_readings()
                continue
        if not planner.greedy_move():
            break
    planner.steps.append(PlannedOperation(Op.STOP, time_s=planner.time_s))
    return planner.steps
