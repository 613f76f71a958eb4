"""A plan from the relaxation: the bound's continuous design rounded to instrument bundles.

The greedy search (:mod:`calibrators.planning.search`) prices a set-up by what its bundle
buys per second against the dials' next moves, so a set-up that pays only over the whole
hour (the laser's soak and set-ups take 40 minutes) is never bought, where the bound's
design (:mod:`calibrators.planning.bound`) sets the laser up on every drive and reads the
bar.  Here the design chooses the instruments' readings and the greedy search the dials'
around them:

1. :func:`sequential_design`: the continuous design of the bound's model for a choice of
   set-ups, with one clock: a visit to a candidate posture reads the stands mounted
   where the plan starts that touch there safely (:func:`dial_visits`), a reading of the
   bar costs a visit, of the laser a settle and its dwell, and each set-up its lifts and
   engages (a visit is a settle, and in a lab whose every move reads a laser set up,
   ``OrthoglideLab-v1`` to ``-v3``, the laser's dwell too: a plan sets it up first and
   leaves it; where the moves ask, ``-v4``, a visit leaves it unread).  The bound lets a
   visit's readings fall at as many postures as it reads stands; a plan's visit is at one
   posture, where most stands see little, so a design priced so took five times the
   dials a plan can.  The plan
   lifts the plungers while an instrument reads, so unlike the bound's relaxation the
   instruments and the dials do not share visits.
   Solved by the multiplicative algorithm (every reading used gains as much per second
   at its optimum); the :data:`CHOICES_TRIED` choices of least value are rounded.
2. :func:`apportion`: each instrument's readings (the design's count, rounded) are shared
   over its candidates by efficient apportionment (Pukelsheim and Rieder 1992, "Efficient
   rounding of approximate designs", Biometrika 79: ``ceil((n - p/2) w_i)``, then one
   reading at a time added where ``n_i / w_i`` is least or taken where ``(n_i - 1) / w_i``
   is most).
3. :func:`relaxed_bundles`: the readings as bundles a plan takes, the laser along each
   drive at its targets (ascending, back to Zero), the bar at its points round its circles.

``optimal`` takes each choice's bundles first and lets the greedy search fill the rest of
the budget (:func:`relaxed_plan`), then keeps the plan, of these and the greedy one alone,
whose criterion predicts least (:func:`calibrators.agents.optimal.fixed_plan`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import (
    BAR,
    BoundModel,
    bar_bundle,
    best_design,
    bound_model,
    setup_seconds,
)
from calibrators.planning.instruments import Bundle, conditions_or_default
from calibrators.planning.search import Planner, greedy_plan, take_fitting
from orthoglide_env.lab.operations import TIME, Op
from orthoglide_env.lab.slot_table import slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.world.conditions import Conditions

#: Steps of :func:`sequential_design`'s multiplicative algorithm: a design to round, not a
#: certified value (on the prototype's one-hour problems the RMS moved 0.1-0.4 % between
#: 30 and 100 steps, less than rounding to whole readings moves it).
DESIGN_STEPS: int = 100
#: Steps that screen the set-ups (their designs ranked alike after 30 and after 100 steps
#: on the prototype's one-hour problems).
SCREEN_STEPS: int = 30
#: The set-up choices whose rounded designs are planned (each a greedy fill, seconds): the
#: sequential design's ranking misses what the plan adds (the stands' unknown
#: installations, the world's terms, the drives' travel, whole readings), so the planner's
#: criterion decides among the best few.  Under ``lab``, one hour, the three instruments,
#: the designs with the pivot ranked 1.31, 1.58, 1.74, 2.58 um (the laser on three, two,
#: one drive, none) and their plans the other way round, 3.67, 2.34, 2.28, 2.12 um: four
#: tries take every choice with the pivot.
CHOICES_TRIED: int = 4
#: A candidate whose share of its instrument's readings is below this is dropped before
#: apportioning (the multiplicative algorithm leaves every share positive, most tiny).
SHARE_FLOOR: float = 1e-3


def apportion(weights: np.ndarray, n: int) -> np.ndarray:
    """``n`` whole readings shared over the candidates of design ``weights`` (non-negative,
    not all zero) by efficient apportionment; where ``n`` is below the support's size, one
    reading each at the ``n`` largest weights."""
    w = np.asarray(weights, dtype=float)
    if not (n >= 0 and np.all(w >= 0) and w.sum() > 0):
        raise ValueError(f"apportion needs n >= 0 and non-negative weights, got n={n}")
    w = w / w.sum()
    support = np.flatnonzero(w > 0)
    counts = np.zeros(len(w), dtype=int)
    if n < len(support):
        counts[support[np.argsort(w[support])[::-1][:n]]] = 1
        return counts
    counts[support] = np.ceil((n - len(support) / 2) * w[support]).astype(int)
    while counts.sum() < n:
        counts[support[np.argmin(counts[support] / w[support])]] += 1
    while counts.sum() > n:
        counts[support[np.argmax((counts[support] - 1) / w[support])]] -= 1
    return counts


def dial_visits(model: BoundModel, design: MachineDesign, slots: tuple[int, ...]
                ) -> np.ndarray:
    """(P, N) the dial readings a visit to each of ``design``'s candidate postures expects of
    stands mounted at ``slots``, over ``model``'s candidates: each stand's a-priori contact
    probability where it is safe there (a plan lifts it where it is not), one visit one
    posture."""
    table = slot_table(design)
    safe, contact = table.prior_reach
    dial = np.flatnonzero(model.laser == -1)
    slot, posture = model.label[dial, 0], model.label[dial, 1]
    read = np.isin(slot, slots) & safe[slot, posture]
    out = np.zeros((len(table.postures), model.rows.shape[0]))
    out[posture[read], dial[read]] = contact[slot[read], posture[read]]
    return out


def sequential_design(model: BoundModel, seconds: float, drives: tuple[int, ...],
                      pivot: bool, visits: np.ndarray, steps: int = DESIGN_STEPS,
                      laser_asked: bool = False) -> tuple[float, np.ndarray]:
    """The continuous design on ``model`` over ``seconds`` of one clock with the laser set
    up on ``drives`` and the bar's pivot or not (see the module), the dials read on
    ``visits`` (:func:`dial_visits`), after ``steps`` multiplicative steps, in a lab whose
    moves read the laser only where they ask (``laser_asked``) or at every move: its value
    ``f`` (mm^2) and counts (N,) of ``model``'s candidates."""
    instrument = np.flatnonzero(np.isin(model.laser, drives) | ((model.laser == BAR) & pivot))
    postures = np.flatnonzero(visits.any(axis=1))
    read = np.flatnonzero(visits.any(axis=0))
    expected = visits[postures][:, read]  # (V, D): a visit's readings of the dials it reads
    # A plan sets the laser up first and leaves it set up: every later visit dwells, but
    # where the lab's moves ask.
    visit = TIME.settle_and_read_s + (TIME.interferometer_target_s
                                      if drives and not laser_asked else 0.0)
    price = np.concatenate([np.full(len(postures), visit), np.where(
        model.laser[instrument] == BAR, visit,
        TIME.settle_and_read_s + TIME.interferometer_target_s)])
    w = np.full(len(price), 1.0 / len(price))
    counts = np.zeros(model.rows.shape[0])
    value = np.inf
    for step in range(steps + 1):
        taken = w * seconds / price
        counts[read] = taken[:len(postures)] @ expected
        counts[instrument] = taken[len(postures):]
        value, fall = model.value_and_fall(counts)
        if step == steps:
            break
        gain = np.concatenate([expected @ fall[read], fall[instrument]])
        per_second = gain / price
        w = w * per_second / float(w @ per_second)
        w /= w.sum()
    return value, counts


@lru_cache(maxsize=8)
def relaxed_bundles(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                    budget_s: float, instruments: tuple[str, ...], slots: tuple[int, ...],
                    laser_asked: bool = False) -> tuple[tuple[Bundle, ...], ...]:
    """The bundles of the best sequential designs (:func:`sequential_design`) of a lab of
    ``design`` under ``conditions`` with dials of weighting sigma ``dial_sigma`` (mm) on
    stands at ``slots``, owning ``instruments``, over ``budget_s`` seconds (its moves
    reading the laser only where they ask with ``laser_asked``):
    one tuple per choice of set-ups, the :data:`CHOICES_TRIED` of least value first (a
    choice that sets nothing up is the greedy plan's, left out).

    To keep it to seconds, the set-ups are the laser on the first ``k`` drives (the
    prototype's drives are alike) with or without the pivot, each ranked after
    :data:`SCREEN_STEPS` steps and the kept ones solved to :data:`DESIGN_STEPS`.  Each
    set-up's seconds are less the lifts and engages of the plungers around it."""
    owned = "interferometer" in instruments
    bar = "ballbar" in instruments
    model = (bound_model(design, conditions, float(dial_sigma), owned, True) if bar
             else bound_model(design, conditions, float(dial_sigma), owned))
    every = (0, 1, 2) if owned else ()
    visits = dial_visits(model, design, slots)

    def seconds(drives: tuple[int, ...], pivot: bool) -> float:
        flicks = (len(drives) + pivot) * 2 * len(slots) * TIME.lift_s
        return (budget_s - setup_seconds(drives) - (TIME.ballbar_setup_s if pivot else 0.0)
                - flicks)

    ranked = sorted((sequential_design(model, seconds(every[:k], pivot), every[:k], pivot,
                                       visits, SCREEN_STEPS, laser_asked)[0], every[:k], pivot)
                    for pivot in ([False, True] if bar else [False])
                    for k in range(len(every) + 1)
                    if (k or pivot) and seconds(every[:k], pivot) > 0)
    return tuple(_bundles(model, design, drives, pivot, sequential_design(
        model, seconds(drives, pivot), drives, pivot, visits, laser_asked=laser_asked)[1])
        for _, drives, pivot in ranked[:CHOICES_TRIED])


def _bundles(model: BoundModel, design: MachineDesign, drives: tuple[int, ...], pivot: bool,
             counts: np.ndarray) -> tuple[Bundle, ...]:
    """A design's ``counts`` of the laser's and the bar's candidates as bundles; an
    instrument the design gives no reading (a world where it sees nothing, ``ideal``'s bar)
    gets no bundle."""
    out: list[Bundle] = []
    for axis in drives:
        on = np.flatnonzero(model.laser == axis)
        if not counts[on].sum() > 0:
            continue
        targets = np.repeat(model.targets[model.label[on, 2]], _rounded(counts[on]))
        path = np.zeros((len(targets) + 1, 3))
        path[:-1, axis] = np.sort(targets)  # then back to Zero, read too
        out.append(Bundle("interferometer", f"interferometer {'xyz'[axis]} (design)",
                          Op.ALIGN, path, axis=axis))
    if pivot and counts[model.laser == BAR].sum() > 0:
        circle = bar_bundle(design)
        out.append(Bundle("ballbar", "ballbar 50 mm (design)", Op.PIVOT,
                          np.repeat(circle.path, _rounded(counts[model.laser == BAR]), axis=0),
                          centre=circle.centre, bar=circle.bar))
    return tuple(out)


def _rounded(counts: np.ndarray) -> np.ndarray:
    """An instrument's design ``counts`` as whole readings: their sum rounded (at least
    one), apportioned over the candidates above :data:`SHARE_FLOOR` of it."""
    kept = np.where(counts >= SHARE_FLOOR * counts.sum(), counts, 0.0)
    return apportion(kept, max(round(float(counts.sum())), 1))


def bound_bundles(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                  budget_s: float, instruments: tuple[str, ...], remounts: bool = True
                  ) -> tuple[Bundle, ...]:
    """The bound's own design (:func:`~calibrators.planning.bound.best_design`, whose
    instruments share its visits with the dials; without ``remounts``, that of the bound
    with the stands held at the paper's slots) rounded to bundles as
    :func:`relaxed_bundles` rounds the sequential designs: its set-ups, its laser targets
    and its bar points.  Not among ``optimal``'s choices: with the bar, where its plan was
    kept, its prediction was within 1 % of the plan kept before and its error in the lab
    no measurably lower; with the laser at three hours, kept on the model with the timed
    terms unknown, no lower either (``benchmarks/plan_gap.py``, docs/instruments.md)."""
    found = best_design(design, conditions, dial_sigma, budget_s, instruments,
                        remounts=remounts)
    model = (bound_model(design, conditions, float(dial_sigma), "interferometer" in instruments,
                         True) if "ballbar" in instruments
             else bound_model(design, conditions, float(dial_sigma),
                              "interferometer" in instruments))
    return _bundles(model, design, found.drives, found.pivot, found.counts)


def plan_bundles(slots: tuple[int, ...], sigma: float, budget_s: float, design: MachineDesign,
                 conditions: Conditions | None, instruments: tuple[str, ...],
                 laser_asked: bool = False) -> tuple[tuple[Bundle, ...], ...]:
    """:func:`relaxed_bundles` of a plan's lab: stands at ``slots`` (-1: none), dials of
    weighting sigma ``sigma`` (mm), ``budget_s`` seconds, ``conditions`` (None: ideal),
    owning ``instruments``, its moves reading the laser only where they ask with
    ``laser_asked``; none where it owns no instrument the bound holds."""
    if not {"interferometer", "ballbar"} & set(instruments):
        return ()
    return relaxed_bundles(design, conditions_or_default(conditions), float(sigma),
                           float(budget_s), ("dial", *instruments),
                           tuple(int(s) for s in slots if s >= 0),
                           bool(laser_asked) and "interferometer" in instruments)


def relaxed_plan(planner: Planner, bundles: tuple[Bundle, ...], remounts: bool = True
                 ) -> list[PlannedOperation]:
    """``bundles`` taken first, each that fits in the planner's budget, their readings
    expected, then the budget spent by :func:`~calibrators.planning.search.greedy_plan`."""
    for bundle in bundles:
        take_fitting(planner, bundle)
    return greedy_plan(planner, remounts=remounts)
