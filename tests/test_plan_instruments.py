"""The planner over the lab's instruments (calibrators.planning.instruments): a set-up's
own unknowns integrated out exactly, a bundle priced and timed as the lab runs it, and
the bound over the ballbar below a plan that reads it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

import orthoglide_env
from calibrators.agents.base import action
from calibrators.agents.optimal import lab_setup, laser_asked, move_dwell_s
from calibrators.planning import bound
from calibrators.planning.bound import bound_model, lower_bound, plan_counts
from calibrators.planning.instruments import (
    bundles,
    marginal,
    operation_keys,
    planned_bundles,
    step_actions,
)
from calibrators.planning.search import Planner, best_bundle, expect, take
from orthoglide_env.instruments.ballbar import BallbarSpec
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

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
def bundle_taken():
    """The best bundle of a lab owning the ballbar (ideal world: the geometry alone), after
    the readings of the episode's opening, taken and its readings expected."""
    planner = Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 1800.0, design=PROTOTYPE,
                      instruments=("dial", "ballbar"))
    planner.expect_readings()
    before = planner.predicted_rigid_mm()
    bundle = best_bundle(planner, 0.0)
    ops = take(planner, bundle)
    expect(planner, bundle)
    return bundle, ops, planner.time_s, before, planner.predicted_rigid_mm()


def test_a_bundle_is_timed_as_the_lab_runs_it(bundle_taken):
    bundle, ops, planned_s, before, after = bundle_taken
    # Any bar reading informs the geometry, so the best bundle gains.
    assert bundle.instrument == "ballbar" and after < before
    env = gym.make(orthoglide_env.LAB_V2_ENV_ID, errors="nominal", backend="exact",
                   conditions="ideal", instruments=["dial", "ballbar"])
    obs, _ = env.reset(seed=0)
    start = float(obs["time"][0])
    for step in ops:
        obs, _, _, _, info = env.step(action(step.op, step.rho, step.stand, step.slot,
                                             **operation_keys(step)))
        assert not info.get("refused"), step
    # The plan's clock is the lab's (one time table), to rounding.
    assert float(obs["time"][0]) - start == pytest.approx(planned_s, abs=1e-6)
    read = [r for r in env.unwrapped.records if isinstance(r.spec, BallbarSpec)]
    assert len(read) == len(bundle.path)
    assert planned_bundles(ops, PROTOTYPE, ("ballbar",))[0][1] == bundle


def test_bound_with_the_ballbar_is_below_a_plan_that_reads_it(bundle_taken, monkeypatch):
    # Fewer solver steps: the bound stays certified (f - gap), only less tight.
    monkeypatch.setattr(bound, "MAX_ITERATIONS", 40)
    bundle, ops, _, _, _ = bundle_taken
    ideal = Conditions("ideal")
    with_bar = lower_bound(PROTOTYPE, ideal, SIGMA, 1800.0, ("dial", "ballbar"))
    dial = lower_bound(PROTOTYPE, ideal, SIGMA, 1800.0)
    model = bound_model(PROTOTYPE, ideal, SIGMA, False, True)
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * 6, step_actions(ops))
    # Every bar reading of the plan is a candidate of the bound's.
    assert counts[model.laser == bound.BAR].sum() == len(bundle.path)
    assert with_bar.bound_mm <= np.sqrt(model.value(counts))
    # Owning more can only help, and the bar is read where it pays.
    assert with_bar.bound_mm <= dial.bound_mm
    assert with_bar.ballbar_readings > 0


@pytest.mark.parametrize("world", ["ideal", "lab", "workshop"])
def test_the_planner_s_bar_rows_are_the_fit_s(world):
    # The planner's and the bound's rows of one bar set-up's readings are the rows the
    # ``full`` fit linearises at the nominal machine, built here the fit's way: the
    # Jacobian over the machine's errors; its fitted lead terms' columns from
    # consider_terms (the pitch table and the screw's periodic error, each moving the TCP
    # the bar reads and, through the pivot, the bar's other end at the set-up's centre
    # command); the pivot's centre per unit of the fit's prior (pivot_sigmas without the
    # drives, as gauss_newton sets it); every column whitened by the bar's sigma.  Both
    # sides are the same sums of the same products, so they agree to rounding (1e-12 of
    # the largest entry, against ~1e-16 a product); rows that leave the pivot fixed, or
    # price the drives' errors at the centre in its prior, miss by the pivot's part (its
    # share is checked to be most of a lead column's size, and the prior 1.7-2.8x wider).
    from calibrators.estimators.consider import (
        DEFAULT_NODE_SPACING,
        FULL_TERMS,
        consider_terms,
        lead_terms,
        pivot_sigmas,
    )
    from calibrators.estimators.exact_fit import world_columns
    from calibrators.planning.instruments import bar_layout, reading_rows
    from orthoglide_env.instruments import ballbar
    from orthoglide_env.reading_model import (
        BALLBAR_CENTRE_SCALE,
        default_scales,
        jacobian,
        pivot_derivatives,
    )

    conditions = Conditions(world)
    bar = next(b for b in bundles(PROTOTYPE, ("ballbar",)) if b.instrument == "ballbar")
    rows, setup, nominal = reading_rows(bar, PROTOTYPE, conditions, bar.path)
    layout = bar_layout(bar, PROTOTYPE, bar.path)
    space = layout.space
    derivative = jacobian(np.zeros(len(space)), layout, np.ones(len(space), dtype=bool),
                          default_scales(space))
    times = np.zeros((1, len(layout)))  # the lead error is not timed
    terms = consider_terms(layout, nominal[None], times, conditions, DEFAULT_NODE_SPACING)
    fitted, _ = terms.split((*FULL_TERMS, "periodic"))
    lead, _ = fitted.split(("lead", "periodic"))
    names = [n for n, _ in lead_terms(bar.path, PROTOTYPE, conditions, DEFAULT_NODE_SPACING)]
    assert list(lead.names) == names  # the planner's lead columns, in its order
    prior = pivot_sigmas(layout, conditions, drives=False)
    sigma = ballbar.sigma(conditions)
    expected = np.hstack([derivative[:, :27], world_columns(layout, lead)[0]]) / sigma
    expected_setup = derivative[:, 27:] * prior / BALLBAR_CENTRE_SCALE / sigma
    assert rows.shape == expected.shape and setup.shape == (len(layout), 4)
    tolerance = 1e-12 * np.abs(expected).max()
    assert np.allclose(rows, expected, rtol=0, atol=tolerance)
    assert np.allclose(setup[:, :3], expected_setup, rtol=0, atol=1e-12 * np.abs(
        expected_setup).max())
    if world == "ideal":
        assert not names and np.allclose(prior, ballbar.centring_sigma(), rtol=1e-12)
        return
    # The pivot's part of the lead columns is not a rounding: the TCP's part alone (the
    # pivot fixed) misses by most of a column's size.
    through_pivot = np.einsum("na,nak->nk", pivot_derivatives(layout), lead.pivot[0]) / sigma
    assert np.abs(through_pivot).max() > 0.5 * np.abs(expected[:, 27:]).max()
    assert np.all(pivot_sigmas(layout, conditions) > 1.7 * prior)


def test_a_plan_started_with_the_laser_set_up_moves_on_the_lab_s_clock():
    """A reference procedure leaves the interferometer set up, and the lab then charges
    every move its dwell: a planner started there (the gauges' part) prices each move as
    the lab charges it, and one told nothing of the laser would run behind the lab's
    clock by the dwell per move."""
    env = gym.make(orthoglide_env.LAB_V1_ENV_ID, errors="nominal", backend="exact",
                   conditions="ideal", instruments=["dial", "interferometer"])
    obs, _ = env.reset(seed=0)
    assert move_dwell_s(obs) == 0.0
    obs, *_ = env.step(action(Op.ALIGN, axis=2))
    dwell = move_dwell_s(obs)
    assert dwell == TIME.interferometer_target_s > 0
    slots, engaged, sigma, budget, design, conditions = lab_setup(env.unwrapped, obs)
    planner = Planner(list(slots), list(engaged), sigma, budget, design=design,
                      conditions=conditions, dwell_s=dwell)
    unaware = planner.fork()
    unaware.dwell_s = 0.0
    moved = 0
    for posture in np.flatnonzero(planner.table.postures[:, 2] != 0)[::40]:
        priced = planner.priced_moves()
        if not np.array_equal(priced.engaged[:, posture], planner.engaged):
            continue  # a plunger's lever would be a step of its own
        obs, _, _, _, info = env.step(action(Op.MOVE, planner.table.postures[posture]))
        assert not info.get("refused")
        assert info["step_time_s"] == priced.seconds[posture]
        assert (info["step_time_s"] - unaware.priced_moves().seconds[posture]
                == pytest.approx(dwell, abs=1e-12))
        planner.move(int(posture), priced)
        unaware.move(int(posture), unaware.priced_moves())
        moved += 1
    assert moved >= 3


def test_a_plan_for_v4_reads_the_laser_on_its_run_only():
    """In ``OrthoglideLab-v4`` a plan reads the laser on its bundle's run (its set-up at
    Zero and every target) and leaves it unread on the dials' moves after it, which pay no
    dwell: the plan's clock is the lab's, and the bound's counter counts the laser
    readings the lab took."""
    env = gym.make(orthoglide_env.LAB_V4_ENV_ID, errors="nominal", backend="exact",
                   conditions="ideal", instruments=["dial", "interferometer"])
    obs, _ = env.reset(seed=0)
    assert laser_asked(env.unwrapped)
    slots, engaged, sigma, budget, design, conditions = lab_setup(env.unwrapped, obs)
    planner = Planner(list(slots), list(engaged), sigma, budget, design=design,
                      conditions=conditions, instruments=("interferometer",),
                      dwell_s=move_dwell_s(obs, True), laser_asked=True)
    bundle = next(b for b in bundles(design, ("interferometer",)) if b.axis == 2)
    ops = take(planner, bundle)
    assert planner.dwell_s == 0.0
    for posture in np.flatnonzero(planner.table.postures[:, 2] != 0)[::60]:
        priced = planner.priced_moves()
        if np.array_equal(priced.engaged[:, posture], planner.engaged):
            planner.move(int(posture), priced)
    played = list(ops) + [s for s in planner.steps if s.op == Op.MOVE and s not in ops]
    assert len(played) > len(ops) + 2
    start = float(obs["time"][0])
    valid = []
    for step in played:
        obs, _, _, _, info = env.step(action(step.op, step.rho, step.stand, step.slot,
                                             **operation_keys(step)))
        assert not info["refused"], step
        if step.op == Op.MOVE:
            valid.append(int(obs["interferometer_valid"][0]))
    assert float(obs["time"][0]) - start == pytest.approx(planner.time_s, abs=1e-6)
    runs = len(bundle.path)
    assert valid == [1] * runs + [0] * (len(valid) - runs)
    model = bound_model(PROTOTYPE, Conditions("ideal"), SIGMA, True)
    counts = plan_counts(model, PROTOTYPE, slots, engaged, step_actions(played))
    taken = [r for r in env.unwrapped.records if isinstance(r.spec, InterferometerAxis)]
    assert counts[model.laser >= 0].sum() == len(taken) == runs + 1


@pytest.mark.parametrize("every_move", [True, False])
def test_optimal_plans_for_the_laser_at_every_move_unless_told(monkeypatch, every_move):
    """In ``OrthoglideLab-v4`` ``optimal`` plans as in v1-v3, the laser read (and its dwell
    paid) at every move once set up, unless its ``laser_at_every_move`` is off: what the
    planner is told is what the lab's moves will do (leaving the laser unread was measured
    and not kept, docs/instruments.md)."""
    import calibrators.agents.optimal as optimal

    told = {}

    def fixed_plan(*args, **kwargs):
        told.update(kwargs)
        return (), 0.0

    monkeypatch.setattr(optimal, "fixed_plan", fixed_plan)
    env = gym.make(orthoglide_env.LAB_V4_ENV_ID, errors="nominal", backend="exact",
                   conditions="ideal", instruments=["dial", "interferometer"])
    obs, _ = env.reset(seed=0)
    agent = optimal.OptimalAgent()
    agent.laser_at_every_move = every_move
    agent.env = env.unwrapped
    agent.reserved_s = 0.0
    agent.make_plan(obs)
    assert told["laser_asked"] is (not every_move)
