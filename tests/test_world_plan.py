"""Experiment design with the lab's world: the planner's world terms and what they do to
a plan."""

from __future__ import annotations

import os

import numpy as np
import pytest

from calibrators.agents import get_agent, optimal
from calibrators.agents.optimal import fixed_plan, handed_plans, made_plans
from calibrators.planning.belief import (
    N_MACHINE,
    N_STAND,
    PlannedOperation,
    _missed,
    entries,
    observe_many,
    predicted_tips_many,
    rows_here_many,
    tips_at,
    world_rows_here,
)
from calibrators.planning.pricing import WORLD_SHORTLIST, top_rates_many
from calibrators.planning.search import (
    LOOKAHEAD_MOVES,
    Planner,
    _spread,
    best_moves,
    greedy_plan,
    lookahead_rates,
    screening_over,
)
from calibrators.study.compare import Config, run_chunk, shared_start
from orthoglide_env.lab import slot_table as tables
from orthoglide_env.lab.kept import Kept
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

SIGMA = 0.02
LAB = Conditions("lab")


def planner(conditions: Conditions | None, budget_s: float = 120.0) -> Planner:
    p = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), SIGMA, budget_s,
                conditions=conditions, design=PROTOTYPE)
    p.expect_readings()  # the readings of the lab's opening, at Zero
    return p


def test_ideal_conditions_plan_as_without_conditions() -> None:
    """Under ``ideal`` the planner has no world terms: the same plan, step for step, and
    the same predicted error to the last bit as a planner told nothing."""
    plans = []
    for conditions in (None, Conditions("ideal")):
        p = planner(conditions)
        assert p.world is None
        plans.append((greedy_plan(p, remounts=False), p.predicted_rigid_mm()))
    assert plans[0] == plans[1]


def test_lab_terms_enlarge_the_state_and_the_predicted_error() -> None:
    """Under ``lab`` the state holds the drives' and the stands' drift unknowns, and the
    indicators' curves bias the estimate: after the same moves, the predicted error is
    larger than the ideal planner's, by the considered terms' part and more."""
    ideal, lab = planner(None), planner(LAB)
    assert len(lab.covariance) == len(ideal.covariance) + lab.world.count
    for _ in range(6):
        choice = ideal.best_move()
        assert choice is not None
        posture = choice[0]
        ideal.move(posture, choice[1])
        ideal.expect_readings()
        lab.move(posture, lab.priced_moves())
        lab.expect_readings()
    bias = lab.world.bias(lab.weight)
    assert bias > 0
    known = np.trace(lab.weight @ lab.covariance[:N_MACHINE, :N_MACHINE])
    assert lab.predicted_rigid_mm() ** 2 == pytest.approx(known + bias, rel=1e-12)
    assert lab.predicted_rigid_mm() > ideal.predicted_rigid_mm()


def test_schmidt_updates_are_the_batch_consider_covariance() -> None:
    """Readings added one batch at a time leave ``D`` = ``P R^T Dc``, the batch
    consider analysis of all of them (``P`` the posterior covariance, ``R`` and ``Dc``
    the whitened rows over the fitted and the considered unknowns): what the ``full``
    estimator's consider covariance is for the same readings."""
    p = planner(LAB)
    prior, n, m = p.covariance.copy(), len(p.covariance), p.world.consider.shape[1]
    start = p.world.consider.copy()
    rng = np.random.default_rng(1)
    rows = [rng.normal(size=(3, n)) for _ in range(4)]
    considered = [rng.normal(size=(3, m)) for _ in range(4)]
    for r, d in zip(rows, considered, strict=True):
        p._add(r, considered=d)
    r, d = np.vstack(rows), np.vstack(considered)
    posterior = np.linalg.inv(np.linalg.inv(prior) + r.T @ r)
    # The opening's readings left a bias ``start`` with their own covariance ``prior``.
    expected = posterior @ (np.linalg.solve(prior, start) + r.T @ d)
    assert np.allclose(p.covariance, posterior, atol=1e-9)
    assert np.allclose(p.world.consider, expected, atol=1e-9)


def test_the_price_of_a_move_under_lab_is_what_taking_it_changes() -> None:
    """Under ``lab`` the gain the planner quotes for a move (the world's rows at the
    move's time and direction, the considered terms' bias included) is the fall of the
    predicted mean-square error once the move is taken and its readings expected."""
    p = planner(LAB)
    rng = np.random.default_rng(0)
    for _ in range(3):
        options = p.priced_moves()
        posture = int(rng.choice(np.flatnonzero(options.seconds < 10)))
        trial = p.fork()
        before = trial.predicted_rigid_mm() ** 2
        trial.move(posture, options)
        trial.expect_readings(np.arange(len(PAPER_SLOTS)), options.reads[:, posture])
        after = trial.predicted_rigid_mm() ** 2
        assert options.gain[posture] == pytest.approx(before - after, rel=1e-6, abs=1e-14)
        p.move(posture, options)
        p.expect_readings(np.arange(len(PAPER_SLOTS)), options.reads[:, posture])


def test_backlash_makes_a_moves_direction_count() -> None:
    """A posture read after driving up to it is not read as one reached coming down: the
    backlash unknowns' rows change sign with the axes' direction of travel."""
    p = planner(Conditions("lab", effects=("backlash",)))
    here = np.flatnonzero(np.all(p.table.postures == [20.0, 0.0, 0.0], axis=1))[0]
    slots = np.array(p.slots)
    times = np.zeros(1)
    up, _ = p.world.rows(slots, np.array([here]), times, np.ones((1, 3)))
    down, _ = p.world.rows(slots, np.array([here]), times, -np.ones((1, 3)))
    assert np.abs(up).max() > 0
    assert np.allclose(up, -down)


def test_a_lab_plan_ends_with_a_stop_within_its_budget() -> None:
    """Under ``lab`` a greedy plan is a plan: it ends with a stop and keeps to its budget
    (it may stop before it)."""
    p = planner(LAB, budget_s=90.0)
    steps = greedy_plan(p, remounts=False)
    assert steps[-1].op == Op.STOP
    assert steps[-1].time_s <= 90.0


def test_a_subset_of_stands_gets_those_stands_rows() -> None:
    """The world's rows of some stands' readings are those stands' rows among every
    stand's: each stand's drift and indicator columns are its own, whichever others are
    read with it."""
    p = planner(LAB)
    for _ in range(3):
        p.greedy_move()
    slots, here = np.array(p.slots), np.array([p.here])
    times, approach = np.array([p.time_s]), p.world.approach[None]
    every = p.world.rows(slots, here, times, approach)
    some = np.array([4, 1])
    part = p.world.rows(slots, here, times, approach, some)
    for whole, subset in zip(every, part, strict=True):
        assert np.array_equal(subset, whole[some])


def test_the_world_prices_the_bounds_shortlist_and_zero() -> None:
    """Under ``lab`` a move is priced with the world's terms only if its geometric gain
    bound per second is among the :data:`WORLD_SHORTLIST` highest, or it goes to Zero;
    each priced gain is the one pricing every move gives it, and the best move is the
    best of them."""
    p = planner(LAB, budget_s=600.0)
    for _ in range(5):
        p.greedy_move()
    rate, options = p.top_rates(1)
    priced = np.flatnonzero(np.isfinite(rate))
    seconds, _, reads = p._moves()
    live = np.flatnonzero((p.time_s + seconds <= p.budget_s) & reads.any(axis=0))
    ceiling = p._gain_bounds(reads, live) / seconds[live]
    top = live[np.argsort(-ceiling, kind="stable")[:WORLD_SHORTLIST]]
    assert set(priced) == set(top) | {p.table.zero}
    every = p.priced_moves()
    assert np.allclose(options.gain[priced], every.gain[priced], rtol=1e-9, atol=0.0)
    choice = p.best_move()
    assert choice is not None and choice[0] == priced[np.argmax(rate[priced])]


def test_a_lab_plan_ends_only_when_no_move_pays() -> None:
    """A plan under ``lab`` ends when the best of every move priced, not only of the
    shortlist, falls under the stop rule (or gains nothing)."""
    p = planner(LAB, budget_s=600.0)
    greedy_plan(p, remounts=False)
    rate = p.affordable_rates(p.priced_moves())
    assert p._ends(float(np.max(rate)))


@pytest.mark.slow
def test_optimal_stay_never_remounts() -> None:
    """``optimal-stay``'s plan keeps the set-up's stands where ``optimal``'s moves some,
    and is a plan: it ends with a stop within its budget."""
    setup = (tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS), SIGMA, 900.0, PROTOTYPE, LAB)
    moving, _ = fixed_plan(*setup)
    staying, _ = fixed_plan(*setup, remounts=False)
    assert any(s.op == Op.REMOUNT for s in moving)
    assert not any(s.op == Op.REMOUNT for s in staying)
    assert staying[-1].op == Op.STOP and staying[-1].time_s <= 900.0
    assert get_agent("optimal-stay").remounts is False


def test_filters_priced_together_price_as_each_alone() -> None:
    """The ``active`` agent's chunk prices its machines' moves together
    (:func:`~calibrators.planning.pricing.top_rates_many`, the stands' reach stacked over
    the filters): each filter's rates, gains, seconds, plungers and readings are its own
    alone to the bit, and :func:`~calibrators.planning.search.best_moves` its own choice,
    through filters of different readings, clocks and stands (two re-mounted); their
    readings taken in together (:func:`~calibrators.planning.belief.observe_many`) leave
    each filter's mean, covariance and considered terms as alone, to the bit."""
    rng = np.random.default_rng(11)
    filters = []
    for steps in (3, 8, 14):
        p = planner(LAB, budget_s=1200.0)
        for step in range(steps):
            if step == 6:
                p.remount(1, next(s for s in range(len(p.table.tip)) if s not in p.slots))
            stands, _ = p.reading_here()
            nominal = p.table.reading[[p.slots[k] for k in stands], p.here]
            p.observe(list(stands), list(nominal + rng.normal(0.0, SIGMA, len(stands))))
            p.move(*p.best_move())
        filters.append(p)
    assert len({tuple(p.slots) for p in filters}) == 2
    # The stacked tips are each stand's own product with its mean, as one belief made it
    # before it was a batch of one (a stacked product's items are BLAS's lone products).
    for p, tips in zip(filters, predicted_tips_many(filters), strict=True):
        for k, slot in enumerate(p.slots):
            columns = np.r_[:N_MACHINE, N_MACHINE + N_STAND * k + np.arange(N_STAND - 1)]
            own = p.table.change[slot] @ p.mean[columns]
            np.testing.assert_array_equal(tips[k], p.table.tip[slot] + p.table.sign[slot] * own)
    # At any entries alone (the moves' pricing asks a few hundred postures a stand), the
    # same tips to the bit: counts of postures that are and are not multiples of four,
    # where the tip meets its bar (elsewhere it is NaN whatever the product).
    full = predicted_tips_many(filters)
    meets = np.flatnonzero(~np.isnan(full))
    for size in (1, 2, 3, 4, 5, 7, 301, meets.size - 1):
        asked = np.unravel_index(np.sort(rng.choice(meets, size, replace=False)), full.shape)
        np.testing.assert_array_equal(tips_at(filters, asked), full[asked])
    np.testing.assert_array_equal(_missed(filters, np.maximum([p.slots for p in filters], 0)),
                                  np.isnan(full))
    alone = [p.fork().top_rates(1) for p in filters]
    together = top_rates_many([p.fork() for p in filters], 1)
    for (rate, priced), (rate_, priced_) in zip(alone, together, strict=True):
        np.testing.assert_array_equal(rate_, rate)
        for field, field_ in zip(priced, priced_, strict=True):
            np.testing.assert_array_equal(field_, field)
    chosen = best_moves([p.fork() for p in filters])
    for p, choice in zip(filters, chosen, strict=True):
        assert choice is not None and choice[0] == p.fork().best_move()[0]
    # Their readings taken in together: each filter's update is its own alone.
    reads = []
    for p in filters:
        stands, _ = p.reading_here()
        nominal = p.table.reading[[p.slots[k] for k in stands], p.here]
        reads.append((list(stands), list(nominal + rng.normal(0.0, SIGMA, len(stands)))))
    # Each filter's rows here, made with every other's stands', are its rows of the
    # stands it reads alone, the world's added.
    for p, (stands, _), (rows, _) in zip(filters, reads, rows_here_many(
            filters, [s for s, _ in reads]), strict=True):
        own = p.rows_at(np.array([p.here]), stands)[0].copy()
        fitted, _ = world_rows_here([p], [np.array(stands)])[0]
        own[:, p.world.start:p.world.start + p.world.count] += fitted
        np.testing.assert_array_equal(rows, own)
    alone, together = [p.fork() for p in filters], [p.fork() for p in filters]
    assert len({len(s) for s, _ in reads}) < len(reads)  # some stacked together
    for p, (stands, values) in zip(alone, reads, strict=True):
        p.observe(stands, values)
    observe_many(together, [s for s, _ in reads], [v for _, v in reads])
    for p, q in zip(alone, together, strict=True):
        for name in ("mean", "covariance"):
            np.testing.assert_array_equal(getattr(q, name), getattr(p, name))
        np.testing.assert_array_equal(q.world.consider, p.world.consider)


def test_entries_are_the_nonzero_indices() -> None:
    """The reach's entries found from a mask's flat index are ``np.nonzero``'s index
    arrays, in its order and type, whatever the shape and however many are set."""
    rng = np.random.default_rng(3)
    for shape in ((7,), (3, 5), (4, 6, 9), (2, 1, 3), (3, 0, 2)):
        for share in (0.0, 0.05, 0.5, 1.0):
            mask = rng.random(shape) < share
            got, want = entries(mask), np.nonzero(mask)
            assert len(got) == len(want)
            for a, b in zip(got, want, strict=True):
                assert a.dtype == b.dtype
                np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_a_remount_checks_options_priced_together_as_each_alone() -> None:
    """A re-mount check (:meth:`~calibrators.planning.search.Planner.best_remount`) screens
    its options and plays the best out together: copies re-mounted together, their
    opening readings expected together (:func:`~calibrators.planning.belief.expect_many`),
    hold each its own covariance and considered terms alone; their moves priced together
    (:func:`~calibrators.planning.pricing.top_rates_many` of plans, whose reach is their
    table's) are each one's own alone; and their look-aheads played together
    (:func:`~calibrators.planning.search.lookahead_rates`) are each one's greedy moves
    taken alone, to the bit, through options that run out of budget before the
    look-ahead's last move and one that does not."""
    p = planner(LAB, budget_s=420.0)
    for _ in range(5):
        assert p.greedy_move()
    free = [s for s in range(len(p.table.tip)) if s not in p.slots]
    options = [(0, free[0]), (0, free[9]), (3, free[4]), (5, free[-1])]
    together = p._remounted(options)
    for (stand, slot), trial in zip(options, together, strict=True):
        alone = p.fork()
        alone.remount(stand, slot)
        alone.expect_readings()
        np.testing.assert_array_equal(trial.covariance, alone.covariance)
        np.testing.assert_array_equal(trial.world.consider, alone.world.consider)
    alone_rates = [t.fork().top_rates(LOOKAHEAD_MOVES) for t in together]
    for (rate, priced), (rate_, priced_) in zip(
            alone_rates, top_rates_many([t.fork() for t in together], LOOKAHEAD_MOVES),
            strict=True):
        np.testing.assert_array_equal(rate_, rate)
        for field, field_ in zip(priced, priced_, strict=True):
            np.testing.assert_array_equal(field_, field)

    def played_alone(option: Planner) -> tuple[float, int]:
        trial = option.fork()
        moves = 0
        while moves < LOOKAHEAD_MOVES and trial.greedy_move():
            moves += 1
        return (start - trial._criterion_value()) / (trial.time_s - p.time_s), moves

    start = p._criterion_value()
    played = [p, *together]
    alone = [played_alone(option) for option in played]
    assert {moves for _, moves in alone} > {LOOKAHEAD_MOVES}  # some run out, one does not
    assert lookahead_rates(played, start, p.time_s) == [rate for rate, _ in alone]


def test_spread_answers_in_order_from_forks() -> None:
    """Under :func:`~calibrators.planning.search.screening_over` a screening's items are
    answered in their order, the later part by a fork of this process (another pid) that
    holds the caller's state; outside it, all here."""
    def pids(items: list[int]) -> list[tuple[int, int]]:
        return [(item, os.getpid()) for item in items]

    with screening_over(2):
        spread = _spread(pids, list(range(7)))
    assert [item for item, _ in spread] == list(range(7))
    assert [pid for _, pid in spread[:4]] == [os.getpid()] * 4
    assert {pid for _, pid in spread[4:]} - {os.getpid()}
    assert {pid for _, pid in _spread(pids, list(range(7)))} == {os.getpid()}


@pytest.mark.slow
def test_a_remount_check_spread_over_processes_chooses_as_in_one() -> None:
    """A re-mount check whose screening and play-outs are spread over two processes (a
    sweep's start-up plan, :func:`~calibrators.study.compare.shared_start`) screens and
    plays out its options with the same numbers, to the bit, as in one process, and
    makes the same choice."""
    p = planner(LAB, budget_s=420.0)
    for _ in range(5):
        assert p.greedy_move()
    start = p._criterion_value()
    options = [[(0, slot)] for slot in range(len(p.table.tip)) if slot not in p.slots][:6]
    screened = [rate for chunk in options for rate in p._screening_rates([chunk], start)]
    groups = [[None, options[0][0]], [options[1][0], options[2][0]]]
    played = [rate for group in groups for rate in p._played_rates(group, start)]
    with screening_over(2):
        assert _spread(lambda part: p._screening_rates(part, start), options) == screened
        assert _spread(lambda part: [rate for group in part
                                     for rate in p._played_rates(group, start)],
                       groups) == played
        choice = p.fork().best_remount()
    assert choice == p.fork().best_remount()


def test_a_handed_plan_serves_only_its_own_set_up(monkeypatch: pytest.MonkeyPatch) -> None:
    """A plan handed to a process (:func:`~calibrators.agents.optimal.handed_plans`, a
    sweep's workers) is the plan of a set-up equal to its key in every argument; a set-up
    one argument away is planned as before."""
    setup = (tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS), SIGMA, 60.0, PROTOTYPE, LAB,
             "I", True, (), 0.0, False, False)
    handed = ((PlannedOperation(Op.STOP, time_s=0.0),), 1.0)  # not what planning makes
    # The process's other plans kept out.
    monkeypatch.setattr(optimal, "_PLANS", Kept(optimal.PLANS_KEPT))
    handed_plans({setup: handed})
    assert setup in made_plans()
    assert fixed_plan(*setup[:6]) is handed
    steps, predicted = fixed_plan(*setup[:6], remounts=False)
    assert predicted < 1.0 and len(steps) > 1


def test_a_sweeps_workers_make_no_plan_of_their_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan a comparison makes before its workers start
    (:func:`~calibrators.study.compare.shared_start`, on its first machine) is the one
    every worker's agents ask for on their machines, and its slot table the one they plan
    and read on: handed to a process that has neither, its chunk of other machines,
    ``active`` and ``optimal`` both, plans nothing and makes no slot table again, and
    plays and scores them as it does when it makes both itself."""
    config = Config(("active", "optimal"), ("extended",), seed=1, conditions=LAB,
                    budget_s=240.0)
    monkeypatch.setattr(optimal, "_PLANS", Kept(optimal.PLANS_KEPT))
    monkeypatch.setattr(tables, "_TABLES", Kept(2))
    start = shared_start(config, 0, 1)
    assert len(start.plans) == 1  # the two agents share one set-up
    assert list(start.tables) == [PROTOTYPE]
    monkeypatch.setattr(optimal, "_PLANS", Kept(optimal.PLANS_KEPT))
    monkeypatch.setattr(tables, "_TABLES", Kept(2))
    made = []
    planning, tabling = optimal._fixed_plan, tables._slot_table
    monkeypatch.setattr(optimal, "_fixed_plan", lambda *key: made.append(key) or planning(*key))
    monkeypatch.setattr(tables, "_slot_table", lambda d: made.append(d) or tabling(d))
    trials = run_chunk(config, [3, 4], set(), start=start)
    assert len(trials) == 4 and not made
    # What the process makes of its own is what it was handed: the same trials, to the byte.
    monkeypatch.setattr(optimal, "_PLANS", Kept(optimal.PLANS_KEPT))
    monkeypatch.setattr(tables, "_TABLES", Kept(2))
    alone = run_chunk(config, [3, 4], set())
    assert len(made) == 2  # the plan and the slot table
    assert [t.to_json() for t in alone] == [t.to_json() for t in trials]
