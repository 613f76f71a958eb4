"""The ballbar in the lab (``OrthoglideLab-v2``): what it reads of the machine, that both
backends and every face of the lab agree on it, its travel's refusals, its readings'
model in the fit, its rows in a reading file, and the ``ballbar`` agent's needs."""

from __future__ import annotations

import itertools
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import (
    assert_batch_reads_as_alone,
    assert_refused_in_one_line,
    command_here,
    refit_misfit,
)

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.ballbar import LENGTH_MM, circle_postures, circle_steps
from calibrators.agents.base import action
from calibrators.measurements import Measurements
from calibrators.study.episodes import measurements_of
from calibrators.study.labs import lab_kwargs
from orthoglide_env.instruments import ballbar
from orthoglide_env.instruments.ballbar import BallbarSpec
from orthoglide_env.lab.operations import V1_OPS, V2_OPS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import AXIS_NAMES, MachineParams
from orthoglide_env.model.kinematics import direct, inverse
from orthoglide_env.reading_model import ReadingLayout, jacobian, predict
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM

V2 = orthoglide_env.LAB_V2_ENV_ID
OWNED = ["dial", "ballbar"]
BAR = BALLBAR_LENGTHS_MM.index(LENGTH_MM)
#: Where the agent's circles are centred (a command), and a point a bar's length from it.
CENTRE = inverse(MachineParams(design=PROTOTYPE), np.full(3, -20.0))
SIGMA_UM = ballbar.sigma(Conditions("lab")) * 1e3



def _circle(env: gym.Env, seed: int, plane: tuple[int, int] = (0, 1)) -> list[dict]:
    """Lift the stands, set the pivot up at :data:`CENTRE` and run one anticlockwise
    circle: every observation from the set-up on."""
    obs, _ = env.reset(seed=seed)
    for k in range(len(obs["slot"])):
        env.step(action(Op.LIFT, stand=k))
    seen = [env.step(action(Op.PIVOT, CENTRE, bar=BAR))[0]]
    seen += [env.step(action(Op.MOVE, rho))[0]
             for rho in circle_postures(PROTOTYPE, plane, False)]
    return seen


def _bar_readings(seen: list[dict]) -> np.ndarray:
    return np.array([o["ballbar"][0] for o in seen if o["ballbar_valid"][0]])


def test_v1_keeps_its_spaces_and_refuses_the_ballbar():
    env = gym.make(orthoglide_env.LAB_V1_ENV_ID, backend="exact", conditions="ideal")
    assert env.action_space["op"].n == V1_OPS == 6
    assert "bar" not in env.action_space.spaces
    assert not any(k.startswith("ballbar") for k in env.observation_space.spaces)
    with pytest.raises(ValueError, match="OrthoglideLab-v2"):
        gym.make(orthoglide_env.LAB_V1_ENV_ID, backend="exact", instruments=OWNED)
    v2 = gym.make(V2, backend="exact", conditions="ideal")
    assert v2.action_space["op"].n == V2_OPS and "bar" in v2.action_space.spaces
    v2.reset(seed=0)
    _, _, _, _, info = v2.step(action(Op.PIVOT, CENTRE, bar=BAR))
    assert "no ballbar" in info["refused"]


@pytest.mark.parametrize("conditions", ["ideal", "lab"])
def test_both_backends_read_the_same_circle(conditions: str):
    """The bar reads the TCP: the PyBullet machine and the exact model put it within the
    workbench's 1 um of each other (the same draws, so only their TCPs differ)."""
    readings = [_bar_readings(_circle(gym.make(V2, errors="realistic", backend=backend,
                                                 conditions=conditions, instruments=OWNED),
                                        seed=4))
                for backend in ("exact", "pybullet")]
    assert len(readings[0]) == len(readings[1]) == len(circle_postures(PROTOTYPE, (0, 1),
                                                                        False))
    assert np.max(np.abs(readings[0] - readings[1])) <= 1e-3


def test_a_nominal_machine_reads_its_scatter_only():
    """On the nominal machine in an ideal world the TCP runs on the circle: what the bar
    reads is its own scatter, sigma ~0.35 um.  With 25 readings the sample deviation lies
    within +-35 % of sigma at about 3 standard errors (1 / sqrt(2 * 25) = 14 %)."""
    env = gym.make(V2, errors="nominal", backend="exact", conditions="ideal",
                   instruments=OWNED)
    values = _bar_readings(_circle(env, seed=2)) * 1e3  # um
    assert len(values) == 25
    assert 0.65 * SIGMA_UM <= np.std(values) <= 1.35 * SIGMA_UM
    assert abs(np.mean(values)) <= 4 * SIGMA_UM / np.sqrt(len(values))


def test_the_model_predicts_the_engine_at_the_truth():
    """The fit's model at the true machine (the pivot centred exactly, as in an ideal
    world) gives the engine's readings up to the bar's scatter; its derivatives are the
    model's finite differences."""
    env = gym.make(V2, errors="realistic", backend="exact", conditions="ideal",
                   instruments=OWNED)
    _circle(env, seed=5, plane=(1, 2))
    records = [r for r in env.unwrapped.records if isinstance(r.spec, BallbarSpec)]
    layout = ReadingLayout.of([r.mounting for r in records], [r.spec for r in records],
                              np.array([r.rho for r in records]), PROTOTYPE)
    truth = np.concatenate([env.unwrapped._batch.machines[0].to_vector(), np.zeros(3)])
    residual = (np.array([r.reading for r in records]) - predict(truth, layout)) * 1e3
    # 25 readings: their RMS within +-35 % of sigma (see the test above).
    assert 0.65 * SIGMA_UM <= np.sqrt(np.mean(residual**2)) <= 1.35 * SIGMA_UM
    free = np.ones(len(truth), dtype=bool)
    analytic = jacobian(truth, layout, free, np.ones(len(truth)))
    step, numeric = 1e-6, np.zeros_like(analytic)
    for k in range(len(truth)):
        e = np.zeros(len(truth))
        e[k] = step
        numeric[:, k] = (predict(truth + e, layout) - predict(truth - e, layout)) / (2 * step)
    # Central differences of a model smooth on the scale of the legs (300 mm): their error
    # is ~1e-9 of the largest derivative (tens of mm/rad), far below 1e-6.
    assert np.max(np.abs(analytic - numeric)) <= 1e-6 * np.max(np.abs(numeric))


def test_the_model_predicts_many_machines_at_once_as_each_alone():
    """A batch fit predicts the readings of several machines that share one layout (every
    machine of a planned experiment does) in one call: each row is that machine's own
    prediction, pivots included (a batch of two used to fail on the pivots' shape)."""
    env = gym.make(V2, errors="realistic", backend="exact", conditions="ideal",
                   instruments=OWNED)
    _circle(env, seed=5)
    records = [r for r in env.unwrapped.records if isinstance(r.spec, BallbarSpec)]
    layout = ReadingLayout.of([r.mounting for r in records], [r.spec for r in records],
                              np.array([r.rho for r in records]), PROTOTYPE)
    truth = np.concatenate([env.unwrapped._batch.machines[0].to_vector(), np.zeros(3)])
    thetas = truth + np.random.default_rng(0).normal(0.0, 1e-3, (3, len(truth)))
    together = predict(thetas, layout)
    # The same arithmetic per machine, batched or not: equal to rounding (1e-12 mm).
    np.testing.assert_allclose(together, [predict(t, layout) for t in thetas],
                               rtol=0, atol=1e-12)


def test_a_batch_reads_what_separate_labs_read():
    batched = assert_batch_reads_as_alone(
        V2, circle_steps(6, PROTOTYPE)[:40], {"bar": BAR},
        ("ballbar", "ballbar_valid", "ballbar_in", "gauges", "time"),
        errors="realistic", conditions="lab", instruments=OWNED)
    assert batched["ballbar_valid"].all()


def test_the_bar_refuses_a_move_outside_its_travel():
    """The first move after a set-up puts the bar in, and from then on every move must
    keep it within its travel, else ValueError and nothing changes; any other operation
    takes it off."""
    env = gym.make(V2, errors="realistic", backend="exact", conditions="ideal",
                   instruments=OWNED)
    seen = _circle(env, seed=1)
    assert seen[-1]["ballbar_in"][0] == 1
    time = env.unwrapped._batch.time.copy()
    with pytest.raises(ValueError, match="outside its travel") as info:
        env.step(action(Op.MOVE, np.zeros(3)))
    assert "\n" not in str(info.value)
    np.testing.assert_array_equal(env.unwrapped._batch.time, time)
    obs = env.step(action(Op.LIFT))[0]
    assert obs["ballbar_in"][0] == 0
    assert env.step(action(Op.MOVE, np.zeros(3)))[0]["ballbar_valid"][0] == 0
    env.step(action(Op.PIVOT, CENTRE, bar=BAR))
    with pytest.raises(ValueError, match="outside its travel"):
        env.step(action(Op.MOVE, np.zeros(3)))


def test_a_full_fit_of_circles_sees_the_geometry():
    """On a realistic machine in an ideal world, the three planes' circles alone (no
    gauge but the stands' zeros) give the full fit a TCP error after rigid motion of a
    few um: well under the 0.15 mm the machine's errors leave uncalibrated (DESIGN.md)."""
    from calibrators.estimators.catalogue import for_study
    from orthoglide_env.scoring.truth import score
    env = gym.make(V2, errors="realistic", backend="exact", conditions="ideal",
                   instruments=OWNED)
    env.reset(seed=1)
    for step in circle_steps(6, PROTOTYPE):
        env.step({"bar": BAR, **step})
    data = measurements_of(env.unwrapped.records, design=PROTOTYPE)
    est = for_study("full", 0.02).fit(data)
    error = score(est.machine, env.unwrapped._batch.machines[0]).tcp_after.rigid.rms
    assert error < 0.01
    assert not any("does not explain" in w for w in est.warnings)


def _file(tmp_path: Path, *rows: str) -> Path:
    path = tmp_path / "r.csv"
    header = ("mounting,leg,axis,at,rho_x,rho_y,rho_z,repetition,reading_mm,instrument,"
              "pivot_x,pivot_y,pivot_z,bar_mm")
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def test_a_reading_file_keeps_the_set_up(tmp_path: Path):
    row = "ballbar#1,,,,10,-20,-5,1,0.0123,ballbar,-21.5,-21.5,-21.5,50"
    data = Measurements.read(_file(tmp_path, row))
    assert data.items[0].gauge == BallbarSpec((-21.5, -21.5, -21.5), 50.0)
    data.write(tmp_path / "back.csv")
    assert Measurements.read(tmp_path / "back.csv").items == data.items


#: Bad rows and the words of their refusal.
BAD_ROWS = [
    ("ballbar#1,,,,10,-20,-5,1,0.0123,ballbar,-21.5,-21.5,-21.5,", "(bar_mm): empty"),
    ("ballbar#1,,,,10,-20,-5,1,0.0123,ballbar,,-21.5,-21.5,50", "(pivot_x): empty"),
    ("ballbar#1,,,,10,-20,-5,1,1.5,ballbar,-21.5,-21.5,-21.5,50", "its travel"),
    ("ballbar#1,x,y,,10,-20,-5,1,0.01,ballbar,-21.5,-21.5,-21.5,50", "has no leg"),
    ("s,x,y,,0,0,0,1,0.01,dial,-21.5,,,", "only a ballbar")]


@pytest.mark.parametrize(("row", "words"), BAD_ROWS)
def test_a_bad_ballbar_row_is_refused_in_one_line(tmp_path: Path, row: str, words: str):
    # The first row's refusal is the command's as a child; the others run in this process.
    assert_refused_in_one_line(_file(tmp_path, row), words, child=(row, words) == BAD_ROWS[0])


def test_the_agent_needs_the_ballbar():
    agent = get_agent("ballbar")
    with pytest.raises(ValueError, match="needs the ballbar"):
        lab_kwargs(agent, ("dial",))
    assert lab_kwargs(agent, ("dial", "ballbar"))["instruments"] == ["dial", "ballbar"]
    done = command_here(["compare", "--agents", "ballbar", "--machines", "1"])
    assert done.returncode == 2
    assert "needs the ballbar" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_check_env_is_clean_with_the_ballbar():
    import warnings

    from gymnasium.utils.env_checker import check_env
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(V2, backend="exact", conditions="lab",
                           instruments=OWNED).unwrapped, skip_render_check=True)
    # The one warning left, as for v0 and v1: joint targets are in mm, not a normalised box
    # (besides Gymnasium's note that v3, the lab with the step gauge, exists).
    messages = {str(w.message) for w in caught if "is out of date" not in str(w.message)}
    assert all("symmetric and normalized" in m for m in messages), messages


def test_the_fit_considers_the_drives_give_only_with_a_ballbar():
    """The weight's deflection (about 1 um) is a consider term of a fit with ballbar
    readings, at the world's own size, and so is the bar's scale error; a fit of gauges
    alone is as before."""
    from calibrators.estimators.consider import consider_terms
    from orthoglide_env.instruments.slots import PAPER_LAYOUT
    from orthoglide_env.world.truth import deflection
    lab = Conditions("lab")
    rho = circle_postures(PROTOTYPE, (0, 1), False)
    bar = ReadingLayout.of(["ballbar#1"] * len(rho), [BallbarSpec(tuple(CENTRE), 50.0)]
                           * len(rho), rho, PROTOTYPE)
    dial = ReadingLayout.of(["g"] * len(rho), [PAPER_LAYOUT[0]] * len(rho), rho, PROTOTYPE)
    times = np.zeros((1, len(rho)))
    with_bar = consider_terms(bar, np.zeros((1, len(rho))), times, lab)
    assert "compliance.weight" not in consider_terms(dial, np.zeros((1, len(rho))), times,
                                                     lab).names
    assert "ballbar.scale" in with_bar.names  # its transducer's: one bar, one term
    k = with_bar.names.index("compliance.weight")
    np.testing.assert_array_equal(with_bar.drive[0, :, :, k], deflection(rho, PROTOTYPE, lab))
    # The weight's share on a drive changes by about a micrometre over the circle.
    assert 0.2e-3 < np.ptp(with_bar.drive[0, :, :, k]) < 3e-3


@pytest.mark.parametrize("conditions", ["lab", "workshop"])
def test_the_pivot_prior_is_the_spread_of_where_the_drives_put_the_centre(conditions: str):
    """A pivot is centred where the TCP truly is: off the nominal-model TCP at the centre
    command by the centring, and by the drives' carriage errors there (lead, half the
    lost motion, the warm-up) through the TCP's sensitivity and the structure's growth
    with the room.  The fit's prior on it adds that spread to the centring's: over 400
    drawn worlds (warm: 4 h in), each coordinate's RMS offset beside the centring lies
    within 15 % of it (the RMS of 400 draws scatters by about 4 %; the lead curve's prior
    is the table's sizes, not the two sines the world draws).  Under the workshop the
    centring's prior alone was 3x too tight.  (The planner's prior: the fit instead moves
    the pivot with its drive terms, the test below.)"""
    from calibrators.estimators.consider import pivot_sigmas
    from orthoglide_env.world.truth import World
    world_of = Conditions(conditions)
    stream = np.random.default_rng(7)
    nominal = MachineParams(design=PROTOTYPE)
    nominal_tcp = direct(nominal, CENTRE)
    time = np.array([4 * 3600.0])
    offsets = []
    for _ in range(400):
        world = World.draw(world_of, stream, stands=1)
        approach = stream.choice((-1.0, 1.0), (1, 3))
        carriages = world.joints(CENTRE[None], approach, time, PROTOTYPE)[0]
        # The nominal geometry's TCP (its errors are the fit's own unknowns), grown.
        offsets.append(direct(nominal, carriages) * world.scale(time)[0] - nominal_tcp)
    rms = np.sqrt(np.mean(np.square(offsets), axis=0))
    layout = ReadingLayout.of(["ballbar#1"], [BallbarSpec(tuple(CENTRE), 50.0)], CENTRE[None],
                              PROTOTYPE)
    drives = np.sqrt(pivot_sigmas(layout, world_of) ** 2 - ballbar.centring_sigma() ** 2)
    np.testing.assert_allclose(rms, drives, rtol=0.15)
    if conditions == "workshop":
        assert (rms > 2.5 * ballbar.centring_sigma()).all()


def test_a_set_ups_first_reading_is_approached_from_its_centre():
    """The set-up drove to its centre unread: the backlash term of its first reading has
    the direction of the move from the centre, not from the reading before it."""
    from calibrators.estimators.consider import consider_terms
    from orthoglide_env.instruments.slots import PAPER_LAYOUT
    before = np.array([0.0, 0.0, -100.0])  # a gauge's reading far below the centre
    start = CENTRE + np.array([0.0, 0.0, -10.0])  # the circle's start, below the centre
    layout = ReadingLayout.of(["g", "ballbar#1"], [PAPER_LAYOUT[0], BallbarSpec(
        tuple(CENTRE), 50.0)], np.stack([before, start]), PROTOTYPE)
    terms = consider_terms(layout, np.zeros((1, 2)), np.zeros((1, 2)), Conditions("lab"))
    z = terms.drive[0, 1, 2, terms.names.index("backlash.spread[z]")]
    # Reached going down from the centre: the carriage lags above, +b/2 (the lag's sign
    # is minus the approach).
    assert z > 0


def test_the_approach_is_the_last_move_of_each_axis_read_in_order():
    """Each reading's and each set-up centre's approach, from the array of the points
    driven to, is the one found by walking the readings one by one: the sign of each
    axis's last non-zero step, +1 before it first moves, a set-up's centre driven to
    unread before its first reading (set-ups out of order, repeated points, a first
    reading that is a set-up's)."""
    from calibrators.estimators.consider import _approach
    from orthoglide_env.instruments.slots import PAPER_LAYOUT
    stream = np.random.default_rng(5)
    points = np.round(CENTRE + stream.uniform(-20.0, 20.0, (40, 3)), 0)
    points[[7, 8, 21]] = points[[6, 7, 20]]  # moves that leave the axes where they were
    mounting = ["ballbar#2"] * 4 + ["g"] * 10 + ["ballbar#1"] * 12 + ["g"] * 14
    centres = {"ballbar#1": CENTRE - 5.0, "ballbar#2": CENTRE + 3.0}
    names = list(dict.fromkeys(mounting))
    spec = {n: PAPER_LAYOUT[0] if n == "g" else BallbarSpec(tuple(centres[n]), 50.0)
            for n in names}
    layout = ReadingLayout.of(mounting, [spec[n] for n in mounting], points, PROTOTYPE)
    state, last, expected, at_centres = np.ones(3), points[0], [], {}
    for k, posture in enumerate(points):
        first = mounting[k] != "g" and mounting.index(mounting[k]) == k
        for point in ((centres[mounting[k]], posture) if first else (posture,)):
            step = point - last
            state = np.where(step > 0, 1.0, np.where(step < 0, -1.0, state))
            last = point
            if first and point is not posture:
                at_centres[mounting[k]] = state
        expected.append(state)
    approach, centre_approach = _approach(layout)
    np.testing.assert_array_equal(approach, expected)
    np.testing.assert_array_equal(
        centre_approach, [at_centres[names[k]] for k in layout.space.ballbars])


def _circles_in_a_warming_workshop(effects: tuple[str, ...] | None = None
                                   ) -> tuple[gym.Env, list[float]]:
    """A workshop lab whose stands are lifted, then twice the three planes' circles, each
    from its own set-up at :data:`CENTRE` (ISO 230-4's in one lab, repeated as the drives
    warm), and the lab time each set-up centred its pivot."""
    env = gym.make(V2, errors="realistic", backend="exact", instruments=OWNED,
                   conditions=Conditions("workshop", effects=effects), budget_s=4 * 3600.0)
    obs, _ = env.reset(seed=3)
    for k in range(len(obs["slot"])):
        env.step(action(Op.LIFT, stand=k))
    centred = []
    for _ in range(2):
        for plane in ((0, 1), (1, 2), (0, 2)):
            env.step(action(Op.PIVOT, CENTRE, bar=BAR))
            centred.append(env.unwrapped._time)
            for rho in circle_postures(PROTOTYPE, plane, False):
                env.step(action(Op.MOVE, rho))
    return env, centred


def test_the_pivot_moves_with_the_drives_where_and_when_it_was_centred():
    """A pivot is centred where the drives then put the TCP: each drive term's pattern at
    a ballbar reading's pivot is the term at its set-up's centre command, at the lab time
    the set-up ended (its first reading a move later) and approached as the carriages
    reached the centre; and only the centre's part of the reading's derivative by the
    carriages, with the TCP's part, makes the encoder offsets' (a carriage error that
    does not change moves the pivot and the TCP alike)."""
    from calibrators.estimators.consider import consider_terms, warmup_curves, warmup_sizes
    from orthoglide_env.reading_model import carriage_derivatives, pivot_derivatives
    env, centred = _circles_in_a_warming_workshop(("warmup", "backlash"))
    data = measurements_of(env.unwrapped.records, design=PROTOTYPE)
    times = np.array([[m.time_s for m in data.items]])
    layout = ReadingLayout.of([m.mounting for m in data.items], [m.gauge for m in data.items],
                              np.array([m.rho for m in data.items]), PROTOTYPE)
    terms = consider_terms(layout, np.zeros(times.shape), times, Conditions("workshop"))
    x = (CENTRE - PROTOTYPE.rho_min) / (PROTOTYPE.rho_max - PROTOTYPE.rho_min)
    mean = warmup_sizes(Conditions("workshop"))[0]
    k = terms.names.index("warmup.mean")
    for setup, when in enumerate(centred):
        rows = layout.mounting == layout.space.ballbars[setup]
        expected = mean * warmup_curves(x, np.array(when), Conditions("workshop"))[1]
        # The first reading's time less a move's, in floating point.
        np.testing.assert_allclose(terms.pivot[0, rows, :, k], np.broadcast_to(
            expected, (rows.sum(), 3)), rtol=1e-9)
    # Every set-up reached the centre from the circle's start before it (or, the first,
    # from the stands' lifting at Zero): each carriage came down or up, none stayed.
    bars = np.isin(layout.mounting, layout.space.ballbars)
    lag = terms.pivot[0, bars, :, terms.names.index("backlash.mean")]
    assert (np.abs(lag) > 0).all()
    # The TCP's part and the pivot's make the reading's derivative by the encoder offsets.
    n = len(layout.space)
    encoder = jacobian(np.zeros(n), layout, np.arange(n) < 3, np.ones(n))
    both = carriage_derivatives(layout) + pivot_derivatives(layout)
    np.testing.assert_allclose(both[bars], encoder[bars], rtol=0, atol=1e-12)
    # The pivot's part is not small: a circle's readings move by the bar's direction.
    assert np.abs(pivot_derivatives(layout)[bars]).max() > 0.5
    # Machines that share the layout (a fixed design's batch) read at their own times:
    # each one's terms are its own alone.
    later = np.concatenate([times, times + 600.0])
    both = consider_terms(layout, np.zeros(later.shape), later, Conditions("workshop"))
    for m in range(2):
        alone = consider_terms(layout, np.zeros((1, later.shape[1])), later[m:m + 1],
                               Conditions("workshop"))
        np.testing.assert_array_equal(both.pivot[m], alone.pivot[0])


def test_a_ballbar_leaves_the_drives_common_scale_to_its_prior():
    """A scale common to the three drives, from their back ends, is to first order a
    similarity of the workspace about a point: each ballbar set-up's zero (the bar's
    calibrated length) takes its part along the bar, and its pivot, centred where the
    drives put the TCP, moves with it.  So circles alone leave the pitch tables' common
    value at the stroke's end to its prior: the kinematics tell a joint scale from a
    similarity over 50 mm circles by about (25 mm / 310 mm)^2, well under 2 %.  A pivot
    whose offset from the model's TCP had its own zero-mean prior per set-up, sized by
    the drives' errors, pulled every set-up's coordinate along its plane's normal (seen
    to second order only) to the nominal TCP and told the fit this scale to 0.83 of its
    prior: in a warming workshop, pitch tables about 15 um off at the end, 2-3.5 of their
    sigmas."""
    from calibrators.estimators.catalogue import for_study
    from calibrators.estimators.consider import TABLE_TERM, table_prior
    from orthoglide_env.model.errors import ERROR_NAMES
    env, _ = _circles_in_a_warming_workshop()
    est = for_study("full", 0.02, Conditions("workshop")).fit(
        measurements_of(env.unwrapped.records, design=PROTOTYPE))
    _, root = table_prior(PROTOTYPE, Conditions("workshop"), est.node_spacing)
    columns = [len(ERROR_NAMES) + k for axis in AXIS_NAMES for k, name in
               enumerate(est.lead_terms) if name.startswith(TABLE_TERM)
               and name.endswith(f"[{axis}]")]
    # The three axes' end values, each the table's last node: its prior root's last row.
    end = np.kron(np.eye(3), root[-1])
    mean = np.full(3, 1 / 3) @ end
    posterior = mean @ est.lead_covariance[np.ix_(columns, columns)] @ mean
    prior = mean @ mean
    assert np.sqrt(posterior / prior) > 0.98



def test_active_refits_the_circles_under_lab_with_the_drives_terms():
    """Under ``lab`` the drives' lead, lost motion and warm-up move the TCP by microns
    between the circles' points, which the bar reads to 0.35 um.  Beside 384 dial
    readings (which set the residuals' robust spread), ``active``'s refit told an ideal
    world misfits the bar's readings by more than twice their sigma, even after leaving
    the worst out one refit after another (honest readings flag once in 6e-5: none of
    150).  Its refit of a notebook with the bar, told the lab and fitting those terms,
    leaves none out and fits the bar to its scatter (the chi-square's 99.9 % bound on the
    RMS of 150 honest readings is 1.18 sigma).  The first says that so many of one
    instrument's readings left out are the model's error."""
    env = gym.make(V2, errors="realistic", backend="exact", conditions="lab",
                   instruments=OWNED)
    env.reset(seed=1)
    for step in circle_steps(6, PROTOTYPE):
        env.step({"bar": BAR, **step})
    for offset in itertools.product((-3.0, -1.0, 1.0, 3.0), repeat=3):
        assert not env.step(action(Op.MOVE, np.array(offset)))[4].get("refused")
    data = measurements_of(env.unwrapped.records, design=PROTOTYPE)
    bars = np.flatnonzero([isinstance(m.gauge, BallbarSpec) for m in data.items])
    assert len(bars) == 150
    left_out, rms_um, said = refit_misfit(data, BallbarSpec, None, "ballbar")
    # More than the outlier cap's 5 % of the bar's readings: the warning names model error.
    assert left_out >= 8 and rms_um > 2 * SIGMA_UM and said
    left_out, rms_um, said = refit_misfit(data, BallbarSpec, Conditions("lab"), "ballbar")
    assert left_out == 0 and rms_um < 1.18 * SIGMA_UM and not said
