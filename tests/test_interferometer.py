"""The laser interferometer in the lab (``OrthoglideLab-v1``): what it reads of a drive,
what it costs, who may use it, and that every face of the lab agrees on it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents.base import action
from orthoglide_env.instruments import interferometer
from orthoglide_env.lab.operations import TIME, V0_OPS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

V1 = orthoglide_env.LAB_V1_ENV_ID
OWNED = ["dial", "interferometer"]
#: Targets along a drive, both ways (the ISO 230-2 pattern's shape).
TARGETS = (-90.0, -50.0, -10.0, 30.0, 55.0, 30.0, -10.0, -50.0, -90.0)



def _run(env: gym.Env, axis: int, seed: int = 3) -> tuple[list[dict], list[dict]]:
    """Lift the stands, set the interferometer up along ``axis`` and drive it through
    :data:`TARGETS`: every observation and info from the set-up on."""
    obs, _ = env.reset(seed=seed)
    for k in range(len(obs["slot"])):
        env.step(action(Op.LIFT, stand=k))
    seen = [env.step(action(Op.ALIGN, axis=axis))]
    for value in TARGETS:
        rho = np.zeros(3)
        rho[axis] = value
        seen.append(env.step(action(Op.MOVE, rho)))
    return [s[0] for s in seen], [s[4] for s in seen]


def test_v0_keeps_its_spaces_and_refuses_the_interferometer():
    env = gym.make(orthoglide_env.LAB_ENV_ID, backend="exact", conditions="ideal")
    assert env.action_space["op"].n == V0_OPS == 5
    assert "axis" not in env.action_space.spaces
    assert not any(k.startswith("interferometer") for k in env.observation_space.spaces)
    with pytest.raises(ValueError, match="OrthoglideLab-v1"):
        gym.make(orthoglide_env.LAB_ENV_ID, backend="exact", conditions="ideal",
                 instruments=OWNED)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="op"):
        env.step(action(Op.ALIGN, axis=0))


@pytest.mark.parametrize(("names", "words"), [
    (["dial", "laser"], "unknown instrument"),
    (["interferometer"], "include 'dial'"),
    ("dial", "a list of instrument names")])
def test_bad_instruments_are_refused_in_one_line(names, words):
    with pytest.raises(ValueError, match=words) as info:
        gym.make(V1, backend="exact", conditions="ideal", instruments=names)
    assert "\n" not in str(info.value)


def test_the_tracker_flag_and_the_tracker_instrument_say_the_same():
    by_flag = gym.make(V1, backend="exact", conditions="ideal", tracker=True).unwrapped
    by_name = gym.make(V1, backend="exact", conditions="ideal",
                       instruments=["dial", "tracker"]).unwrapped
    assert by_flag.tracker and by_name.tracker
    assert by_flag.instruments == by_name.instruments == ("dial", "tracker")


def test_align_without_the_interferometer_is_refused():
    env = gym.make(V1, backend="exact", conditions="ideal")
    env.reset(seed=0)
    *_, info = env.step(action(Op.ALIGN, axis=0))
    assert "no interferometer" in info["refused"]
    assert info["step_time_s"] == TIME.lift_s


def test_an_ideal_drive_reads_its_noise_only():
    """Without the world a carriage is where it is commanded: every reading is the
    instrument's scatter, whose sample deviation over 9 readings lies within a factor
    of 2 of the table's (chi-square with 9 dof: outside [0.25, 4] var with p < 1e-3)."""
    env = gym.make(V1, backend="exact", conditions="ideal", instruments=OWNED)
    obs, infos = _run(env, axis=1)
    values = np.array([o["interferometer"][0] for o in obs[1:]])
    sigma = interferometer.sigma(Conditions("ideal"))
    assert all(o["interferometer_valid"][0] == 1 and o["interferometer_axis"] == 1
               for o in obs)
    assert 0.5 * sigma < np.sqrt(np.mean(values**2)) < 2 * sigma
    assert infos[0]["op"] == "align"


def test_the_reading_is_the_lead_error_since_the_zero():
    """With the lead error alone acting, a reading is the carriage's lead error at the
    target less the one at Zero (where the count was zeroed), to within the scatter and
    the instrument's scale error: 5 sigma, and 1.6 ppm (laser and air) of the 100 mm
    travel."""
    conditions = Conditions("lab", ("lead",))
    env = gym.make(V1, backend="exact", conditions=conditions, instruments=OWNED)
    for axis in range(3):
        obs, _ = _run(env, axis, seed=axis)
        world = env.unwrapped._batch.world
        rho = np.zeros((len(TARGETS), 3))
        rho[:, axis] = TARGETS
        lead = world.lead_error(rho[None], PROTOTYPE)[0, :, axis]
        zero = world.lead_error(np.zeros((1, 1, 3)), PROTOTYPE)[0, 0, axis]
        values = np.array([o["interferometer"][0] for o in obs[1:]])
        tolerance = 5 * interferometer.sigma(conditions) + 1.6e-6 * 100
        assert np.abs(values - (lead - zero)).max() < tolerance
        assert np.abs(lead - zero).max() > 5 * tolerance  # the test can tell


def test_backlash_shows_as_the_reversal():
    """Approached from either side, a target reads the lost motion apart (the carriage
    lags by half of it against each approach), to within 4 sigma of two readings."""
    conditions = Conditions("workshop", ("backlash",))
    env = gym.make(V1, backend="exact", conditions=conditions, instruments=OWNED)
    obs, _ = _run(env, axis=0)
    values = np.array([o["interferometer"][0] for o in obs[1:]])
    lost = env.unwrapped._batch.world.backlash[0, 0]
    forward, backward = values[2], values[6]  # -10 mm going up, then coming down
    tolerance = 4 * np.sqrt(2) * interferometer.sigma(conditions)
    assert abs((backward - forward) - lost) < tolerance
    assert lost > 2 * tolerance  # the workshop's nut loses 5-15 um: the test can tell


def test_times_follow_the_time_table():
    env = gym.make(V1, backend="exact", conditions="ideal", instruments=OWNED)
    env.reset(seed=0)
    rho = np.array([20.0, 0.0, 0.0])
    *_, info = env.step(action(Op.MOVE, rho))
    assert info["step_time_s"] == pytest.approx(float(TIME.move(np.zeros(3), rho)))
    *_, info = env.step(action(Op.ALIGN, axis=0))
    assert info["step_time_s"] == pytest.approx(
        float(TIME.move(rho, np.zeros(3))) + TIME.interferometer_setup_s
        + TIME.interferometer_soak_s)
    *_, info = env.step(action(Op.MOVE, rho))
    assert info["step_time_s"] == pytest.approx(
        float(TIME.move(np.zeros(3), rho)) + TIME.interferometer_target_s)
    *_, info = env.step(action(Op.ALIGN, axis=2))  # the sensor has settled: no soak
    assert info["step_time_s"] == pytest.approx(
        float(TIME.move(rho, np.zeros(3))) + TIME.interferometer_setup_s)
    records = [r for r in env.unwrapped.records if isinstance(
        r.spec, interferometer.InterferometerAxis)]
    assert [r.mounting for r in records] == ["interferometer.x#1", "interferometer.x#1",
                                             "interferometer.z#2"]


def test_both_backends_read_the_same():
    """The interferometer reads the carriages, which both backends put where the world
    says: the readings agree to the last bit (the house's 1 um holds a fortiori)."""
    readings = []
    for backend in ("exact", "pybullet"):
        env = gym.make(V1, backend=backend, conditions="lab", instruments=OWNED)
        obs, _ = _run(env, axis=2, seed=5)
        readings.append([float(o["interferometer"][0]) for o in obs])
        env.close()
    assert readings[0] == readings[1]


def test_a_batch_reads_what_lone_labs_read():
    n = 3
    envs = gym.make_vec(V1, num_envs=n, vectorization_mode="vector_entry_point",
                        backend="exact", conditions="lab", instruments=OWNED)
    obs, _ = envs.reset(seed=11)
    batched = []
    steps = [{"op": np.full(n, Op.LIFT), "rho": np.zeros((n, 3)), "stand": np.full(n, k),
              "slot": np.zeros(n, int)} for k in range(6)]
    steps.append({"op": np.full(n, Op.ALIGN), "rho": np.zeros((n, 3)),
                  "stand": np.zeros(n, int), "slot": np.zeros(n, int),
                  "axis": np.arange(n)})
    for value in TARGETS:
        rho = np.diag(np.full(n, value))
        steps.append({"op": np.full(n, Op.MOVE), "rho": rho, "stand": np.zeros(n, int),
                      "slot": np.zeros(n, int)})
    for step in steps:
        obs, *_ = envs.step(step)
        batched.append(obs["interferometer"][:, 0].copy())
    for i in range(n):
        env = gym.make(V1, backend="exact", conditions="lab", instruments=OWNED)
        env.reset(seed=11 + i)
        for step, expected in zip(steps, batched, strict=True):
            one = {k: v[i] for k, v in step.items()}
            obs, *_ = env.step(one)
            assert obs["interferometer"][0] == expected[i]
        assert env.unwrapped.records == envs.unwrapped.records[i]


def test_check_env_is_clean_with_the_interferometer():
    import warnings

    from gymnasium.utils.env_checker import check_env
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(V1, backend="exact", conditions="lab",
                           instruments=OWNED).unwrapped, skip_render_check=True)
    # The one warning left, as for v0: joint targets are in mm, not a normalised box
    # (besides Gymnasium's note that v2, the lab with the ballbar, exists).
    messages = {str(w.message) for w in caught if "is out of date" not in str(w.message)}
    assert all("symmetric and normalized" in m for m in messages), messages


def test_scales_leave_the_scale_s_grade_and_keep_every_other_draw():
    """Closed-loop drives: the screw's curve, periodic error, warm-up and lost motion
    are gone and the linear error is within the scale's grade (lab: +-3 um over the
    stroke); the machine and the rest of the world are drawn as with screws (the same
    stream, the same draws)."""
    screw = gym.make(V1, backend="exact", conditions=Conditions("lab"), instruments=OWNED)
    scales = gym.make(V1, backend="exact", conditions=Conditions("lab", drives="scales"),
                      instruments=OWNED)
    for env in (screw, scales):
        env.reset(seed=4)
    a, b = (env.unwrapped._batch.world for env in (screw, scales))
    for name in ("lead_a1", "lead_a2", "lead_periodic", "backlash", "warm_amplitude"):
        assert not getattr(b, name).any()
    assert np.all(np.abs(b.lead_scale) <= 3e-3) and b.lead_scale.any()
    for name in ("offset", "rate", "walk", "dial_range", "creep", "warm_tau"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert np.array_equal(screw.unwrapped.true_machine.to_vector(),
                          scales.unwrapped.true_machine.to_vector())


def test_scales_are_read_as_the_scale_s_line():
    """The interferometer reads a scale-driven carriage's linear grade error (the drives'
    effect alone acting): its readings lie on the grade's line from Zero within 5 sigma
    and its own scale error (1.6 ppm of the 100 mm travel)."""
    conditions = Conditions("lab", ("lead",), drives="scales")
    env = gym.make(V1, backend="exact", conditions=conditions, instruments=OWNED)
    obs, _ = _run(env, axis=0, seed=2)
    world = env.unwrapped._batch.world
    x = (np.array(TARGETS) - PROTOTYPE.rho_min) / (PROTOTYPE.rho_max - PROTOTYPE.rho_min)
    x0 = -PROTOTYPE.rho_min / (PROTOTYPE.rho_max - PROTOTYPE.rho_min)
    line = world.lead_scale[0, 0] * (x - x0)
    values = np.array([o["interferometer"][0] for o in obs[1:]])
    assert np.abs(values - line).max() < 5 * interferometer.sigma(conditions) + 1.6e-4


def test_drives_are_refused_by_name_and_in_an_ideal_world():
    with pytest.raises(ValueError, match="unknown drives"):
        Conditions("lab", drives="belts")
    with pytest.raises(ValueError, match="ideal"):
        Conditions("ideal", drives="scales")
    assert Conditions.from_dict(Conditions("workshop", drives="scales").to_dict()) == \
        Conditions("workshop", drives="scales")
    assert "drives" not in Conditions("lab").to_dict()
