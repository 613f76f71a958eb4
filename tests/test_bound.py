"""The bound (calibrators.planning.bound): a certified lower bound of the continuous
design, equal to the analytic optimum on a tiny problem, below every discrete plan."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibrators.agents.iso230 import drive_steps, runs_for
from calibrators.agents.optimal import fixed_plan
from calibrators.agents.paper import REPETITIONS, paper_plan
from calibrators.planning import bound
from calibrators.planning.bound import (
    Bound,
    BoundModel,
    Budgets,
    bound_model,
    lower_bound,
    plan_counts,
    solve,
)
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.lab.design_belief import rigid_weight
from orthoglide_env.lab.operations import PAPER_SLOTS
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

#: The weighting sigma of the default dials (0.02 mm, 0.01 mm resolution).
SIGMA = float(np.hypot(0.02, 0.01 / np.sqrt(12)))
LAB = Conditions("lab")


def tiny(a: float, b: float) -> BoundModel:
    """Two unknowns of unit prior, each read by one dial candidate (``a``, ``b`` its
    whitened sensitivity), the TCP error their plain sum of squares."""
    rows = np.array([[a, 0.0], [0.0, b]])
    return BoundModel(rows, np.array([-1, -1]), np.array([[0, 0, -1], [1, 0, -1]]),
                      np.eye(2), np.zeros(1))


def test_tiny_problem_meets_its_analytic_optimum():
    # f = 1/(1 + n1 a^2) + 1/(1 + n2 b^2) with n1 + n2 = N: equal marginal gains give
    # n1 = (a - b + N a b^2) / (a b (a + b)).
    a, b, seconds, price = 2.0, 0.5, 30.0, 1.0
    n = seconds / price
    n1 = (a - b + n * a * b**2) / (a * b * (a + b))
    best = 1 / (1 + n1 * a**2) + 1 / (1 + (n - n1) * b**2)
    lower, value, counts = solve(tiny(a, b), Budgets(seconds, price, 2.0, 7.0),
                                 np.zeros(0, dtype=int))
    # The certificate is below the optimum, and the design above it (both by the
    # theory); the solver's stopping rule puts them within GAP_SHARE of each other.
    assert lower <= best + 1e-12 <= value + 2e-12
    assert value - lower <= bound.GAP_SHARE * value
    assert counts[0] == pytest.approx(n1, rel=0.02)


def test_the_laser_pays_its_visit_and_its_dwell():
    # One dial candidate on the first unknown, one laser candidate on the second: the
    # least of f over both budgets, found by brute force over the laser's visits.
    model = BoundModel(np.array([[1.0, 0.0], [0.0, 3.0]]), np.array([-1, 0]),
                       np.array([[0, 0, -1], [-1, 0, 0]]), np.eye(2), np.zeros(1))
    budgets = Budgets(40.0, 5.0 / 6, 2.0, 7.0)
    visits = np.linspace(0.0, budgets.seconds / budgets.visit_s, 200001)
    dials = (budgets.seconds - budgets.laser_s * visits) / budgets.dial_s
    best = np.min(1 / (1 + dials) + 1 / (1 + 9 * visits))
    lower, value, _ = solve(model, budgets, np.array([1]))
    # The grid's step moves f by under 1e-9 here.
    assert lower <= best + 1e-9
    assert value >= best - 1e-9


def test_the_criterion_is_the_planners():
    # The machine's block of the bound's weight is the planner's (trace(W C) after rigid
    # motion), to rounding.
    model = bound_model(PROTOTYPE, LAB, SIGMA, False)
    weight = model.factor @ model.factor.T
    assert np.allclose(weight[:27, :27], rigid_weight(PROTOTYPE), rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def quick():
    """Fewer steps: the bound stays certified (f - gap), only less tight."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(bound, "MAX_ITERATIONS", 40)
        yield


def _plan_mm(model: BoundModel, actions: list[dict]) -> float:
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS), actions)
    return float(np.sqrt(model.value(counts)))


@pytest.mark.slow
def test_bound_is_below_every_discrete_plan(quick):
    # Half an hour: the laser's set-up on one drive fits, and the plans are quick to make.
    budget = 1800.0
    dial = lower_bound(PROTOTYPE, LAB, SIGMA, budget)
    laser = lower_bound(PROTOTYPE, LAB, SIGMA, budget, ("dial", "interferometer"))
    model = bound_model(PROTOTYPE, LAB, SIGMA, True)
    steps, _ = fixed_plan(PAPER_SLOTS, (True,) * len(PAPER_SLOTS), SIGMA, budget, PROTOTYPE,
                          LAB)
    optimal = [{"op": s.op, "rho": s.rho, "stand": s.stand, "slot": s.slot} for s in steps]
    legs = tuple(spec.leg for spec in PAPER_LAYOUT)
    paper = [dict(a) for a in paper_plan(legs, (True,) * len(legs), REPETITIONS, PROTOTYPE)]
    iso = drive_steps(len(PAPER_SLOTS), PROTOTYPE, runs_for(budget, PROTOTYPE))
    plans = {"optimal": _plan_mm(model, optimal), "paper": _plan_mm(model, paper),
             "iso230-2's drives": _plan_mm(model, iso)}
    # Readings count where the nominal tip touches, so each plan's error is finite and
    # above the bound of its instruments; the dial plans are plans of the laser's lab too.
    for name, error in plans.items():
        assert laser.bound_mm <= error, name
        if name != "iso230-2's drives":
            assert dial.bound_mm <= error, name
    # Owning more can only help: the dial-only problem is one of the laser lab's.
    assert laser.bound_mm <= dial.bound_mm
    assert 0 < dial.bound_mm <= dial.design_mm


def test_bound_round_trips_and_refuses_bad_input():
    b = Bound(0.002, 0.0021, 1e-8, (0, 2), 8.5)
    assert Bound.from_dict(b.to_dict()) == b
    with pytest.raises(ValueError, match="unknown bound key"):
        Bound.from_dict({**b.to_dict(), "extra": 1})
    with pytest.raises(ValueError, match="budget_s"):
        lower_bound(PROTOTYPE, LAB, SIGMA, 0.0)
    with pytest.raises(ValueError, match="dial"):
        lower_bound(PROTOTYPE, LAB, SIGMA, 600.0, ("interferometer",))
    with pytest.raises(ValueError, match="dial_sigma"):
        bound_model(PROTOTYPE, LAB, -1.0, False)


def test_compare_rows_carry_the_bound(capsys, quick):
    from calibrators.cli import main

    argv = ["compare", "--machines", "1", "--agents", "paper,optimal", "--estimators", "full",
            "--conditions", "ideal", "--budget", "600", "--seed", "1", "--quiet", "--json"]
    assert main(argv) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main([*argv, "--bound"]) == 0
    out = json.loads(capsys.readouterr().out)
    # The same value in every row, the row's numbers unchanged, the bound named.
    assert {r["bound_mm"] for r in out["rows"]} == {out["bound"]["bound_mm"]}
    assert [{k: v for k, v in r.items() if k != "bound_mm"} for r in out["rows"]] == \
        plain["rows"]
    assert "bound" not in plain and "bound" not in plain["config"]
    assert out["config"]["bound"] is True
    assert any("x the bound" in line for line in out["table"])


def test_the_drives_weight_is_the_predicted_frames():
    # trace(W C) is the square of the rigid RMS the predicted frames give for the same C
    # over the 27 errors and two made-up drive terms (one product against a sum over the
    # grid's targets: equal to rounding).
    from orthoglide_env.model.errors import MachineParams
    from orthoglide_env.scoring.predicted import (
        predicted_tcp_frames_many,
        rigid_weight_with_drives,
    )

    model = MachineParams(design=PROTOTYPE)

    def drive(rho: np.ndarray) -> np.ndarray:
        return np.stack([rho**2 * 1e-4, np.sin(rho / 7.0) * 1e-3], axis=-1)

    weight = rigid_weight_with_drives(model, drive)
    spread = np.random.default_rng(0).normal(size=(29, 29)) * 1e-3
    covariance = spread @ spread.T
    expected = predicted_tcp_frames_many([model], [covariance], None, [drive])[0].rigid.rms
    assert np.sum(weight * covariance) == pytest.approx(expected**2, rel=1e-9)
