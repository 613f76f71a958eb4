"""A dial plan from the bound of its own slots: a greedy plan's re-mounts kept, its
readings re-chosen by the design of the bound of the plans that re-mount so.

The greedy search (:mod:`calibrators.planning.search`) chooses its re-mounts well (under
``lab``, one hour, dials alone, its five slots' bound is 0.8 % above the best five found,
``benchmarks/stand_sets.py``) and its readings less so: on the bound's model the plan was
1.19x the bound of its own slots.  Here the slots and their order stay the greedy plan's,
and the readings are those of the continuous design of the bound with the stands at each
of the plan's slot sets in turn (:func:`~calibrators.planning.bound.held_design` with
``phases``), rounded:

1. :func:`plan_phases`: the slot sets a plan's stands stand at, in turn, and the re-mounts
   between them.
2. :func:`phase_visits`: per candidate posture, the fewest visits per phase that take the
   design's readings of each slot there (a visit reads every mounted stand that touches;
   a small linear programme per posture), apportioned to whole visits over postures and
   phases (:func:`~calibrators.planning.rounding.apportion`).
3. :func:`rounded_plan`: the phases in order, each posture's visits taken nearest first
   (the drive is a cost the bound does not price), the re-mounts between, and the budget
   left spent greedily without re-mounts.

The design is that of the bound's model with each dial reading counted at its a-priori
contact (:func:`~calibrators.planning.bound.at_contact_model`), as the planner expects
readings: rounded from the design counted whole, the plan read where the stands seldom
touch (under ``lab``, one hour, 5.548 um on the bound's model and 6.609 um counted at
contact, against the greedy plan's 6.370 and 6.424 um) and realised no better on 50
machines (docs/instruments.md, "The dial plan read as the bound of its own slots").

The design's budget is the plan's less what the bound leaves out (driving, the levers,
the re-mounts' drives to Zero): first as the greedy plan spends it, then as the rounded
plan does (:data:`PASSES`).
"""

from __future__ import annotations

import numpy as np

from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import dial_grid, held_design, lab_model, start_slots
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.rounding import apportion
from calibrators.planning.search import Planner, greedy_plan
from orthoglide_env.lab.operations import TIME, Op

#: Designs made, each at the budget less the last plan's time beyond its visits and
#: re-mounts: the greedy plan's, then the rounded plan's (under ``lab``, one hour, dials
#: alone: 5.820, 5.768 and with a third pass 5.761 um on the bound's model, the overhead
#: 553, 170, 150 s; a third pass buys 0.1 %).
PASSES: int = 2
#: A phase's share of a posture's visits below this is rounding noise of the linear
#: programme (visits, not readings).
VISIT_FLOOR: float = 1e-6


def plan_phases(slots: tuple[int, ...], steps: tuple[PlannedOperation, ...]
                ) -> tuple[tuple[tuple[int, ...], ...], tuple[tuple[int, int], ...]]:
    """The slot sets (one per phase, the first ``slots``) the stands of a plan of ``steps``
    from ``slots`` stand at in turn, and its re-mounts (stand, slot) between them."""
    now, phases, remounts = list(slots), [tuple(slots)], []
    for step in steps:
        if step.op == Op.REMOUNT:
            now[step.stand] = step.slot
            phases.append(tuple(now))
            remounts.append((step.stand, step.slot))
    return tuple(phases), tuple(remounts)


def overhead_s(steps: tuple[PlannedOperation, ...] | list[PlannedOperation]) -> float:
    """The seconds a plan of ``steps`` spends beyond its visits' settles and its re-mounts'
    work (the bound's clock): driving and the levers."""
    visits = sum(s.op in (Op.MOVE, Op.REMOUNT) for s in steps)
    remounts = sum(s.op == Op.REMOUNT for s in steps)
    return float(steps[-1].time_s - visits * TIME.settle_and_read_s
                 - remounts * TIME.remount_s)


def phase_visits(readings: np.ndarray, phases: tuple[tuple[int, ...], ...]) -> np.ndarray:
    """(P, J) whole visits per candidate posture and phase that take ``readings`` (P, S), a
    design's readings of each slot at each posture: per posture the fewest visits over the
    ``phases`` (sets of slots) that read each slot at least its share (the earlier phase
    of equals), their sum rounded and apportioned."""
    from scipy.optimize import linprog  # as the bound's linear algebra: at planning only

    visits = np.zeros((len(readings), len(phases)))
    # The earlier phase of equal cost, so that ties resolve one way.
    cost = 1.0 + 1e-3 * np.arange(len(phases))
    for posture in np.flatnonzero(readings.max(axis=1) > VISIT_FLOOR):
        read = np.flatnonzero(readings[posture] > VISIT_FLOOR)
        covers = np.array([[slot in phase for phase in phases] for slot in read], dtype=float)
        if not covers.any(axis=1).all():
            raise ValueError(f"posture {posture}: a slot read there is in no phase")
        found = linprog(cost, A_ub=-covers, b_ub=-readings[posture, read], bounds=(0, None))
        visits[posture] = np.where(found.x > VISIT_FLOOR, found.x, 0.0)
    if not visits.sum() > 0:
        return np.zeros(visits.shape, dtype=int)
    return apportion(visits.ravel(), round(float(visits.sum()))).reshape(visits.shape)


def rounded_plan(planner: Planner, visits: np.ndarray,
                 remounts: tuple[tuple[int, int], ...]) -> list[PlannedOperation]:
    """``visits`` (P, J) taken phase by phase from the planner's state, each posture's
    nearest first, the ``remounts`` between the phases, each step that fits in the budget
    (readings expected), then the budget spent by :func:`~calibrators.planning.search.
    greedy_plan` without re-mounts."""
    for phase in range(visits.shape[1]):
        if phase:
            if planner.time_s + planner.remount_seconds() > planner.budget_s:
                break
            planner.remount(*remounts[phase - 1])
            planner.expect_readings()
        left = {int(p): int(n) for p, n in enumerate(visits[:, phase]) if n}
        while left:
            seconds, after, reads = planner._moves()
            posture = min(left, key=lambda p: (seconds[p], p))
            if planner.time_s + seconds[posture] > planner.budget_s:
                break
            planner.move(posture, PricedMoves(np.zeros(len(seconds)), seconds, after, reads))
            planner.expect_readings()
            left[posture] -= 1
            if not left[posture]:
                del left[posture]
    return greedy_plan(planner, remounts=False)


def phased_plan(opened: Planner, greedy: tuple[PlannedOperation, ...]
                ) -> tuple[tuple[PlannedOperation, ...], float] | None:
    """The plan of :func:`rounded_plan` from the fresh planner ``opened`` (its opening's
    readings expected; a copy is planned) on the slots and re-mounts of the ``greedy``
    plan, and its predicted error (mm); None where the bound's design does not apply:
    stands not all at the paper's slots with their plungers down, a lab that owns an
    instrument beyond its dials or moves that dwell, or ``ideal`` conditions (the
    bound's model is a world's)."""
    slots = tuple(int(s) for s in opened.slots)
    if (slots != start_slots(opened.design, len(slots)) or not all(opened.engaged)
            or opened.kit is not None or opened.dwell_s or opened.conditions is None):
        return None
    phases, remounts = plan_phases(slots, greedy)
    added = tuple(sorted({s for phase in phases for s in phase} - set(slots)))
    model = lab_model(opened.design, opened.conditions, opened.sigma, opened.budget_s,
                      ("dial",), len(slots))
    grid = dial_grid(model)
    steps: tuple[PlannedOperation, ...] = greedy
    planner = opened
    for _ in range(PASSES):
        design = held_design(opened.design, opened.conditions, opened.sigma,
                             opened.budget_s - overhead_s(steps), ("dial",), added,
                             len(remounts), len(slots), phases=phases, at_contact=True)
        readings = np.where(grid >= 0, design.counts[np.maximum(grid, 0)], 0.0)
        planner = opened.fork()
        steps = tuple(rounded_plan(planner, phase_visits(readings, phases), remounts))
    return steps, planner.predicted_rigid_mm()
