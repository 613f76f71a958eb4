"""Both envs are faces of one lab engine: the same input is refused by both in the same
words, the lab draws pictures where the calibration env does, and the lab's observation
tells a faulted stand from a lifted one."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import load_env_creator

import orthoglide_env
from calibrators.agents.base import action
from orthoglide_env.lab.operations import Op, slot_index
from orthoglide_env.lab.settings import lab_settings
from orthoglide_env.lab.spec import LAB, check_arguments
from orthoglide_env.model.design import PROTOTYPE

ENV_IDS = [orthoglide_env.ENV_ID, orthoglide_env.LAB_ENV_ID]
#: Arguments both envs take, with input one of them accepted before the engine was
#: shared (the lab took ``travel=True`` as 1 mm) or refused with another error.
SHARED_BAD = [
    ("travel", True), ("travel", "10"), ("travel", 0.0), ("travel", float("nan")),
    ("gauge_sigma", True), ("gauge_sigma", "0.02"), ("gauge_resolution", False),
    ("errors", ["realistic"]), ("errors", "wild"), ("backend", 1), ("backend", "bullet"),
    ("render_mode", True), ("render_mode", "png"),
]
#: Joint targets the lab used to accept (numpy read them as numbers).
BAD_TARGETS = [[True, False, True], ["1", "2", "3"], np.array(["1", "2", "3"]),
               [1 + 0j, 2, 3], [1.0, None, 3.0]]


def refusal(env_id: str, **kwargs) -> str:
    """The message of the env's refusal of ``kwargs`` (built from its registered entry
    point: ``gym.make`` looks at a ``render_mode`` itself first)."""
    make = load_env_creator(gym.spec(env_id).entry_point)
    with pytest.raises(ValueError) as caught:
        make(backend=kwargs.pop("backend", "exact"), **kwargs)
    return str(caught.value)


@pytest.mark.parametrize(("name", "value"), SHARED_BAD)
def test_a_shared_argument_is_refused_by_both_envs_in_the_same_words(name: str,
                                                                      value: object) -> None:
    messages = {env_id: refusal(env_id, **{name: value}) for env_id in ENV_IDS}
    assert len(set(messages.values())) == 1, messages
    assert name in messages[ENV_IDS[0]] and "\n" not in messages[ENV_IDS[0]]


@pytest.mark.parametrize(("name", "value", "rule"), [
    ("budget_s", "100", "budget_s must be a number (s) > 0, got '100'"),
    ("budget_s", True, "budget_s must be a number (s) > 0, got True"),
    ("stands", True, "stands must be an integer in [1, "),
    ("stands", 2.0, "stands must be an integer in [1, "),
    ("tracker", 1, "tracker must be True or False, got 1"),
    ("tracker_sigma", "0.005", "tracker_sigma must be a number (mm) > 0"),
    ("time_weight", -1.0, "time_weight must be a number >= 0"),
    ("reward", 0, "reward must be one of ['time', 'accuracy', 'information'], got 0"),
    ("estimator", "extended", "estimator must be a function"),
])
def test_the_labs_own_arguments_are_refused_with_a_value_error(name: str, value: object,
                                                               rule: str) -> None:
    assert refusal(orthoglide_env.LAB_ENV_ID, **{name: value}).startswith(rule)


def test_the_calibration_env_words_its_own_arguments_by_the_same_rules() -> None:
    assert refusal(orthoglide_env.ENV_ID, clip_actions="no").startswith(
        "clip_actions must be True or False")
    assert refusal(orthoglide_env.ENV_ID, motion=0).startswith("motion must be one of")
    assert refusal(orthoglide_env.ENV_ID, gauges="x-leg/y").startswith(
        "gauges must be a list of gauge names")


def test_the_lab_spec_holds_every_constructor_argument() -> None:
    from inspect import signature

    from orthoglide_env.envs.lab import OrthoglideLabEnv

    assert set(signature(OrthoglideLabEnv).parameters) == set(LAB)
    with pytest.raises(ValueError, match=r"unknown argument\(s\) \['speed'\]"):
        check_arguments(LAB, {"speed": 1})
    with pytest.raises(KeyError):
        lab_settings({})  # a builder takes checked arguments only, all of them


def _step_with_target(env: gym.Env, env_id: str, target: object) -> object:
    if env_id == orthoglide_env.ENV_ID:
        return env.step(target)
    return env.step({"op": Op.MOVE, "rho": target, "stand": 0, "slot": 0})


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("target", BAD_TARGETS, ids=repr)
def test_a_target_that_is_not_real_numbers_is_refused_by_both_envs(env_id: str,
                                                                   target: object) -> None:
    env = gym.make(env_id, backend="exact")
    env.reset(seed=0)
    with pytest.raises(ValueError) as caught:
        _step_with_target(env, env_id, target)
    # The same rule in the same words; the lab names the action's field.
    field = "action" if env_id == orthoglide_env.ENV_ID else "action rho"
    assert str(caught.value) == (f"{field} must be 3 numbers (mm), not text, booleans, "
                                 f"complex numbers or objects; got {target!r}")
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_both_envs_refuse_the_same_reset_input(env_id: str) -> None:
    env = gym.make(env_id, backend="exact")
    env.reset(seed=0)
    for kwargs, words in (({"seed": True}, "reset seed must be None or an integer >= 0"),
                          ({"options": ["machine"]}, "reset options must be a dict or None"),
                          ({"options": {"machine": 0}}, "reset option 'machine' must be a dict"),
                          ({"options": {"machine": {"drho": [30.0, 0, 0]}}}, "validity range")):
        with pytest.raises(ValueError, match=words):
            env.reset(**kwargs)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_both_envs_draw_rgb_frames_in_direct_mode(env_id: str) -> None:
    env = gym.make(env_id, backend="pybullet", render_mode="rgb_array")
    assert env.unwrapped.metadata["render_modes"][0] == "rgb_array"
    env.reset(seed=0)
    frame = env.render()
    env.close()
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 20  # a picture, not a blank


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_exact_backend_has_no_picture_in_either_env(env_id: str) -> None:
    assert "the exact backend has no picture" in refusal(env_id, render_mode="rgb_array")
    assert gym.make(env_id, backend="exact").unwrapped.metadata["render_modes"] == []


HUMAN_SCRIPT = """
import gymnasium as gym, orthoglide_env
try:
    gym.make({!r}, backend="pybullet", render_mode="human")
except ValueError as exc:
    print(exc)
"""


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_a_window_without_a_display_is_a_clear_error_in_both_envs(env_id: str) -> None:
    # In a subprocess: were the check missing, PyBullet's GUI would end the process.
    environ = {k: v for k, v in __import__("os").environ.items()
               if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run([sys.executable, "-c", HUMAN_SCRIPT.format(env_id)],
                          capture_output=True, text=True, timeout=120, env=environ)
    assert proc.returncode == 0, proc.stderr
    assert "render_mode='human' needs a display" in proc.stdout


def test_the_lab_tells_a_faulted_stand_from_a_lifted_one() -> None:
    env = gym.make(orthoglide_env.LAB_ENV_ID, stands=2, gauge_sigma=0.0)
    obs, _ = env.reset(seed=4)
    assert obs["engaged"].tolist() == [1, 1] and obs["faulted"].tolist() == [0, 0]
    obs, *_ = env.step(action(Op.LIFT, stand=1))
    assert obs["engaged"].tolist() == [1, 0] and obs["faulted"].tolist() == [0, 0]
    # Toward -y the x leg presses its y gauge (stand 0) past its travel: a fault.
    obs, _, _, _, info = env.step(action(Op.MOVE, np.array([0.0, -12.0, 0.0])))
    assert info["overtravel"] == ["stand 0 (x-leg/y@0.5)"]
    assert obs["engaged"].tolist() == [0, 0] and obs["faulted"].tolist() == [1, 0]
    # Re-mounted, it is in service again.
    obs, *_ = env.step(action(Op.REMOUNT, stand=0,
                              slot=slot_index("x-leg/y@0.5", design=PROTOTYPE)))
    assert obs["engaged"].tolist() == [1, 0] and obs["faulted"].tolist() == [0, 0]
    assert env.observation_space.contains(obs)
    env.close()


def test_the_clock_never_passes_the_budget() -> None:
    """Equal lab time is enforced: a re-mount that would end past the budget (8 s used of
    10, a re-mount takes 128 s from the far corner) is refused, saying so, and the clock
    runs to the budget exactly (it ended at 136 s when the step was played whole).  The
    time box keeps its documented bound."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, budget_s=10.0)
    lab = env.unwrapped
    high = float(env.observation_space["time"].high[0])
    assert high == 10.0 + lab.settings.longest_step()
    assert "budget_s + longest" in type(lab).__doc__
    env.reset(seed=0)
    obs, _, _, truncated, _ = env.step(action(Op.MOVE, np.full(3, 60.0)))
    assert not truncated and obs["time"][0] == 8.0
    mountings = lab.mountings
    obs, _, _, truncated, info = env.step(action(
        Op.REMOUNT, stand=0, slot=slot_index("x-carriage/y", design=PROTOTYPE)))
    assert truncated and obs["time"][0] == 10.0 and info["step_time_s"] == 2.0
    assert "past the budget of 10 s" in info["refused"] and lab.mountings == mountings
    assert env.observation_space.contains(obs)
    env.close()
