"""The bound with the warm-up unknown (calibrators.planning.warm_bound): above the bound
that knows the warm-up, below a plan's error on its own model."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

from calibrators.agents import optimal
from calibrators.agents.optimal import fixed_plan
from calibrators.planning import warm_bound
from calibrators.planning.bound import best_design, lab_model, plan_hits
from calibrators.planning.instruments import step_actions
from calibrators.planning.warm_bound import (
    plan_value,
    steps_value,
    warm_design,
    warm_models,
    warm_rows,
)
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

LAB = Conditions("lab")
#: Twenty minutes in three bins: the warm-up's curves change most then, and the plan and
#: both bounds take seconds.
BUDGET, BINS = 1200.0, 3


@pytest.fixture(scope="session")
def held():
    with pytest.MonkeyPatch.context() as patch:
        # Fewer steps: the bound stays certified (f - gap), only less tight.
        patch.setattr(warm_bound, "MAX_ITERATIONS", 60)
        return warm_design(PROTOTYPE, LAB, SIGMA, BUDGET, bins=BINS)


def test_the_warm_up_is_read_as_the_fit_reads_it():
    warm = warm_models(PROTOTYPE, LAB, SIGMA, BUDGET, bins=BINS)
    base = warm.models[0]
    rows = [warm_rows(base, PROTOTYPE, LAB, SIGMA, t) for t in (0.0, 600.0, 6 * 3600.0)]
    # Cold, the warm-up moves nothing; its mean term (the first) grows with the lab's
    # time on every reading, as 1 - exp(-t / tau) does.
    assert np.all(rows[0] == 0)
    assert np.all(np.abs(rows[2][:, 0]) >= np.abs(rows[1][:, 0]))
    assert np.any(rows[1][:, 0] != 0)
    # Its terms do not move the tool: the criterion's weight is the bound's.
    assert np.all(warm.models[1].factor[base.rows.shape[1]:] == 0)


def test_it_is_above_the_bound_that_knows_the_warm_up(held):
    design, warm = held
    known = best_design(PROTOTYPE, LAB, SIGMA, BUDGET).bound
    # Its design's readings, summed over the bins, are a design of the bound's problem,
    # and their error there is below their error with the warm-up unknown (a Gaussian
    # posterior only widens with more unknowns): so the design is above the bound.
    model = lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, ("dial",), len(PAPER_SLOTS))
    old = float(np.sqrt(model.value(design.counts.sum(axis=0))))
    assert known.bound_mm <= old <= design.bound.design_mm
    # Each certificate is within its solver's gap of its optimum, so the two bounds'
    # squares differ by no more than the gaps allow.
    assert design.bound.bound_mm**2 >= known.bound_mm**2 - design.bound.gap_mm2
    # The design respects the bins: no bin reads more than its visits' stands.
    most = np.diff(warm.edges) / TIME.settle_and_read_s * len(PAPER_SLOTS)
    assert np.all(design.counts.sum(axis=1) <= most * (1 + 1e-9))


@pytest.mark.slow
def test_a_plan_is_above_it_on_its_model(held):
    design, warm = held
    steps, _ = fixed_plan(PAPER_SLOTS, (True,) * len(PAPER_SLOTS), SIGMA, BUDGET, PROTOTYPE,
                          LAB)
    hits = plan_hits(warm.models[0], PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS),
                     step_actions(steps))
    times = np.array([s.time_s for s in steps])
    error = float(np.sqrt(plan_value(warm, hits, times)))
    # optimal's plan is a plan of the lab, its readings at their bins' times.
    assert design.bound.bound_mm <= error
    # The same readings with the warm-up known: no worse.
    flat = np.bincount(hits[:, 1], minlength=warm.models[0].rows.shape[0]).astype(float)
    known = lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, ("dial",), len(PAPER_SLOTS))
    assert np.sqrt(known.value(flat)) <= error


def test_it_refuses_a_world_without_a_warm_up():
    with pytest.raises(ValueError, match="warm-up"):
        warm_models(PROTOTYPE, Conditions("ideal"), SIGMA, BUDGET)
    with pytest.raises(ValueError, match="bins"):
        warm_models(PROTOTYPE, LAB, SIGMA, BUDGET, bins=0)


@pytest.mark.slow
def test_optimal_keeps_the_plan_the_timed_terms_price_least():
    """In a lab with a warm-up and the bar, ``optimal`` keeps of its candidate plans the one
    least on the model with the timed terms unknown, where the planner's criterion (which
    ``active`` replays) keeps the one it predicts least; with no warm-up the two are one."""
    instruments = ("ballbar",)
    # Ten minutes: two candidates, as in twenty, at 3.4 CPU-s of plans where twenty took 5.8.
    setup = (tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS), SIGMA, 600.0, PROTOTYPE)
    judged = fixed_plan(*setup, LAB, instruments=instruments, warm_judged=True)
    planned = fixed_plan(*setup, LAB, instruments=instruments)
    # Both judges chose among the same candidates, made once.
    plans = optimal._CANDIDATES.made()[(*setup, LAB, "I", True, instruments, 0.0, False)]
    assert len(plans) >= 2  # the greedy plan and the rounded design's
    assert any(judged is p for p in plans) and any(planned is p for p in plans)
    warm = warm_models(PROTOTYPE, LAB, SIGMA, setup[3], ("dial", *instruments))
    values = [steps_value(warm, PROTOTYPE, *setup[:2], steps) for steps, _ in plans]
    # Each judge's plan is the least of the candidates on its own model, so no worse
    # there than the other judge's.
    assert steps_value(warm, PROTOTYPE, *setup[:2], judged[0]) == pytest.approx(min(values),
                                                                                rel=1e-12)
    assert planned[1] == min(p for _, p in plans) <= judged[1]
    # Without a warm-up there is nothing the planner's criterion leaves unpriced: one plan,
    # whatever the budget (ten minutes' plan sets the bar's pivot up): 2 CPU-s of plans,
    # where the twenty minutes' ideal candidates took 21.
    ideal = fixed_plan(*setup, Conditions("ideal"), instruments=instruments)
    assert fixed_plan(*setup, Conditions("ideal"), instruments=instruments,
                      warm_judged=True) is ideal
