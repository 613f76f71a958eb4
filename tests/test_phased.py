"""A dial plan from the bound of its own slots (calibrators.planning.phased): the greedy
plan's re-mounts kept, its readings those of the design of the bound of its phases."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import (
    BAR,
    at_contact_model,
    bound_model,
    given_model,
    held_design,
    plan_counts,
)
from calibrators.planning.instruments import InstrumentOperation, bundles, step_actions
from calibrators.planning.phased import (
    due_seconds,
    overhead_s,
    phase_visits,
    phased_plan,
    plan_phases,
    plan_runs,
    rounded_plan,
)
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.search import Planner, expect, greedy_plan, take
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

LAB = Conditions("lab")


def test_a_plans_phases_follow_its_re_mounts():
    steps = (PlannedOperation(Op.MOVE, (1.0, 0.0, 0.0)),
             PlannedOperation(Op.REMOUNT, stand=1, slot=9),
             PlannedOperation(Op.MOVE, (0.0, 1.0, 0.0)),
             PlannedOperation(Op.REMOUNT, stand=0, slot=7),
             PlannedOperation(Op.STOP))
    phases, remounts = plan_phases((0, 1, 2), steps)
    assert phases == ((0, 1, 2), (0, 9, 2), (7, 9, 2))
    assert remounts == ((1, 9), (0, 7))


def test_a_visit_reads_every_mounted_slot_so_the_fewest_visits_share_them():
    # Slot 0 is mounted in both phases, slot 1 in the second only: a visit of the second
    # phase reads both, so 3 visits at the first posture take its 3 readings of slot 0
    # and 2 of slot 1 (5 visits if each read one), and 1 at the third.
    readings = np.array([[3.0, 2.0], [0.0, 0.0], [1.0, 0.0]])
    phases = ((0,), (0, 1))
    visits = phase_visits(readings, phases)
    assert visits.sum() == 4
    covers = np.array([[slot in phase for phase in phases] for slot in (0, 1)])
    assert np.all(visits @ covers.T >= readings)
    with pytest.raises(ValueError, match="in no phase"):
        phase_visits(readings, ((0,),))


def test_counted_at_contact_a_design_is_worth_less_than_counted_whole():
    # Every contact probability is at most 1, so each dial row shrinks and the same
    # counts leave at least the error they leave counted whole (Loewner order).
    model = bound_model(PROTOTYPE, LAB, SIGMA, False)
    counts = np.zeros(model.rows.shape[0])
    counts[::97] = 3.0
    assert at_contact_model(model, PROTOTYPE).value(counts) >= model.value(counts)


@pytest.mark.slow
def test_the_phased_plan_keeps_the_greedy_re_mounts_and_lies_above_their_bound():
    # A quarter hour under lab re-mounts once.  The phased plan mounts the same stands at
    # the same slots in the same order, so its readings are a point of the bound of those
    # phases: that problem's certified value is below the plan on the bound's model, with
    # no tolerance (a certified value is below its optimum).  The phases only take kinds
    # of visit away, so their design is above the bound of the slots without them.
    budget = 900.0

    def opened() -> Planner:
        planner = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, budget,
                          design=PROTOTYPE, conditions=LAB)
        planner.expect_readings()
        return planner

    greedy = tuple(greedy_plan(opened()))
    made = phased_plan(opened(), greedy)
    assert made is not None
    steps, _ = made
    phases, remounts = plan_phases(tuple(PAPER_SLOTS), steps)
    assert (phases, remounts) == plan_phases(tuple(PAPER_SLOTS), greedy)
    assert len(remounts) >= 1 and steps[-1].time_s <= budget
    added = tuple(slot for _, slot in remounts)
    own = held_design(PROTOTYPE, LAB, SIGMA, budget, slots=added, remounts=len(added),
                      phases=phases)
    free = held_design(PROTOTYPE, LAB, SIGMA, budget, slots=added, remounts=len(added))
    assert own.bound.design_mm >= free.bound.bound_mm
    # The ladder's driving and levers rungs take time off the budget: every point of the
    # shorter problem is one of the longer, so its design is above the longer's bound.
    shorter = held_design(PROTOTYPE, LAB, SIGMA, budget - 60.0, slots=added,
                          remounts=len(added), phases=phases)
    assert shorter.bound.design_mm >= own.bound.bound_mm
    model = bound_model(PROTOTYPE, LAB, SIGMA, False)
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS),
                         step_actions(steps))
    assert own.bound.bound_mm <= np.sqrt(model.value(counts))


def test_no_phased_plan_where_the_bound_does_not_hold_the_lab():
    # Under ideal conditions the bound's model is no world's; a stand off the paper's
    # slots is not where the bound's stands start; the bound's visits do not dwell.
    ideal = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, 900.0,
                    design=PROTOTYPE)
    assert phased_plan(ideal, (PlannedOperation(Op.STOP),)) is None
    other = next(s for s in range(len(PAPER_SLOTS) + 1) if s not in PAPER_SLOTS)
    moved = Planner([*PAPER_SLOTS[:-1], other],
                    [True] * len(PAPER_SLOTS), SIGMA, 900.0, design=PROTOTYPE, conditions=LAB)
    assert phased_plan(moved, (PlannedOperation(Op.STOP),)) is None
    dwelling = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, 900.0,
                       design=PROTOTYPE, conditions=LAB, instruments=("ballbar",),
                       dwell_s=1.0)
    assert phased_plan(dwelling, (PlannedOperation(Op.STOP),)) is None


def test_readings_given_to_a_model_count_as_read_before_any_design():
    # f of a design's counts on the model given some laser readings is f of both counts
    # on the model itself (the prior's square root taken out exactly, to rounding).
    model = bound_model(PROTOTYPE, LAB, SIGMA, True)
    rng = np.random.default_rng(3)
    given = np.where(model.laser >= 0, rng.integers(0, 3, len(model.laser)), 0).astype(float)
    counts = np.zeros(len(model.laser))
    counts[rng.choice(np.flatnonzero(model.laser == -1), 200, replace=False)] = 2.0
    counts[np.flatnonzero(model.laser == 1)[::9]] = 1.0
    on_given = given_model(model, given).value(counts)
    assert on_given == pytest.approx(model.value(given + counts), rel=1e-9)
    assert given_model(model, np.zeros(len(model.laser))) is model
    with pytest.raises(ValueError, match="own columns"):
        given_model(model, np.where(model.laser == -1, 1.0, 0.0))


def _opened(budget: float, instrument: str) -> Planner:
    """A fresh planner under lab owning ``instrument``, its opening's readings expected."""
    planner = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, budget,
                      design=PROTOTYPE, conditions=LAB, instruments=(instrument,))
    planner.expect_readings()
    return planner


def _run_plan(budget: float, instrument: str = "interferometer") -> tuple[PlannedOperation, ...]:
    """A plan under lab with ``instrument``: a few dial moves, a re-mount, a few more, its
    first bundle (the laser's run along x, the bar round the XY circle), then the dials
    greedily without re-mounts."""
    planner = _opened(budget, instrument)
    for _ in range(5):
        planner.greedy_move()
    other = next(s for s in range(len(PAPER_SLOTS) + 1) if s not in PAPER_SLOTS)
    planner.remount(0, other)
    planner.expect_readings()
    for _ in range(5):
        planner.greedy_move()
    run = bundles(PROTOTYPE, (instrument,))[0]
    take(planner, run)
    expect(planner, run)
    return tuple(greedy_plan(planner, remounts=False))


def test_a_plans_laser_runs_fall_in_its_phases_at_their_share_of_its_visits():
    steps = (PlannedOperation(Op.MOVE, (1.0, 0.0, 0.0)),
             PlannedOperation(Op.REMOUNT, stand=1, slot=9),
             PlannedOperation(Op.MOVE, (0.0, 1.0, 0.0)),
             InstrumentOperation(Op.LIFT, stand=0),
             InstrumentOperation(Op.ALIGN, axis=2),
             InstrumentOperation(Op.MOVE, (0.0, 0.0, 5.0)),
             InstrumentOperation(Op.MOVE, (0.0, 0.0, 0.0)),
             InstrumentOperation(Op.ENGAGE, stand=0),
             PlannedOperation(Op.MOVE, (0.0, 2.0, 0.0)),
             PlannedOperation(Op.MOVE, (0.0, 3.0, 0.0)),
             PlannedOperation(Op.STOP, time_s=300.0))
    runs = plan_runs(steps)
    assert len(runs) == 2 and runs[0] == ()
    (share, run), = runs[1]
    assert share == pytest.approx(1 / 3) and run.axis == 2 and run.setup == Op.ALIGN
    assert np.array_equal(run.path, [[0.0, 0.0, 5.0], [0.0, 0.0, 0.0]])
    # The bound's clock charges the dials' four moves and the re-mount (a visit and its
    # work), not the laser's run.
    assert overhead_s(steps) == pytest.approx(300.0 - 5 * 5.0 - 120.0)


def test_a_rounded_plan_drops_visits_before_what_is_due_not_what_is_due():
    # Half an hour under lab with the interferometer.  The first phase asks for 400 visits
    # at Zero (2000 s of settles alone, more than the budget), then the laser's run along
    # x (set-up and soak 20 minutes) and a re-mount; the second phase 10 visits.  Taken
    # as they fit, the visits spent the budget and the run and the re-mount were lost:
    # here the visits that would leave no time for them are dropped instead.
    budget = 1800.0
    planner = _opened(budget, "interferometer")
    visits = np.zeros((len(planner.table.postures), 2), dtype=int)
    visits[planner.here] = (400, 10)
    other = next(s for s in range(len(PAPER_SLOTS) + 1) if s not in PAPER_SLOTS)
    laser = next(b for b in bundles(PROTOTYPE, ("interferometer",)) if b.axis == 0)
    # What is due from Zero, as the lab's clock charges it, before anything is taken.
    due = due_seconds(planner, np.zeros(3), np.array(planner.engaged), [laser, (0, other)])
    start = planner.time_s
    steps = rounded_plan(planner, visits, ((0, other),), (((1.0, laser),), ()))
    assert plan_phases(tuple(PAPER_SLOTS), steps) == (
        (tuple(PAPER_SLOTS), (other, *PAPER_SLOTS[1:])), ((0, other),))
    (_, run), = plan_runs(tuple(steps))[0]
    assert run.axis == 0 and np.array_equal(run.path, laser.path)
    assert steps[-1].time_s <= budget
    # The first phase's visits (a settle each, at Zero) stopped where one more would not
    # leave the run and the re-mount their time.
    first = sum(s.op == Op.MOVE and not isinstance(s, InstrumentOperation)
                for s in steps[:next(i for i, s in enumerate(steps) if s.op == Op.ALIGN)])
    settle = TIME.settle_and_read_s
    assert start + settle * first + due <= budget < start + settle * (first + 1) + due


@pytest.mark.slow
def test_the_phased_plan_keeps_a_run_its_plan_takes_last():
    # Forty minutes under lab (the laser's set-up and soak take twenty): a plan that
    # re-mounts once, then visits one posture until the laser's run along x only just
    # fits, and takes it last.  Its visits pay no drive and no levers, the least a visit
    # can cost beyond its settle, so the phased plan's visits, spread over the design's
    # postures, cost more than the plan's time prices them at: its first rounded plan
    # overran, and the run, due last, was dropped (and again at the second pass, priced
    # at the plan without it).  Kept, with the plan's re-mount, within the budget.
    budget = 2400.0
    planner = _opened(budget, "interferometer")
    for _ in range(5):
        planner.greedy_move()
    other = next(s for s in range(len(PAPER_SLOTS) + 1) if s not in PAPER_SLOTS)
    planner.remount(0, other)
    planner.expect_readings()
    laser = next(b for b in bundles(PROTOTYPE, ("interferometer",)) if b.axis == 0)
    while True:
        trial = planner.fork()
        take(trial, laser)
        if trial.time_s > budget - 60.0:
            break
        seconds, after, reads = planner._moves()
        planner.move(planner.here, PricedMoves(np.zeros(len(seconds)), seconds, after, reads))
        planner.expect_readings()
    take(planner, laser)
    expect(planner, laser)
    plan = tuple(greedy_plan(planner, remounts=False))
    made = phased_plan(_opened(budget, "interferometer"), plan)
    assert made is not None
    steps, _ = made
    assert plan_phases(tuple(PAPER_SLOTS), steps) == plan_phases(tuple(PAPER_SLOTS), plan)
    assert [[(run.axis, run.path.tolist()) for _, run in phase] for phase in plan_runs(steps)
            ] == [[], [(0, laser.path.tolist())]]
    assert steps[-1].time_s <= budget


@pytest.mark.slow
def test_the_phased_plan_keeps_a_plans_laser_runs_and_re_mounts():
    # Forty minutes under lab with the interferometer: a plan that re-mounts once and
    # sets the laser up on x.  The phased plan mounts the same stands at the same slots in
    # the same order and drives the same laser run (the same path along the same drive)
    # within the budget, and its readings are a point of the bound of its phases with the
    # laser on x: that certified value is below it on the bound's model.
    budget = 2400.0
    plan = _run_plan(budget)
    made = phased_plan(_opened(budget, "interferometer"), plan)
    assert made is not None
    steps, predicted = made
    phases, remounts = plan_phases(tuple(PAPER_SLOTS), steps)
    assert (phases, remounts) == plan_phases(tuple(PAPER_SLOTS), plan)
    kept = [[(run.axis, run.path.tolist()) for _, run in phase] for phase in plan_runs(plan)]
    assert kept == [[(run.axis, run.path.tolist()) for _, run in phase]
                    for phase in plan_runs(steps)]
    assert any(kept) and steps[-1].time_s <= budget and predicted > 0
    own = held_design(PROTOTYPE, LAB, SIGMA, budget, ("dial", "interferometer"),
                      tuple(slot for _, slot in remounts), len(remounts),
                      setups=(((0,), False),), phases=phases)
    model = bound_model(PROTOTYPE, LAB, SIGMA, True)
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS),
                         step_actions(steps))
    assert own.bound.bound_mm <= np.sqrt(model.value(counts))


def test_a_plans_bar_run_is_kept_as_the_plan_drives_it():
    # The bar's run: its pivot (centre and bar) and the moves round its arcs, up to the
    # operation that takes the bar off; the way back to Zero and the engages are the
    # bundle's own, made again when it is taken.
    run = bundles(PROTOTYPE, ("ballbar",))[0]
    planner = _opened(600.0, "ballbar")
    take(planner, run)
    planner.steps.append(PlannedOperation(Op.STOP, time_s=planner.time_s))
    (share, kept), = plan_runs(tuple(planner.steps))[0]
    assert share == 0.0 and kept.setup == Op.PIVOT and kept.bar == run.bar
    assert kept.centre == run.centre and np.array_equal(kept.path, run.path)
    again = _opened(600.0, "ballbar")
    take(again, kept)
    assert [(s.op, s.rho) for s in again.steps] == [(s.op, s.rho) for s in planner.steps[:-1]]


@pytest.mark.slow
def test_the_phased_plan_keeps_a_plans_bar_runs_and_reads_better_beside_them():
    # Forty minutes under lab with the ballbar: a plan that re-mounts once and reads the
    # bar round the XY circle (and, greedy, once more).  The phased plan mounts the same
    # stands at the same slots in the same order and drives the same bar runs about the
    # same pivot, so on the bound's model it reads the bar exactly as the plan does; its
    # readings are a point of the bound of its phases with the pivot set up (that
    # certified value is below it, no tolerance), and its dials, read as that bound's
    # design beside the bar's readings, leave less error there than the plan's greedy
    # ones (the reason to make it; two deterministic values, no tolerance either).
    budget = 2400.0
    plan = _run_plan(budget, "ballbar")
    made = phased_plan(_opened(budget, "ballbar"), plan)
    assert made is not None
    steps, predicted = made
    phases, remounts = plan_phases(tuple(PAPER_SLOTS), steps)
    assert (phases, remounts) == plan_phases(tuple(PAPER_SLOTS), plan)
    kept = [[(run.centre, run.bar, run.path.tolist()) for _, run in phase]
            for phase in plan_runs(plan)]
    assert kept == [[(run.centre, run.bar, run.path.tolist()) for _, run in phase]
                    for phase in plan_runs(steps)]
    assert any(kept) and steps[-1].time_s <= budget and predicted > 0
    model = bound_model(PROTOTYPE, LAB, SIGMA, False, True)
    counts = [plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS),
                          step_actions(s)) for s in (plan, steps)]
    bar = model.laser == BAR
    assert counts[0][bar].sum() > 0 and np.array_equal(counts[0][bar], counts[1][bar])
    own = held_design(PROTOTYPE, LAB, SIGMA, budget, ("dial", "ballbar"),
                      tuple(slot for _, slot in remounts), len(remounts),
                      setups=(((), True),), phases=phases)
    plan_mm, phased_mm = (np.sqrt(model.value(c)) for c in counts)
    assert own.bound.bound_mm <= phased_mm < plan_mm
