"""The greedy search for a plan: the move or re-mount with the most gain per second next,
until the budget is spent or nothing pays.

:class:`Planner` holds an experiment being designed (its belief:
:mod:`calibrators.planning.belief`) and prices every candidate operation
(:mod:`calibrators.planning.pricing`); it takes the affordable move of the highest gain
per second (:meth:`Planner.best_move`), and every :data:`REMOUNT_CHECK_S` of the plan
weighs re-mounting a stand elsewhere against staying (:meth:`Planner.best_remount`).
:func:`greedy_plan` spends a budget so; the ``active`` agent takes one move at a time
between readings.  In a lab that owns an instrument the planner prices
(:mod:`calibrators.planning.instruments`), an instrument's bundle is one more option
(:func:`best_bundle`), taken (:func:`take`) and counted (:func:`expect`, or with its
values :func:`observe`) here, where the planner's state lives.
"""

from __future__ import annotations

import copy
import os
import pickle
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TypeVar

import numpy as np

from calibrators.planning.belief import PlannedOperation, expect_many
from calibrators.planning.instruments import (
    Bundle,
    InstrumentOperation,
    bundles,
    conditions_or_default,
    marginal,
    reading_rows,
)
from calibrators.planning.pricing import PricedMoves, Pricer, top_rates_many
from orthoglide_env.instruments import ballbar, interferometer
from orthoglide_env.lab.clock import move_dwell_seconds
from orthoglide_env.lab.operations import TIME, Op, slot_catalogue

#: Re-mounts are weighed against staying every this many seconds of the plan, each option
#: by the gain per second of its next :data:`LOOKAHEAD_MOVES` moves (after the re-mount).
REMOUNT_CHECK_S: float = 300.0
LOOKAHEAD_MOVES: int = 24
SCREENED: int = 6
#: The options a re-mount's check plays out (:meth:`Planner.best_remount`) are played this
#: many at a time, their moves chosen together (:func:`best_moves`): staying and the
#: :data:`SCREENED` re-mounts at once; all of them at once would hold every re-mount's
#: rows (a megabyte or more each) together.
PLAYED_TOGETHER: int = SCREENED + 1
#: Under the world's terms, a re-mount check screens this many re-mounts at a time, the
#: world's prices of their shortlists stacked (:func:`~calibrators.planning.pricing.
#: price_many`): 8 and a stand's 33 at once cost the one-hour ``lab`` plan alike, and 8
#: hold a quarter of the rows.  Without the world nothing is stacked, and holding the
#: trials only costs memory traffic: they are screened one by one.
SCREENED_TOGETHER: int = 8
#: What a move that reads the laser costs on top of its drive and settle (s): the lab's
#: charge (every move's once a plan has set the laser up, but where the lab's moves ask,
#: :attr:`~calibrators.planning.belief.Belief.laser_asked`).
LASER_DWELL_S: float = float(move_dwell_seconds(laser=True))
#: Processes a re-mount check's screening is spread over (:func:`screening_over`).
_SCREENING_PROCESSES: int = 1

Item = TypeVar("Item")
Result = TypeVar("Result")


@contextmanager
def screening_over(processes: int) -> Iterator[None]:
    """While it lasts, every re-mount check of this process (:meth:`Planner.best_remount`)
    screens its re-mounts over ``processes`` processes, this one and forks of it: for a
    plan made once while cores are idle (a sweep's start-up plan, before its workers
    start).  The same numbers, to the bit: each re-mount's are its own alone."""
    global _SCREENING_PROCESSES
    saved, _SCREENING_PROCESSES = _SCREENING_PROCESSES, max(1, processes)
    try:
        yield
    finally:
        _SCREENING_PROCESSES = saved


def _spread(function: Callable[[list[Item]], list[Result]], items: list[Item]
            ) -> list[Result]:
    """``function(items)``, ``items`` split in order over the screening's processes
    (:func:`screening_over`): the first part here and each other in a fork of this process
    (which holds the caller's state as it is, with nothing to send), its results sent back
    pickled; ``function`` answers each item alone, whatever the others."""
    parts = [[items[i] for i in part] for part in np.array_split(
        np.arange(len(items)), max(1, min(_SCREENING_PROCESSES, len(items))))]
    if len(parts) < 2 or not hasattr(os, "fork"):
        return function(items)
    children = []
    for part in parts[1:]:
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # the fork: its part, sent back, and out without any clean-up
            os.close(read)
            try:
                try:
                    answer = (True, function(part))
                except BaseException:
                    answer = (False, traceback.format_exc())
                with os.fdopen(write, "wb") as out:
                    pickle.dump(answer, out, pickle.HIGHEST_PROTOCOL)
            finally:
                os._exit(0)
        os.close(write)
        children.append((pid, read))
    results = function(parts[0])
    for pid, read in children:
        with os.fdopen(read, "rb") as answer:
            data = answer.read()
        os.waitpid(pid, 0)
        done, value = pickle.loads(data) if data else (False, "no answer")
        if not done:
            raise RuntimeError(f"a forked re-mount screening failed: {value}")
        results += value
    return results


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
        trial.touched_rows = list(self.touched_rows)
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
        self.steps.append(PlannedOperation(Op.MOVE, tuple(float(v) for v in rho), time_s=clock,
                                           laser=int(not self.laser_asked)))
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
        return lookahead_rates([self], self._criterion_value() if start is None else start,
                               self.time_s if start_s is None else start_s)[0]


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
        return self._chosen(*self.top_rates(1))

    def _chosen(self, rate: np.ndarray, priced: PricedMoves
                ) -> tuple[int, PricedMoves] | None:
        """:meth:`best_move`'s answer from :meth:`top_rates`' ``rate`` and ``priced``."""
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

    def _remounted(self, options: list[tuple[int, int]]) -> list[Planner]:
        """Copies re-mounted, one per (stand, slot) of ``options``, each with the readings
        of its opening expected (the world's rows of them stacked: :func:`expect_many`)."""
        trials = []
        for stand, slot in options:
            trial = self.fork()
            trial.remount(stand, slot)
            trials.append(trial)
        expect_many(trials)
        return trials

    def _screening_moves(self) -> tuple[np.ndarray, PricedMoves]:
        """The :data:`LOOKAHEAD_MOVES` affordable moves of the highest rates, the lowest
        first, as ``np.argsort`` of :meth:`affordable_rates` over :meth:`priced_moves` ranks
        them, and the priced moves with their gains.  From :meth:`top_rates` when those rates
        are positive and distinct, and above every other (so the ranking is the only
        one); else from every move priced, whose ties ``np.argsort`` breaks its way."""
        return self._screened(*self.top_rates(LOOKAHEAD_MOVES))

    def _screened(self, rate: np.ndarray, priced: PricedMoves
                  ) -> tuple[np.ndarray, PricedMoves]:
        """:meth:`_screening_moves` from :meth:`top_rates`' ``rate`` and ``priced`` (of
        :data:`LOOKAHEAD_MOVES`)."""
        top = np.argsort(rate)[-LOOKAHEAD_MOVES:]
        kept = rate[top]
        if (kept[0] > 0 and np.unique(kept).size == LOOKAHEAD_MOVES
                and np.sum(rate >= kept[0]) == LOOKAHEAD_MOVES):
            return top, priced
        priced = self.priced_moves()
        return np.argsort(self.affordable_rates(priced))[-LOOKAHEAD_MOVES:], priced

    def _screening_rates(self, chunks: list[list[tuple[int, int]]], start: float
                         ) -> list[tuple[float, int, int]]:
        """Each re-mount (stand, slot) of ``chunks`` (stacked a chunk at a time) with the
        gain per second, since criterion value ``start`` and the re-mount included, of the
        best :data:`LOOKAHEAD_MOVES` moves it opens, each priced alone:
        ``(rate, stand, slot)``."""
        candidates = []
        for chunk in chunks:
            trials = self._remounted(chunk)
            for (stand, slot), trial, opened in zip(chunk, trials, top_rates_many(
                    trials, LOOKAHEAD_MOVES), strict=True):
                top, priced = trial._screened(*opened)
                gain = start - trial._criterion_value() + priced.gain[top].sum()
                spent = trial.time_s - self.time_s + priced.seconds[top].sum()
                candidates.append((gain / spent, stand, slot))
        return candidates

    def _played_rates(self, options: list[tuple[int, int] | None], start: float
                      ) -> list[float]:
        """:meth:`lookahead_rate` since criterion value ``start`` now of each of ``options``:
        a re-mount (stand, slot), or None for staying; played out together."""
        moved = iter(self._remounted([o for o in options if o is not None]))
        return lookahead_rates([self if o is None else next(moved) for o in options], start,
                               self.time_s)

    def best_remount(self, screened: int | None = SCREENED) -> tuple[int, int] | None:
        """The re-mount (stand, slot) whose next moves gain more per second, re-mount
        included, than the next moves of the present configuration, or None.  Every
        re-mount is screened by the best :data:`LOOKAHEAD_MOVES` moves it opens, each
        priced alone; the ``screened`` best (None: all) are then played out greedily.

        The re-mounts are screened :data:`SCREENED_TOGETHER` at a time and the options
        played out :data:`PLAYED_TOGETHER` at a time, their prices stacked
        (:func:`~calibrators.planning.pricing.top_rates_many`): each option's numbers are
        its own alone, to the bit; under :func:`screening_over` both are spread over its
        processes.  None when a re-mount would end past the budget: a plan's every
        operation ends within it, as its moves do (:meth:`affordable_rates`)."""
        if self.time_s + self.remount_seconds() > self.budget_s:
            return None
        start = self._criterion_value()
        options = [(stand, slot) for stand in range(len(self.slots))
                   for slot in range(len(slot_catalogue(self.design)))
                   if slot not in self.slots]
        together = SCREENED_TOGETHER if self.world is not None else 1
        chunks = [options[first:first + together]
                  for first in range(0, len(options), together)]
        ranked = sorted(_spread(lambda part: self._screening_rates(part, start), chunks))
        # Staying first, then the screened re-mounts from the least promising up.
        played = [None] + [(stand, slot) for _, stand, slot in (
            ranked[-screened:] if screened else ranked)]
        # Spread over the screening's processes too, each playing a group at a time.
        size = min(PLAYED_TOGETHER, -(-len(played) // _SCREENING_PROCESSES))
        rates = _spread(lambda part: [rate for group in part
                                      for rate in self._played_rates(group, start)],
                        [played[first:first + size] for first in range(0, len(played), size)])
        best, best_rate = None, rates[0]
        for option, rate in zip(played[1:], rates[1:], strict=True):
            if rate > best_rate:
                best, best_rate = option, rate
        return best



def best_moves(planners: list[Planner]) -> list[tuple[int, PricedMoves] | None]:
    """:meth:`Planner.best_move` of each of ``planners`` (one per machine of a chunk), their
    moves priced together (:func:`~calibrators.planning.pricing.top_rates_many`): each the
    same choice as alone."""
    return [planner._chosen(rate, priced)
            for planner, (rate, priced) in zip(planners, top_rates_many(planners, 1),
                                               strict=True)]


def lookahead_rates(planners: list[Planner], start: float, start_s: float) -> list[float]:
    """:meth:`Planner.lookahead_rate` of each of ``planners`` since criterion value
    ``start`` at ``start_s``, their moves chosen together (:func:`best_moves`) and their
    readings expected together (:func:`~calibrators.planning.belief.expect_many`): each
    its own alone, to the bit."""
    trials = [planner.fork() for planner in planners]
    going = trials
    for _ in range(LOOKAHEAD_MOVES):
        chosen = [(trial, choice) for trial, choice in zip(going, best_moves(going),
                                                           strict=True) if choice is not None]
        for trial, choice in chosen:
            trial.move(*choice)
        going = [trial for trial, _ in chosen]
        expect_many(going)
    out = []
    for trial in trials:
        spent = trial.time_s - start_s
        out.append((start - trial._criterion_value()) / spent if spent > 0 else 0.0)
    return out


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


# -- a bundle in a plan -----------------------------------------------------------------
def operations(planner: Planner, bundle: Bundle) -> tuple[list[InstrumentOperation], float]:
    """The lab operations of taking ``bundle`` from the planner's state, each at its lab
    time, and the seconds they take: lift every plunger down, set up, drive the path, take
    the bar off (any operation but a move does), back to Zero and every lifted plunger
    down again (their zeros were kept).  A laser's path reads it at every move; a bar's
    path and the way back read a laser left set up only where the lab's moves do not ask
    (:attr:`~calibrators.planning.belief.Belief.laser_asked`)."""
    clock = planner.time_s
    kit = planner.kit
    ops: list[InstrumentOperation] = []
    down = [k for k, on in enumerate(planner.engaged) if on]

    def add(op: Op, seconds: float, rho: np.ndarray | None = None, **keys: int) -> None:
        nonlocal clock
        rho_ = (0.0, 0.0, 0.0) if rho is None else tuple(float(v) for v in rho)
        ops.append(InstrumentOperation(op, rho_, time_s=clock, **keys))
        clock += seconds

    for k in down:
        add(Op.LIFT, TIME.lift_s, stand=k)
    here = np.asarray(planner.rho, dtype=float)
    dwell, laser = planner.dwell_s, int(not planner.laser_asked)
    if bundle.setup == Op.ALIGN:
        soak = 0.0 if kit.soaked else TIME.interferometer_soak_s
        add(Op.ALIGN, float(TIME.move(here, np.zeros(3))) + TIME.interferometer_setup_s + soak,
            axis=bundle.axis)
        here, dwell, laser = np.zeros(3), LASER_DWELL_S, 1
    else:
        centre = np.asarray(bundle.centre)
        add(Op.PIVOT, float(TIME.move(here, centre)) + TIME.ballbar_setup_s, centre,
            bar=bundle.bar)
        here = centre
    for rho in bundle.path:
        add(Op.MOVE, float(TIME.move(here, rho)) + dwell, rho, laser=laser)
        here = rho
    if bundle.setup == Op.PIVOT:
        add(Op.LIFT, TIME.lift_s, stand=0)
    if here.any():
        add(Op.MOVE, float(TIME.move(here, np.zeros(3))) + dwell, np.zeros(3), laser=laser)
    for k in down:
        add(Op.ENGAGE, TIME.lift_s, stand=k)
    return ops, clock - planner.time_s


def take(planner: Planner, bundle: Bundle) -> list[InstrumentOperation]:
    """Take ``bundle`` in the plan (its operations appended to the steps, the clock, the
    posture, the laser's state); its readings are added by the caller (expected:
    :func:`expect`, or observed: :func:`observe`)."""
    ops, seconds = operations(planner, bundle)
    kit = planner.kit
    if bundle.setup == Op.ALIGN:
        kit.soaked = True
        if not planner.laser_asked:
            planner.dwell_s = LASER_DWELL_S
    if planner.world is not None:
        planner.world.moved(np.asarray(planner.rho, dtype=float), np.zeros(3))
    planner.steps.extend(ops)
    planner.time_s += seconds
    planner.rho, planner.here = np.zeros(3), planner.table.zero
    return ops


def take_fitting(planner: Planner, bundle: Bundle) -> bool:
    """Take ``bundle`` in the plan, its readings expected, where it ends within the
    planner's budget; whether it did."""
    trial = planner.fork()
    take(trial, bundle)
    if trial.time_s > trial.budget_s:
        return False
    take(planner, bundle)
    expect(planner, bundle)
    return True


def _update(planner: Planner, equivalent: np.ndarray, innovation: np.ndarray | None) -> None:
    full = np.zeros((len(equivalent), len(planner.covariance)))
    full[:, planner.kit.columns] = equivalent
    considered = np.zeros((len(full), planner.world.consider.shape[1])
                          if planner.world is not None else (len(full), 0))
    planner._add(full, innovation, considered)


def expect(planner: Planner, bundle: Bundle) -> None:
    """Count ``bundle``'s readings in the planner's belief (a plan's)."""
    rows, setup, _ = reading_rows(bundle, planner.design, planner.conditions,
                                  _read_path(bundle))
    _update(planner, *marginal(rows, setup)[:1], None)


def observe(planner: Planner, bundle: Bundle, path: np.ndarray, values: np.ndarray) -> None:
    """Readings ``values`` (mm) of ``bundle``'s instrument taken at commands ``path`` (R, 3)
    (the set-up's, in the lab's notebook): update the filter's mean and covariance."""
    if not len(values):
        return
    if planner.mean is None:
        planner.mean = np.zeros(len(planner.covariance))
    rows, setup, nominal = reading_rows(bundle, planner.design, planner.conditions, path)
    sigma = (interferometer.sigma(conditions_or_default(planner.conditions))
             if bundle.instrument == "interferometer"
             else ballbar.sigma(conditions_or_default(planner.conditions)))
    residual = (np.asarray(values, dtype=float) - nominal) / sigma - rows @ planner.mean[
        planner.kit.columns]
    equivalent, innovation = marginal(rows, setup, residual)
    _update(planner, equivalent, innovation)


def _read_path(bundle: Bundle) -> np.ndarray:
    """Where a bundle's instrument reads: a laser at its set-up (Zero) and every move, a
    bar at every move of its path."""
    if bundle.setup == Op.ALIGN:
        return np.vstack([np.zeros((1, 3)), bundle.path])
    return bundle.path


def best_bundle(planner: Planner, rate_to_beat: float) -> Bundle | None:
    """The bundle that fits in the budget with the most fall of the criterion per second,
    set-up included, if that beats ``rate_to_beat`` (per s); else None."""
    start = planner._criterion_value()
    best, best_rate = None, rate_to_beat
    for bundle in bundles(planner.design, planner.kit.owned):
        trial = planner.fork()
        take(trial, bundle)
        if trial.time_s > trial.budget_s:
            continue
        expect(trial, bundle)
        rate = (start - trial._criterion_value()) / (trial.time_s - planner.time_s)
        if rate > best_rate:
            best, best_rate = bundle, rate
    return best
