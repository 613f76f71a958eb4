"""The native vector env: N machines in one numpy pass give exactly what N separate envs
give, through truncations, crashes, autoresets and resets with options."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import orthoglide_env
from orthoglide_env.envs.calibration_vector import OrthoglideCalibrationVectorEnv
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import paper_posture

N = 5
#: Short episodes, so that a few hundred steps truncate each env many times.
EPISODE = 23
#: Steps of an equivalence run: every case covers what it compares (see the test) by step
#: 146 at the latest (ideal gauges, autoreset disabled, its first reset with gauges).
STEPS = 200
#: The forms of a reset call a run must make: its seed none, one int or one per env, the
#: machine and gauge options, a reset mask.
RESET_FORMS = {"seed none", "seed int", "seed list", "machine", "gauges", "reset_mask"}
#: The machine of tests/test_env.py whose couplers meet near the (60, 60, 60) corner.
CRASHING = MachineParams(
    drho=[0.0, 0.0, -10.0], dL=[-10.0, 0.0, -10.0],
    axis_tilt=[[0.0, 0.02], [-0.02, -0.02], [-0.02, 0.02]],
    axis_offset=[[0.0, 5.0], [0.0, -5.0], [-5.0, 0.0]],
    attach=[[3.0, 3.0, -3.0], [3.0, -3.0, 0.0], [0.0, 3.0, -3.0]],
)
LAYOUT = ["z/x", "x/z@0.3", "y/x", "y/z@0.8", "x/y@0.6", "z/y"]


def native(mode: AutoresetMode = AutoresetMode.NEXT_STEP, n: int = N, **kwargs):
    return gym.make_vec(orthoglide_env.ENV_ID, num_envs=n,
                        vectorization_mode="vector_entry_point", backend="exact",
                        autoreset_mode=mode, **kwargs)


def separate(mode: AutoresetMode = AutoresetMode.NEXT_STEP, n: int = N, **kwargs):
    """N separate single envs, stepped one after the other by Gymnasium's SyncVectorEnv
    (which seeds env i with seed + i and autoresets them in ``mode``)."""
    return gym.vector.SyncVectorEnv(
        [lambda: gym.make(orthoglide_env.ENV_ID, backend="exact", **kwargs) for _ in range(n)],
        autoreset_mode=mode)


def assert_same(a: object, b: object, where: str = "") -> None:
    """Equal to the last bit: same keys, types, dtypes, shapes, values and NaN places."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), (where, sorted(a), sorted(b))
        for key in a:
            assert_same(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, tuple | list):
        assert type(a) is type(b) and len(a) == len(b), (where, a, b)
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{k}]")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert isinstance(b, np.ndarray) and b.dtype == object and a.shape == b.shape, where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{k}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype, (where, a.dtype, b)
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert type(a) is type(b) and a == b, (where, a, b)


def random_actions(rng: np.random.Generator) -> np.ndarray:
    """Per env: small moves (gauges read, or are pressed past their travel), moves across
    the joint cube (gauges lose their bars), the crash corner and the paper's postures."""
    kind = rng.integers(10, size=N)
    actions = rng.uniform(-15, 15, (N, 3))
    actions[kind >= 6] = rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max,
                                     (int(np.sum(kind >= 6)), 3))
    actions[kind == 5] = PROTOTYPE.rho_max
    for i in np.flatnonzero(kind == 4):
        actions[i] = paper_posture(str(rng.choice(["XMin", "YMax", "ZMin", "YMin"])), PROTOTYPE)
    return actions


def random_reset(rng: np.random.Generator, ended: np.ndarray) -> dict:
    """A reset call: seeds as an int, a list or none; machine and layout options; a
    reset mask."""
    kwargs: dict = {}
    seed = rng.integers(3)
    if seed == 1:
        kwargs["seed"] = int(rng.integers(1000))
    elif seed == 2:
        kwargs["seed"] = [int(s) if s >= 0 else None for s in rng.integers(-3, 1000, N)]
    options: dict = {}
    if rng.random() < 0.7:
        options["machine"] = CRASHING.to_dict()
    if rng.random() < 0.4:
        options["gauges"] = LAYOUT
    mask = rng.random(N) < 0.5
    if ended.any() or mask.any():
        options["reset_mask"] = mask | ended
    kwargs["options"] = options
    return kwargs


def reset_forms(kwargs: dict) -> set[str]:
    """The forms of reset call ``kwargs`` makes (:data:`RESET_FORMS`)."""
    seed = kwargs.get("seed")
    form = "seed none" if seed is None else "seed list" if isinstance(seed, list) else "seed int"
    return {form, *kwargs["options"]}


def copied(kwargs: dict) -> dict:
    """A fresh copy of reset arguments (SyncVectorEnv pops the mask from the options)."""
    options = {k: (v.copy() if isinstance(v, np.ndarray) else v)
               for k, v in kwargs["options"].items()}
    return {**kwargs, "options": options}


@pytest.mark.slow
@pytest.mark.parametrize("mode", list(AutoresetMode))
@pytest.mark.parametrize("noise", [{}, {"gauge_sigma": 0.0, "gauge_resolution": 0.0}],
                         ids=["noisy", "ideal"])
def test_native_vector_env_is_n_separate_envs(mode: AutoresetMode, noise: dict) -> None:
    # Ideal gauges show every bit of the geometry; noisy ones the random streams.
    rng = np.random.default_rng(list(AutoresetMode).index(mode) + 10 * len(noise))
    fast = native(mode, max_episode_steps=EPISODE, **noise)
    slow = separate(mode, max_episode_steps=EPISODE, **noise)
    assert_same(fast.reset(seed=11), slow.reset(seed=11))
    ended = np.zeros(N, dtype=bool)
    crashes, truncations, overtravel = (np.zeros(N, dtype=int) for _ in range(3))
    forms: set[str] = set()
    for step in range(STEPS):
        kwargs = None
        if mode == AutoresetMode.DISABLED and ended.any():
            # What the other modes do on their own: the ended envs start again.
            kwargs = {"options": {"reset_mask": ended}}
        elif rng.random() < 0.05:
            kwargs = random_reset(rng, ended)
            forms |= reset_forms(kwargs)
        if kwargs is not None:
            assert_same(fast.reset(**copied(kwargs)), slow.reset(**copied(kwargs)),
                        f"reset at {step}")
            ended[:] = False
        actions = random_actions(rng)
        out = fast.step(actions)
        assert_same(out, slow.step(actions), f"step {step}")
        _, _, terminated, truncated, info = out
        ended = terminated | truncated
        crashes += terminated
        truncations += truncated
        overtravel += [len(o) for o in info["overtravel"]]
    np.testing.assert_array_equal(fast.unwrapped.true_machines.to_vector(),
                                  np.stack([m.to_vector()
                                            for m in slow.get_attr("true_machine")]))
    fast.close()
    slow.close()
    # The run went through what it is meant to compare: every form of reset call, as many
    # crashes as envs (the crashing machine comes only with a reset's option), a truncation
    # and the start after it in every env, and every env's gauges pressed past their travel.
    assert forms == RESET_FORMS, forms
    assert crashes.sum() >= N, crashes
    assert truncations.min() >= 1 and overtravel.min() >= 1, (truncations, overtravel)


def test_made_through_make_vec_with_gymnasiums_conventions() -> None:
    envs = native(n=3)
    env = envs.unwrapped
    assert isinstance(env, OrthoglideCalibrationVectorEnv) and envs.num_envs == 3
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert env.max_episode_steps == 500  # the registered episode length
    single = gym.make(orthoglide_env.ENV_ID, backend="exact")
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    obs, _ = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    obs, *_ = envs.step(np.zeros((3, 3)))
    assert envs.observation_space.contains(obs)
    envs.close()
    single.close()


@pytest.mark.parametrize(("kwargs", "fragment"), [
    ({"backend": "pybullet"}, "backend='exact' only"),
    ({}, "backend='exact' only"),  # the single env's default backend
    ({"backend": "exact", "num_envs": 0}, "num_envs"),
    ({"backend": "exact", "autoreset_mode": "sometimes"}, "autoreset_mode"),
    ({"backend": "exact", "render_mode": "rgb_array"}, "no picture"),
    ({"backend": "exact", "gauge_sigma": 1.0}, "repeatability"),
])
def test_bad_constructor_arguments_are_refused(kwargs: dict, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        OrthoglideCalibrationVectorEnv(**kwargs)


def test_a_refused_step_moves_no_env() -> None:
    refused, untouched = native(), native()
    for envs in (refused, untouched):
        envs.reset(seed=3)
        envs.step(np.zeros((N, 3)))
    good = np.random.default_rng(0).uniform(-5, 5, (N, 3))
    for bad, fragment in ((np.where(np.arange(N)[:, None] == 3, 61.0, good), "env 3"),
                          (good[:2], "shape"), (good.astype(str), "numbers"),
                          (np.where(np.arange(N)[:, None] == 1, np.nan, good), "env 1")):
        with pytest.raises(ValueError, match=fragment):
            refused.step(bad)
    assert_same(refused.step(good), untouched.step(good))
    refused.close()
    untouched.close()


def test_a_posture_one_machine_cannot_reach_names_that_env() -> None:
    envs = native()
    envs.reset(seed=0, options={"machine": {"dL": [-10.0, -10.0, -10.0],
                                            "drho": [10.0, 10.0, 10.0]}})
    actions = np.zeros((N, 3))
    actions[2] = PROTOTYPE.rho_max
    with pytest.raises(ValueError, match=r"env 2 .* no env moves"):
        envs.step(actions)
    envs.close()


def test_refused_resets_change_nothing() -> None:
    refused, untouched = native(), native()
    for envs in (refused, untouched):
        envs.reset(seed=5)
    for kwargs, fragment in (({"seed": -1}, "seed"), ({"seed": [1, 2]}, "list of 5"),
                             ({"options": {"reset_mask": [True] * N}}, "reset_mask"),
                             ({"options": {"reset_mask": np.zeros(N, bool)}}, "reset_mask"),
                             ({"options": {"machine": {"drho": [30.0, 0, 0]}}}, "validity"),
                             ({"options": {"speed": 1}}, "unknown reset option")):
        with pytest.raises(ValueError, match=fragment):
            refused.reset(**kwargs)
    actions = np.full((N, 3), 4.0)
    assert_same(refused.step(actions), untouched.step(actions))
    refused.close()
    untouched.close()


def test_nothing_runs_before_every_env_was_reset() -> None:
    envs = native()
    with pytest.raises(RuntimeError, match="reset"):
        envs.step(np.zeros((N, 3)))
    with pytest.raises(RuntimeError, match="every env"):
        envs.reset(options={"reset_mask": np.eye(N, dtype=bool)[0]})
    envs.close()


def test_disabled_autoreset_refuses_to_step_an_ended_env() -> None:
    envs = native(AutoresetMode.DISABLED, max_episode_steps=1)
    envs.reset(seed=0)
    envs.step(np.zeros((N, 3)))
    with pytest.raises(RuntimeError, match="ended"):
        envs.step(np.zeros((N, 3)))
    envs.reset(options={"reset_mask": np.ones(N, dtype=bool)})
    envs.step(np.zeros((N, 3)))
    envs.close()
