"""Experiment design: the Bayesian algebra of the planner, and the designed agents in the lab."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.optimal import fixed_plan
from calibrators.estimators.catalogue import for_study
from calibrators.planning import belief as belief_module
from calibrators.planning.belief import N_MACHINE, SPREAD_SLACK, rigid_weight
from calibrators.planning.search import Planner, greedy_plan
from calibrators.study.episodes import measurements_of, run_episode
from orthoglide_env.lab.operations import PAPER_SLOTS, Op, slot_catalogue
from orthoglide_env.lab.slot_table import reach, slot_table
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import PAPER_POSTURES, axis_postures, paper_posture
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring import predicted_tcp_frames, score

SIGMA = 0.01


def planner(criterion: str = "I", budget_s: float = 600.0) -> Planner:
    p = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, budget_s,
                criterion=criterion, design=PROTOTYPE)
    p.expect_readings()  # the readings of the lab's opening, at Zero
    return p


def test_predicted_error_is_the_scorings_prediction() -> None:
    """``trace(W C)`` is the quadratic form of the scoring's predicted rigid error: the same
    number, for any covariance (the planner's, after some readings)."""
    p = planner()
    for _ in range(5):
        p.greedy_move()
    scale = default_scales(ParameterSpace())
    covariance = p.covariance[:N_MACHINE, :N_MACHINE] * np.outer(scale, scale)
    expected = predicted_tcp_frames(MachineParams(), covariance).rigid.rms
    assert p.predicted_rigid_mm() == pytest.approx(expected, rel=1e-9)
    assert np.allclose(rigid_weight(PROTOTYPE), rigid_weight(PROTOTYPE).T)


def test_a_stands_rows_are_its_slots_changes_in_its_columns() -> None:
    """The rows of a reading (``rows_at``, made at the postures asked for): at every slot
    of the catalogue, the slot's changes over the machine's errors and the mounting's in
    the stand's columns and the zero's scale in its last, bit for bit, nothing elsewhere;
    a stand's rows asked alone or with the others are the same, and the rows the gain
    bounds take over the unknowns a stand touches are those rows' entries there."""
    p = planner()
    postures = np.random.default_rng(1).choice(len(p.table.postures), 41, replace=False)
    table = p.table
    for slot in range(len(slot_catalogue(PROTOTYPE))):
        trial = p.fork()
        if slot not in trial.slots:
            trial.remount(2, slot)
        rows = trial.rows_at(postures)
        for k, at in enumerate(trial.slots):
            columns = trial._columns(k)
            expected = np.zeros((len(postures), len(trial.covariance)))
            expected[:, columns[:-1]] = table.change[at][postures]
            expected[:, columns[-1]] = belief_module.ZERO_SCALE
            assert np.array_equal(rows[:, k].view(np.int64), expected.view(np.int64))
            alone = trial.rows_at(postures, [k])[:, 0]
            assert np.array_equal(alone.view(np.int64), expected.view(np.int64))
            picked, _ = belief_module._touched_block(PROTOTYPE, at)
            used = trial.touched_columns[k, :np.count_nonzero(picked)]
            assert np.array_equal(trial.touched_rows[k][postures][:, :len(used)],
                                  rows[:, k][:, used])
    trial.retire(2)
    assert not trial.rows_at(postures)[:, 2].any()


@pytest.mark.parametrize("criterion", ["I", "D"])
def test_the_price_of_a_move_is_what_taking_it_changes(criterion: str) -> None:
    """The gain the planner quotes for a move (Woodbury, every posture at once) is the
    change of the criterion once that move's readings are added, and the covariance after
    the updates is the inverse of the prior plus the information of every row."""
    p = planner(criterion)
    rng = np.random.default_rng(0)
    rows_so_far = []
    for _ in range(4):
        options = p.priced_moves()
        posture = rng.choice(np.flatnonzero(options.gain > 0))
        trial = p.fork()
        before = (trial.predicted_rigid_mm() ** 2 if criterion == "I"
                  else np.linalg.slogdet(trial.covariance)[1])
        reads = options.reads[:, posture]
        rows = trial.rows[:, posture] * np.sqrt(reads)[:, None] / SIGMA
        trial._add(rows)
        after = (trial.predicted_rigid_mm() ** 2 if criterion == "I"
                 else np.linalg.slogdet(trial.covariance)[1])
        # Either criterion value carries the rounding of a sum over the ~60 unknowns
        # (~1e-14 of its size): a gain far below it is compared to that rounding.
        assert options.gain[posture] == pytest.approx(before - after, rel=1e-7,
                                                      abs=1e-13 * max(abs(before), 1.0))
        rows_so_far.append(rows)
        p._add(rows)
    # Start again from the prior: identity plus every row's information.
    q = Planner(list(PAPER_SLOTS), [True] * 6, SIGMA, 600.0, criterion=criterion,
                design=PROTOTYPE)
    down, chance = q.reading_here()
    first = q.rows[down, q.here] * np.sqrt(chance)[:, None] / SIGMA
    info = first.T @ first + sum(r.T @ r for r in rows_so_far)
    direct = np.linalg.inv(np.eye(len(info)) + info)
    assert np.allclose(p.covariance, direct, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("criterion", ["I", "D"])
def test_the_best_move_is_the_best_of_every_move_priced(criterion: str) -> None:
    """best_move prices only the moves whose bound on the gain can beat the best rate it
    has found.  Over a plan's states, then a filter's (readings observed, a stand
    re-mounted, the budget running out), it takes the move that pricing every move ranks
    first (or none when that does), at the same gains to the bit, each bound at least
    the gain it bounds (up to the rounding, 1e-12 of the largest), and it prices fewer
    than half of the moves where a stand reads."""
    p = planner(criterion, budget_s=400.0)
    rng = np.random.default_rng(3)
    priced = live = 0
    for step in range(40):
        if step == 12:
            p.remount(2, next(s for s in range(len(slot_table(PROTOTYPE).tip)) if s not in p.slots))
        options = p.priced_moves()
        rate = p.affordable_rates(options)
        full = int(np.argmax(rate)) if rate.max() > 0 else None
        choice = p.best_move()
        assert (None if choice is None else choice[0]) == full
        reading = np.flatnonzero(options.reads.any(axis=0))
        bound = p._gain_bounds(options.reads, reading)
        assert np.all(options.gain[reading] <= bound + 1e-12 * bound.max())
        if choice is None:
            break
        gain = choice[1].gain
        assert np.array_equal(gain[~np.isnan(gain)], options.gain[~np.isnan(gain)])
        assert np.array_equal(choice[1].seconds, options.seconds)
        priced, live = priced + np.sum(~np.isnan(gain)), live + len(reading)
        p.move(*choice)
        if step < 8:
            p.expect_readings()
        else:  # a filter: readings near their nominal values
            stands, _ = p.reading_here()
            nominal = slot_table(PROTOTYPE).reading[[p.slots[k] for k in stands], p.here]
            p.observe(list(stands), list(nominal + rng.normal(0.0, 0.05, len(stands))))
    assert choice is None and priced < live / 2
    assert p.mean is not None


def test_the_tcp_on_an_axis_keeps_that_legs_gauges_at_their_zero_distance() -> None:
    """The candidates hold the paper's postures, and wherever the TCP is on a leg's axis
    every gauge of that leg that meets its target is as far from it as at Zero (nominal
    machine): readings a plan can count on."""
    table = slot_table(PROTOTYPE)
    slots = slot_catalogue(PROTOTYPE)
    for leg in range(3):
        along = np.union1d(np.arange(PROTOTYPE.rho_min, PROTOTYPE.rho_max + 1e-9, 20.0),
                           [PROTOTYPE.rho_min, PROTOTYPE.rho_max])
        on_axis = [int(np.flatnonzero(np.all(table.postures == rho, axis=1))[0])
                   for rho in axis_postures(leg, along, PROTOTYPE)]
        mine = [k for k, spec in enumerate(slots) if spec.leg == leg]
        tip = table.tip[np.ix_(mine, on_axis)]
        zero = table.tip[mine, table.zero][:, None]
        met = ~np.isnan(tip)
        assert met[:, on_axis.index(table.zero)].all() and met.mean() > 0.5
        np.testing.assert_allclose(tip[met], np.broadcast_to(zero, tip.shape)[met], atol=1e-9)
    for name in PAPER_POSTURES[1:]:
        assert np.all(table.postures == paper_posture(name, PROTOTYPE), axis=1).any()


@pytest.mark.slow
def test_a_plan_spends_at_most_its_budget_and_the_lab_charges_what_it_planned() -> None:
    """The plan's clock and the lab's are the same time table: replayed on a machine, the
    optimal agent ends exactly when its plan says, within the budget, and no gauge is
    pressed past its travel (the plan keeps three a-priori sigmas clear)."""
    budget = 600.0
    steps, predicted = fixed_plan(tuple(PAPER_SLOTS), (True,) * 6, SIGMA, budget, PROTOTYPE)
    assert steps[-1].op == Op.STOP
    assert steps[-1].time_s <= budget
    # No dial rounding: the agent plans for the same sigma as this test.
    # The plan above is the textbook world's (fixed_plan is given no conditions).
    env = gym.make(orthoglide_env.LAB_ENV_ID, gauge_sigma=SIGMA, gauge_resolution=0.0,
                   budget_s=budget, conditions="ideal")
    for seed in range(3):
        agent = get_agent("optimal")
        observation, info = env.reset(seed=seed)
        agent.reset(env, observation, np.random.default_rng(seed))
        faults = 0
        while True:
            observation, _, terminated, truncated, info = env.step(agent.act(observation, info))
            faults += len(info["overtravel"])
            assert not info["refused"] and not info["collision"]
            if terminated or truncated:
                break
        assert terminated and faults == 0
        assert observation["time"][0] == pytest.approx(steps[-1].time_s, abs=1e-9)
    assert 0 < predicted < 0.7


def test_no_operation_of_a_plan_ends_past_its_budget() -> None:
    """A re-mount is weighed every ``REMOUNT_CHECK_S`` (300 s) of the plan: at 305 s the
    check falls with 5 s left, less than a re-mount's 125 s, and the plan must not take
    one (it did, ending at 432 s: the ``ballbar`` procedure's gauges overran so).  The
    plan's clock is the lab's, so its stop's time is when the lab's episode ends."""
    budget = 305.0
    p = planner(budget_s=budget)
    steps = greedy_plan(p)
    assert steps[-1].op == Op.STOP and steps[-1].time_s <= budget
    assert p.time_s + p.remount_seconds() > budget  # (the re-mount was on offer, and late)


def test_the_designed_plan_beats_the_papers_experiment_at_equal_time() -> None:
    """At the paper procedure's own lab time (about 5 minutes), the optimal plan predicts a
    smaller TCP error after rigid motion than the paper's experiment (both on the nominal
    model, so this is deterministic: 0.017 against 0.032 mm when written)."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, gauge_sigma=SIGMA)
    run_episode(env, get_agent("paper"), 0)
    lab = env.unwrapped
    paper_time = float(lab.records[-1].time_s)
    paper_predicted = lab.predicted_tcp_rigid_mm()
    _, designed = fixed_plan(tuple(PAPER_SLOTS), (True,) * 6, lab.noise.effective_sigma,
                             paper_time, PROTOTYPE)
    assert designed < paper_predicted


@pytest.mark.slow
def test_remounts_are_taken_when_they_pay() -> None:
    """A plan moves stands when that buys accuracy: over 20 minutes it re-mounts at least
    once, and ends with a smaller predicted error than the same greedy plan that may not
    (deterministic, on the nominal model: 0.0076 against 0.0081 mm when written).  Each
    re-mount is a new mounting with fresh unknowns (the covariance block reset to the
    prior, no correlation with the rest)."""
    moving, staying = planner(budget_s=1200.0), planner(budget_s=1200.0)
    steps = greedy_plan(moving)
    greedy_plan(staying, remounts=False)
    assert any(s.op == Op.REMOUNT for s in steps)
    assert moving.predicted_rigid_mm() < staying.predicted_rigid_mm()
    q = planner()
    q.remount(0, len(slot_table(PROTOTYPE).tip) - 1)
    block = q.covariance[N_MACHINE:N_MACHINE + 5]
    assert np.allclose(block[:, N_MACHINE:N_MACHINE + 5], np.eye(5))
    assert np.allclose(np.delete(block, np.s_[N_MACHINE:N_MACHINE + 5], axis=1), 0.0)


def test_active_agents_filter_follows_the_estimator_and_presses_nothing() -> None:
    """The active agent's filter is the extended estimator linearised at the nominal
    machine: after an episode its mean machine puts the tool where the full non-linear fit
    of the same notebook puts it, up to the second-order terms the linearisation drops
    (~delta^2 / L: 2 mm errors over 310 mm legs give 0.013 mm; 0.05 mm is 4 mm errors,
    two sigmas of the realistic preset), against 0.7 mm before calibration; and its
    feedback never presses a gauge."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, gauge_sigma=SIGMA, budget_s=600.0)
    agent = get_agent("active")
    observation, info = env.reset(seed=4)
    agent.reset(env, observation, np.random.default_rng(4))
    lab, est = play_without_faults(env, agent, observation, info)
    filtered = MachineParams.from_vector(
        agent.planner.mean[:N_MACHINE] * default_scales(ParameterSpace()), PROTOTYPE)
    gap = score(filtered, est.machine).tcp_after.rigid.rms
    error = score(est.machine, lab.true_machine).tcp_after.rigid.rms
    assert gap < 0.05
    assert error < 0.05


def play_without_faults(env, agent, observation, info):
    """Let ``agent`` finish its episode, asserting that no step presses a gauge or is
    refused; the lab and its notebook's extended estimate."""
    while True:
        observation, _, terminated, truncated, info = env.step(agent.act(observation, info))
        assert not info["overtravel"] and not info["refused"]
        if terminated or truncated:
            break
    lab = env.unwrapped
    data = measurements_of(lab.records, design=PROTOTYPE)
    return lab, for_study("extended", lab.noise.effective_sigma).fit(data)


@pytest.mark.slow
def test_a_wrong_start_does_not_lock_the_active_agent() -> None:
    """Start the active agent's filter from the estimate of another machine (a draw of
    the prior: every error off by about its a-priori size).  Its margins are the
    filter's own spreads, wide until readings pin a direction down, and each reading
    pulls the mean toward this machine; the full refit at 10 minutes then replaces the
    mean.  So nothing is pressed, and the episode's estimate is as good as usual: within
    3x of the untouched agent's on the same machine (one machine: not a tie; when
    written, the wrong start moved the predicted tips by up to 1 mm and the two episodes
    still took the same steps: the data decide the mean where the margins are narrow)."""
    results = []
    for corrupt in (False, True):
        env = gym.make(orthoglide_env.LAB_ENV_ID, gauge_sigma=SIGMA, budget_s=700.0)
        agent = get_agent("active")
        observation, info = env.reset(seed=6)
        agent.reset(env, observation, np.random.default_rng(6))
        if corrupt:
            before = agent.planner.predicted_tips()
            agent.planner.mean[:N_MACHINE] = np.random.default_rng(1).normal(size=N_MACHINE)
            after = agent.planner.predicted_tips()
            assert np.nanmax(np.abs(after - before)) > 0.5  # a wrong start, in mm of tip
        lab, est = play_without_faults(env, agent, observation, info)
        results.append(score(est.machine, lab.true_machine).tcp_after.rigid.rms)
    assert results[1] < 3 * results[0]


def test_the_filter_computes_only_the_spreads_that_decide_its_reach(monkeypatch) -> None:
    """Once readings are observed, a tip's spread is computed only where it decides
    whether the plunger may be down and how likely it reads; elsewhere the stand's spread
    bound settles it.  Through a filter's decisions and a re-mount, the reach is the one
    every spread computed gives, to the bit, the bound is at least every spread, and
    fewer than a tenth of the spreads are computed (most postures leave a tip off its
    bar, or far from both ends of its travel)."""
    p = planner(budget_s=3600.0)
    rng = np.random.default_rng(5)
    table = slot_table(PROTOTYPE)
    computed = [0]
    spreads_of = belief_module.spreads_many

    def counted(beliefs: list[Planner], machines: np.ndarray, stands: np.ndarray,
                postures: np.ndarray) -> np.ndarray:
        computed[0] += len(postures)
        return spreads_of(beliefs, machines, stands, postures)

    monkeypatch.setattr(belief_module, "spreads_many", counted)
    mine = every = 0
    for step in range(40):
        if step == 20:
            p.remount(1, next(s for s in range(len(table.tip)) if s not in p.slots))
        stands, _ = p.reading_here()
        nominal = table.reading[[p.slots[k] for k in stands], p.here]
        p.observe(list(stands), list(nominal + rng.normal(0.0, SIGMA, len(stands))))
        spread = np.zeros_like(p.spread_bound)
        for k, slot in enumerate(p.slots):
            cols = p._columns(k)[:-1]
            change = table.change[slot]
            spread[k] = np.sqrt(np.clip(np.sum(
                (change @ p.covariance[np.ix_(cols, cols)]) * change, axis=-1), 0.0, None))
        safe, contact = reach(table, np.array(p.slots), p.predicted_tips(), spread)
        before = computed[0]
        got_safe, got_contact = p._reach()
        mine, every = mine + computed[0] - before, every + spread.size
        assert np.array_equal(got_safe, safe)
        assert np.array_equal(got_contact, np.where(p.silent, 0.0, contact))
        assert np.all(spread <= p.spread_bound + SPREAD_SLACK)
        p.move(*p.best_move())
    assert 0 < mine < every / 10


def test_planner_module_keeps_its_earlier_names() -> None:
    """The planner's earlier module and names still import, and name the split modules'
    objects (``Step`` the planned operation, ``Options`` the priced moves)."""
    from calibrators.design import planner as old
    from calibrators.planning import belief, pricing, search
    from calibrators.planning import planner as new

    assert old is new
    assert new.Step is belief.PlannedOperation and new.Options is pricing.PricedMoves
    assert new.Planner is search.Planner and new.greedy_plan is search.greedy_plan
    assert issubclass(search.Planner, pricing.Pricer) and issubclass(pricing.Pricer, belief.Belief)
    p = planner(budget_s=60.0)
    assert np.array_equal(p.options().gain, p.priced_moves().gain)


def test_a_tried_remounts_rows_are_its_stands_own_at_every_gather() -> None:
    """The gain bounds' rows (``touched_at``) of a fork re-mounted once and twice, asked
    once and again, are each stand's own rows at the postures asked, bit for bit, and the
    parent's are left as they were: a re-mount puts its stand's rows in place or stacks
    them anew, never reads another mounting's."""
    parent = planner()
    rng = np.random.default_rng(3)
    postures = np.sort(rng.choice(len(parent.table.postures), 300, replace=False))
    before = parent.touched_at(postures).copy()
    free = [s for s in range(len(slot_catalogue(PROTOTYPE))) if s not in parent.slots]
    trial = parent.fork()
    for stand, slot in ((2, free[0]), (4, free[1])):
        trial.remount(stand, slot)
        for _ in range(2):
            got = trial.touched_at(postures)
            want = np.stack([rows[postures] for rows in trial.touched_rows])
            assert np.array_equal(got, want)
    assert np.array_equal(parent.touched_at(postures), before)


def test_the_world_shortlist_is_the_start_of_a_stable_order() -> None:
    """The moves the world prices are the first of a stable sort of their bounds, found
    by a partition: the same set with ties broken by index and NaN last, whatever the
    values (ties, signed zeros, infinities, NaN)."""
    from calibrators.planning.pricing import _first_of_stable_order
    rng = np.random.default_rng(11)
    for trial in range(2000):
        values = rng.integers(-3, 3, int(rng.integers(1, 50))).astype(float)
        for mark, share in ((-0.0, 0.2), (np.inf, 0.1), (-np.inf, 0.1), (np.nan, 0.2)):
            values[rng.random(len(values)) < share * (trial % 2)] = mark
        count = int(rng.integers(1, 40))
        assert np.array_equal(_first_of_stable_order(values, count),
                              np.sort(np.argsort(values, kind="stable")[:count]))
