"""A dial plan from the bound of its own slots: a plan's re-mounts (and its instruments'
runs) kept, its dials' readings re-chosen by the design of the bound of the plans that
re-mount so.

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
   left spent greedily without re-mounts.  A visit is taken only where the re-mounts and
   laser runs still due fit after it (:func:`due_seconds`), so the plan keeps every one
   of them: a design whose visits overrun the budget loses visits, not what comes last.

In a lab that owns the interferometer or the ballbar the plan's runs of them are kept as
it has them (:func:`plan_runs`: each set-up, the laser's alignment or the bar's pivot, and
the run it opens, in its phase, after the same share of the phase's dial visits), and
their readings are given to the design (:func:`~calibrators.planning.bound.given_model`):
it chooses the dials' readings beside them.  The laser, once set up, also reads at the
dials' moves where every move reads it, so its given readings are those of the last plan
made (they move with its dial visits); the bar comes off at the first operation that is
not a move of its run, and the plungers are lifted while it reads, so its readings are
its runs' alone, the same whatever the dials do.  A design's own laser or bar readings
are no plan's (the bound's model reads the laser at any target on any visit and the bar
at any point of its circles, where a plan reads the laser along one drive at a time and
the bar round the arcs of a pivot's set-up), so rounding them was not tried.

The design is that of the bound's model with each dial reading counted at its a-priori
contact (:func:`~calibrators.planning.bound.at_contact_model`), as the planner expects
readings: rounded from the design counted whole, the plan read where the stands seldom
touch (under ``lab``, one hour, 5.548 um on the bound's model and 6.609 um counted at
contact, against the greedy plan's 6.370 and 6.424 um) and realised no better on 50
machines (docs/instruments.md, "The dial plan read as the bound of its own slots").

The design's budget is the plan's less what the bound leaves out (driving, the levers,
the re-mounts' drives to Zero) and the instruments' part (their runs with their set-ups,
lifts and engages, and the laser's dwell at the dials' moves): first as the plan spends
it, then as the rounded plan does (:data:`PASSES`).  The first pass prices the phased
plan's visits at the plan's overhead, and the phased plan takes more visits (in the
workshop at three hours with the laser, 17-34 % more dial readings), each paying its
drive, levers and the laser's dwell: its rounded plan overruns and, without the reserve
of what is due, dropped its last re-mount or laser run, and the second pass, priced at
that shorter plan, did not get it back.  With the reserve the first rounded plan keeps
them, its visits cut instead, and the second pass is priced at the overhead of a plan
that has all of them.
"""

from __future__ import annotations

import copy

import numpy as np

from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import (
    dial_grid,
    held_design,
    lab_model,
    plan_counts,
    start_slots,
)
from calibrators.planning.instruments import Bundle, InstrumentOperation, step_actions
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.rounding import apportion
from calibrators.planning.search import Planner, greedy_plan, operations, take_fitting
from orthoglide_env.lab.operations import TIME, Op
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM

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
    """The seconds a plan of ``steps`` spends beyond its dials' visits' settles and its
    re-mounts' work (the bound's clock): driving and the levers, and its instruments' runs
    (:func:`plan_runs`, given to the design: :func:`phased_plan`) and the laser's dwell at
    the dials' moves where it reads there."""
    visits = sum(s.op == Op.REMOUNT or (s.op == Op.MOVE and not isinstance(
        s, InstrumentOperation)) for s in steps)
    remounts = sum(s.op == Op.REMOUNT for s in steps)
    return float(steps[-1].time_s - visits * TIME.settle_and_read_s
                 - remounts * TIME.remount_s)


def plan_runs(steps: tuple[PlannedOperation, ...]
              ) -> tuple[tuple[tuple[float, Bundle], ...], ...]:
    """Per phase of a plan of ``steps`` (:func:`plan_phases`), its instruments' runs in
    order: the bundle each set-up (the laser's alignment or the bar's pivot) opens, the
    set-up and the moves it drives until any other operation (the laser's back to Zero;
    the bar's before the operation that takes it off), with the share of the phase's dial
    visits the plan takes before it."""
    runs: list[list[tuple[int, Bundle]]] = [[]]
    visits = [0]
    for i, step in enumerate(steps):
        if step.op == Op.REMOUNT:
            runs.append([])
            visits.append(0)
        elif step.op == Op.MOVE and not isinstance(step, InstrumentOperation):
            visits[-1] += 1
        elif step.op in (Op.ALIGN, Op.PIVOT):
            path = []
            for later in steps[i + 1:]:
                if later.op != Op.MOVE or not isinstance(later, InstrumentOperation):
                    break
                path.append(later.rho)
            runs[-1].append((visits[-1], kept_bundle(step, np.array(
                path, dtype=float).reshape(-1, 3))))
    return tuple(tuple((before / max(total, 1), bundle) for before, bundle in phase)
                 for phase, total in zip(runs, visits, strict=True))


def kept_bundle(setup: PlannedOperation, path: np.ndarray) -> Bundle:
    """The bundle of a plan's set-up operation ``setup`` (an ``ALIGN`` or a ``PIVOT``,
    :class:`~calibrators.planning.instruments.InstrumentOperation`) driving ``path``
    (R, 3): taken again (:func:`~calibrators.planning.search.take`), the same operations."""
    if setup.op == Op.ALIGN:
        axis = setup.axis  # type: ignore[attr-defined]
        return Bundle("interferometer", f"interferometer {'xyz'[axis]} (kept)", Op.ALIGN,
                      path, axis=axis)
    bar = setup.bar  # type: ignore[attr-defined]
    return Bundle("ballbar", f"ballbar {BALLBAR_LENGTHS_MM[bar]:g} mm (kept)", Op.PIVOT, path,
                  centre=tuple(float(v) for v in setup.rho), bar=bar)


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


def due_seconds(planner: Planner, rho: np.ndarray, engaged: np.ndarray,
                items: list[tuple[int, int] | Bundle]) -> float:
    """Seconds the re-mounts (stand, slot) and instrument runs of ``items`` take in turn, nothing
    between them, from posture ``rho`` with the plungers ``engaged`` (K,) and the
    planner's laser as it is: the lab's clock of :meth:`~calibrators.planning.belief.
    Belief.remount_seconds` and :func:`~calibrators.planning.search.operations`."""
    state = copy.copy(planner)  # only the clock's inputs change: no belief is touched
    state.rho, state.engaged = np.asarray(rho, dtype=float), [bool(v) for v in engaged]
    state.kit = None if planner.kit is None else planner.kit.copy()
    seconds = 0.0
    for item in items:
        if isinstance(item, Bundle):
            seconds += operations(state, item)[1]
            # As :func:`~calibrators.planning.search.take` has it: a bar's run soaks no laser.
            state.kit.soaked |= item.setup == Op.ALIGN
        else:
            seconds += state.remount_seconds()
            state.engaged[item[0]] = True
        state.rho = np.zeros(3)
    return seconds


def rounded_plan(planner: Planner, visits: np.ndarray,
                 remounts: tuple[tuple[int, int], ...],
                 runs: tuple[tuple[tuple[float, Bundle], ...], ...] = ()
                 ) -> list[PlannedOperation]:
    """``visits`` (P, J) taken phase by phase from the planner's state, each posture's
    nearest first, the ``remounts`` between the phases and each phase's instrument ``runs``
    (:func:`plan_runs`) once its share of the phase's visits is taken, each step that fits
    in the budget (readings expected), then the budget spent by
    :func:`~calibrators.planning.search.greedy_plan` without re-mounts.

    A visit fits where the re-mounts and runs still due, taken in turn after it
    (:func:`due_seconds`), end within the budget too; where the nearest does not, the
    phase's other visits are dropped.  So every re-mount and run that fits after the
    opening is kept, and a design that overruns the budget (its budget is an estimate
    of the time its visits leave) loses the visits before what is due instead."""
    phases = visits.shape[1]
    kept = [list(runs[phase]) if runs else [] for phase in range(phases)]
    for phase in range(phases):
        if phase:
            if planner.time_s + planner.remount_seconds() > planner.budget_s:
                break
            planner.remount(*remounts[phase - 1])
            planner.expect_readings()
        left = {int(p): int(n) for p, n in enumerate(visits[:, phase]) if n}
        due = kept[phase]
        later = [item for after in range(phase + 1, phases)
                 for item in (remounts[after - 1], *(run for _, run in kept[after]))]
        # The seconds of what is due after a visit, by its posture and plungers: a phase's
        # visits come back to few postures, and what is due changes only with a run.
        reserve: dict[tuple, float] = {}
        total, taken = visits[:, phase].sum(), 0
        while left or due:
            if due and (not left or taken >= due[0][0] * total):
                take_fitting(planner, due.pop(0)[1])
                reserve.clear()
                continue
            seconds, after, reads = planner._moves()
            posture = min(left, key=lambda p: (seconds[p], p))
            down = after[:, posture]
            key = (posture, *(bool(v) for v in down))
            if key not in reserve:
                reserve[key] = due_seconds(planner, planner.table.postures[posture], down,
                                           [run for _, run in due] + later)
            if planner.time_s + seconds[posture] + reserve[key] > planner.budget_s:
                left.clear()
                continue
            planner.move(posture, PricedMoves(np.zeros(len(seconds)), seconds, after, reads))
            planner.expect_readings()
            taken += 1
            left[posture] -= 1
            if not left[posture]:
                del left[posture]
    return greedy_plan(planner, remounts=False)


def phased_plan(opened: Planner, plan: tuple[PlannedOperation, ...]
                ) -> tuple[tuple[PlannedOperation, ...], float] | None:
    """The plan of :func:`rounded_plan` from the fresh planner ``opened`` (its opening's
    readings expected; a copy is planned) on the slots, re-mounts and instrument runs of
    ``plan`` (:func:`plan_runs`), and its predicted error (mm); None where the bound's
    design does not apply: stands not all at the paper's slots with their plungers down,
    moves that dwell from the start, or ``ideal`` conditions (the bound's model is a
    world's).

    The laser's runs and the bar's are the plan's, not the design's: the bound's model
    reads the laser at any target on any visit and the bar at any point of its circles,
    where a plan reads the laser along one drive at a time, in the runs a set-up opens
    (and, in a lab whose every move reads it, at each posture's place along that drive),
    and the bar round its set-up's arcs, so a design's readings of them are no plan's.
    Their readings on the bound's model (the laser's at the last plan's dial moves too;
    the bar reads at none: it comes off before them) are given to the design
    (:func:`~calibrators.planning.bound.given_model`), which chooses the dials' beside
    them over the time the plan's dial visits take."""
    slots = tuple(int(s) for s in opened.slots)
    owned = () if opened.kit is None else opened.kit.owned
    if (slots != start_slots(opened.design, len(slots)) or not all(opened.engaged)
            or opened.dwell_s or opened.conditions is None):
        return None
    phases, remounts = plan_phases(slots, plan)
    runs = plan_runs(plan) if owned else ()
    added = tuple(sorted({s for phase in phases for s in phase} - set(slots)))
    instruments = ("dial", *owned)
    model = lab_model(opened.design, opened.conditions, opened.sigma, opened.budget_s,
                      instruments, len(slots))
    grid = dial_grid(model)
    steps: tuple[PlannedOperation, ...] = plan
    planner = opened
    for _ in range(PASSES):
        # The instruments' readings of the last plan: its runs', and the laser's at its
        # dial moves.
        given = np.where(model.laser != -1, plan_counts(
            model, opened.design, slots, tuple(opened.engaged), step_actions(steps)),
            0.0) if owned else None
        design = held_design(opened.design, opened.conditions, opened.sigma,
                             opened.budget_s - overhead_s(steps), instruments, added,
                             len(remounts), len(slots), setups=(((), False),) if owned
                             else None, phases=phases, at_contact=True, given=given)
        readings = np.where(grid >= 0, design.counts[np.maximum(grid, 0)], 0.0)
        planner = opened.fork()
        steps = tuple(rounded_plan(planner, phase_visits(readings, phases), remounts, runs))
    return steps, planner.predicted_rigid_mm()
