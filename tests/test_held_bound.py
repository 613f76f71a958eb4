"""The bound of the plans that re-mount a given number of times at given slots
(calibrators.planning.bound.held_design): between the share relaxation and the plans.

Apart from tests/test_bound.py, whose module-wide fixture cuts the solver's steps: one
check here needs the solver's own stopping rule."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

from calibrators.agents.optimal import fixed_plan
from calibrators.planning.bound import (
    best_design,
    bound_model,
    held_design,
    lower_bound,
    plan_counts,
)
from calibrators.planning.instruments import step_actions
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

LAB = Conditions("lab")


@pytest.mark.slow
def test_whole_re_mounts_bound_between_the_share_relaxation_and_the_plans():
    # B(E, r): the stands held at the paper's slots and E, r whole re-mounts off the budget.
    # Each inequality below is the theory's (held_design's docstring) with the solver's own
    # certificate as the only slack: a certified value is below its problem's optimum, a
    # design's value above it, so no tolerance is needed.
    budget = 600.0
    never = best_design(PROTOTYPE, LAB, SIGMA, budget, remounts=False)
    # No slot and no re-mount: the very problem of the plans that never re-mount.
    nothing = held_design(PROTOTYPE, LAB, SIGMA, budget)
    assert nothing.bound == never.bound
    assert np.array_equal(nothing.counts, never.counts)
    share = lower_bound(PROTOTYPE, LAB, SIGMA, budget)
    empty = held_design(PROTOTYPE, LAB, SIGMA, budget, remounts=1)
    one = held_design(PROTOTYPE, LAB, SIGMA, budget, slots=(0,))
    two = held_design(PROTOTYPE, LAB, SIGMA, budget, slots=(0, 30))
    for held in (empty, one, two):
        # Each is a subset of the share relaxation's polytope: its optimum is above that
        # bound.
        assert held.bound.design_mm >= share.bound_mm
    # A re-mount's time taken off can only raise the optimum...
    assert empty.bound.design_mm >= nothing.bound.bound_mm
    # ...and a slot added at the same re-mounts only lower it; slot 0 (a stand across the
    # x leg near its platform end, where optimal's plans re-mount) is worth its re-mount,
    # beyond both certificates.
    assert one.bound.design_mm < empty.bound.bound_mm
    assert two.bound.bound_mm <= held_design(PROTOTYPE, LAB, SIGMA, budget, slots=(30,),
                                             remounts=2).bound.design_mm
    with pytest.raises(ValueError, match="re-mounts"):
        held_design(PROTOTYPE, LAB, SIGMA, budget, slots=(0, 30), remounts=1)
    with pytest.raises(ValueError, match="no time"):
        held_design(PROTOTYPE, LAB, SIGMA, budget, remounts=5)


@pytest.mark.slow
def test_a_plan_is_above_the_bound_of_its_own_slots_and_re_mounts():
    # optimal's plan of a quarter hour re-mounts once: its readings are a point of the
    # problem of its slots and re-mounts, so that problem's certified value is below the
    # plan's error on the bound's model.
    budget = 900.0
    steps, _ = fixed_plan(PAPER_SLOTS, (True,) * len(PAPER_SLOTS), SIGMA, budget, PROTOTYPE,
                          LAB)
    moved = tuple(s.slot for s in steps if s.op == Op.REMOUNT)
    assert len(moved) >= 1
    own = held_design(PROTOTYPE, LAB, SIGMA, budget, slots=moved, remounts=len(moved))
    model = bound_model(PROTOTYPE, LAB, SIGMA, False)
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS),
                         step_actions(steps))
    assert own.bound.bound_mm <= np.sqrt(model.value(counts))
