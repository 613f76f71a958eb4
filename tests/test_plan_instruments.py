"""The planner over the lab's instruments (calibrators.planning.instruments): a set-up's
own unknowns integrated out exactly, bundles priced and taken, and the bound over the
ballbar below a plan that reads it."""

from __future__ import annotations

import numpy as np
import pytest

from calibrators.agents.optimal import fixed_plan
from calibrators.planning import bound
from calibrators.planning.bound import bound_model, lower_bound, plan_counts
from calibrators.planning.instruments import (
    InstrumentOperation,
    marginal,
    operation_keys,
    planned_bundles,
)
from calibrators.planning.search import Planner
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

SIGMA = float(np.hypot(0.02, 0.01 / np.sqrt(12)))
LAB = Conditions("lab")


def test_marginal_rows_update_as_the_joint_readings_do():
    # Readings over 5 unknowns of interest and 2 of a set-up (unit priors): the equivalent
    # rows and residual give the joint posterior's marginal, mean and covariance, to
    # rounding (both are the same Gaussian algebra, ~1e-12 relative).
    rng = np.random.default_rng(3)
    rows, setup = rng.normal(size=(9, 5)), rng.normal(size=(9, 2)) * 4.0
    residual = rng.normal(size=9)
    joint = np.hstack([rows, setup])
    covariance = np.linalg.inv(np.eye(7) + joint.T @ joint)
    mean = covariance @ joint.T @ residual
    equivalent, innovation = marginal(rows, setup, residual)
    small = np.linalg.inv(np.eye(5) + equivalent.T @ equivalent)
    assert np.allclose(small, covariance[:5, :5], rtol=0, atol=1e-12)
    assert np.allclose(small @ equivalent.T @ innovation, mean[:5], rtol=0, atol=1e-12)


def test_a_lab_of_dials_plans_without_instruments():
    # Owning only dials (or a tracker) gives the planner no kit: today's plans.
    for owned in ((), ("dial",), ("dial", "tracker")):
        planner = Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 600.0, design=PROTOTYPE,
                          conditions=LAB, instruments=owned)
        assert planner.kit is None


def test_instrument_columns_and_the_lead_share():
    # Under lab the planner carries the lead terms the fit fits; their prior share of the
    # TCP error is positive, and the ideal world has none (no lead error to see).
    lab = Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 600.0, design=PROTOTYPE,
                  conditions=LAB, instruments=("dial", "ballbar"))
    plain = Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 600.0, design=PROTOTYPE,
                    conditions=LAB)
    assert len(lab.kit.lead) > 0
    assert lab.predicted_rigid_mm() > plain.predicted_rigid_mm()
    ideal = Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 600.0, design=PROTOTYPE,
                    instruments=("dial", "ballbar", "interferometer"))
    assert len(ideal.kit.lead) == 0
    assert ideal.predicted_rigid_mm() == Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 600.0,
                                                 design=PROTOTYPE).predicted_rigid_mm()


@pytest.fixture(scope="module")
def ballbar_plan():
    """The ``optimal`` plan of half an hour in a lab owning the ballbar (ideal world: the
    geometry alone, quick to plan)."""
    owned = ("dial", "ballbar")
    steps, predicted = fixed_plan(PAPER_SLOTS, (True,) * 6, SIGMA, 1800.0, PROTOTYPE,
                                  instruments=("ballbar",))
    _, plain_predicted = fixed_plan(PAPER_SLOTS, (True,) * 6, SIGMA, 1800.0, PROTOTYPE)
    return owned, steps, predicted, plain_predicted


def test_plan_takes_the_ballbar_and_predicts_less(ballbar_plan):
    _, steps, predicted, plain = ballbar_plan
    taken = planned_bundles(steps, PROTOTYPE, ("ballbar",))
    assert taken and all(b.instrument == "ballbar" for _, b in taken)
    # A pivot's action carries its bar, and the plan's clock stays within the budget.
    pivots = [s for s in steps if s.op == Op.PIVOT]
    assert all(isinstance(s, InstrumentOperation) and "bar" in operation_keys(s)
               for s in pivots)
    assert steps[-1].time_s <= 1800.0
    # Taken only where it buys more per second than the dials: the prediction falls.
    assert predicted < plain


def test_bound_with_the_ballbar_is_below_its_plan(ballbar_plan, monkeypatch):
    # Fewer solver steps: the bound stays certified (f - gap), only less tight.
    monkeypatch.setattr(bound, "MAX_ITERATIONS", 40)
    _, steps, _, _ = ballbar_plan
    ideal = Conditions("ideal")
    with_bar = lower_bound(PROTOTYPE, ideal, SIGMA, 1800.0, ("dial", "ballbar"))
    dial = lower_bound(PROTOTYPE, ideal, SIGMA, 1800.0)
    model = bound_model(PROTOTYPE, ideal, SIGMA, False, True)
    actions = [{"op": s.op, "rho": s.rho, "stand": s.stand, "slot": s.slot,
                **operation_keys(s)} for s in steps]
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * 6, actions)
    # Every bar reading of the plan is a candidate of the bound's.
    driven = sum(len(b.path) for _, b in planned_bundles(steps, PROTOTYPE, ("ballbar",)))
    assert counts[model.laser == bound.BAR].sum() == driven
    assert with_bar.bound_mm <= np.sqrt(model.value(counts))
    # Owning more can only help, and the bar is read where it pays.
    assert with_bar.bound_mm <= dial.bound_mm
    assert with_bar.ballbar_readings > 0

