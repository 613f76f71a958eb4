"""A dial plan from the bound of its own slots (calibrators.planning.phased): the greedy
plan's re-mounts kept, its readings those of the design of the bound of its phases."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import (
    at_contact_model,
    bound_model,
    held_design,
    plan_counts,
)
from calibrators.planning.instruments import step_actions
from calibrators.planning.phased import phase_visits, phased_plan, plan_phases
from calibrators.planning.search import Planner, greedy_plan
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
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
    # slots is not where the bound's stands start.
    ideal = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, 900.0,
                    design=PROTOTYPE)
    assert phased_plan(ideal, (PlannedOperation(Op.STOP),)) is None
    other = next(s for s in range(len(PAPER_SLOTS) + 1) if s not in PAPER_SLOTS)
    moved = Planner([*PAPER_SLOTS[:-1], other],
                    [True] * len(PAPER_SLOTS), SIGMA, 900.0, design=PROTOTYPE, conditions=LAB)
    assert phased_plan(moved, (PlannedOperation(Op.STOP),)) is None
