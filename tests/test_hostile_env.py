"""The environment against hostile input: every refusal is a ValueError naming the input,
and a refused call changes nothing (the episode before it goes on, random stream
included); rendering and check_env behave where there is no display."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pybullet as pb
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import orthoglide_env
from orthoglide_env.envs import calibration as env_module
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.sim.pybullet import OrthoglideMachine

HAVE_PYBULLET = importlib.util.find_spec("orthoglide_env.sim.pybullet") is not None
needs_pybullet = pytest.mark.skipif(not HAVE_PYBULLET, reason="orthoglide_env.sim.pybullet absent")
BACKENDS = ("exact", pytest.param("pybullet", marks=needs_pybullet))
#: check_env recommends actions normalised to [-1, 1]; ours are joint targets in mm
#: (tests/test_env.py says why), so that warning is the one expected.
EXPECTED_WARNING = "symmetric and normalized space"
FIRST, SECOND = np.array([10.0, -5.0, 3.0]), np.array([-4.0, 2.0, 1.0])


def make(backend: str, **kwargs) -> gym.Env:
    return gym.make(orthoglide_env.ENV_ID, backend=backend, **kwargs).unwrapped


def without_display() -> dict[str, str]:
    """This process's environment with no X display: a subprocess cannot open a window."""
    return {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}


REFUSED_RESETS = [
    ({"options": {"machine": {"dL": [-200.0, -200.0, -200.0]}}}, "validity range"),
    ({"options": {"machine": {"drho": [30.0, 0.0, 0.0]}}}, "validity range"),
    ({"options": {"machine": MachineParams(dL=[-200.0, -200.0, -200.0])}}, "validity range"),
    ({"options": {"machine": {"drho": [True, 0, 0]}}}, "must hold numbers"),
    ({"options": {"machine": []}}, "reset option 'machine' must be a dict"),
    ({"options": {"machine": 0}}, "reset option 'machine' must be a dict"),
    ({"options": {"machine": False}}, "reset option 'machine' must be a dict"),
    ({"options": {"machine": ""}}, "reset option 'machine' must be a dict"),
    ({"options": {"gauges": ["x-leg/q"] * 6}}, "bad gauge name"),
    ({"options": {"gauges": "x-leg/y"}}, "reset option 'gauges' must be a list"),
    ({"options": {"gauges": ["x-leg/y"]}}, "observes 6 gauges"),
    ({"options": {"speed": 3}}, "unknown reset option"),
    ({"options": ["machine"]}, "reset options must be a dict"),
    ({"seed": -1}, "seed"),
    ({"seed": "1"}, "seed"),
    ({"seed": True}, "seed"),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("reset_kwargs", "fragment"), REFUSED_RESETS)
def test_refused_reset_keeps_the_episode_going(backend: str, reset_kwargs: dict,
                                               fragment: str) -> None:
    refused, untouched = make(backend), make(backend)
    try:
        for env in (refused, untouched):
            env.reset(seed=3)
            env.step(FIRST)
        truth = refused.true_machine
        with pytest.raises(ValueError, match=fragment):
            refused.reset(**reset_kwargs)
        assert refused.true_machine == truth
        # The same machine, posture and random stream: the next step is exactly the one
        # an env that never saw the refused reset takes (gauge noise included).
        assert repr(refused.step(SECOND)) == repr(untouched.step(SECOND))
    finally:
        refused.close()
        untouched.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_refused_first_reset_leaves_no_episode(backend: str) -> None:
    env = make(backend)
    with pytest.raises(ValueError, match="validity range"):
        env.reset(options={"machine": {"dL": [-200.0, -200.0, -200.0]}})
    with pytest.raises(RuntimeError, match="reset"):
        env.step(FIRST)
    env.reset(seed=0)  # a good reset after a refused one works
    env.step(FIRST)
    env.close()


def _connected_clients() -> int:
    return sum(pb.getConnectionInfo(c)["isConnected"] for c in range(64))


@needs_pybullet
def test_failure_while_building_releases_the_new_machine(monkeypatch) -> None:
    # No valid input fails this late any more (the validity range refuses such machines
    # first); the failure is injected to show that the half-built episode is released.
    env, untouched = make("pybullet"), make("pybullet")
    for e in (env, untouched):
        e.reset(seed=1)
    clients = _connected_clients()

    close_loops = OrthoglideMachine._close_loops
    calls: list[object] = []

    def refuse_once(machine: OrthoglideMachine) -> list:
        calls.append(machine)
        if len(calls) == 1:
            raise ValueError("the loops do not close")
        return close_loops(machine)

    # Half way through building the new machine in the env's client (once: the old
    # machine is then built again in its place).
    monkeypatch.setattr(OrthoglideMachine, "_close_loops", refuse_once)
    with pytest.raises(ValueError, match="do not close"):
        env.reset(seed=2)
    assert len(calls) == 2
    assert _connected_clients() == clients
    assert env._batch.backend.sim.client.getNumBodies() == 1  # the old machine, built again
    assert repr(env.step(FIRST)) == repr(untouched.step(FIRST))
    env.close()
    untouched.close()


def test_explicit_none_means_what_leaving_it_out_means() -> None:
    env = make("exact")
    drawn = env.reset(seed=4)[0], env.true_machine
    given_none = env.reset(seed=4, options={"machine": None, "gauges": None})[0], \
        env.true_machine
    assert repr(drawn[0]) == repr(given_none[0]) and drawn[1] == given_none[1]
    env.close()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("action", [
    ["1", "2", "3"], np.array(["1", "2", "3"]), [1 + 0j, 2, 3], np.array([1, 2, 3], complex),
    [True, False, True], np.array([1, 0, 1], bool), [1.0, None, 3.0],
    np.array([1.0, 2.0, 3.0], dtype=object), [10**400, 0, 0],
])
def test_actions_must_be_real_numbers(backend: str, action: object) -> None:
    env, untouched = make(backend), make(backend)
    for e in (env, untouched):
        e.reset(seed=5)
    with pytest.raises(ValueError, match="3 numbers"):
        env.step(action)
    assert repr(env.step(FIRST)) == repr(untouched.step(FIRST))
    env.close()
    untouched.close()


def _is_accepted(values: list) -> bool:
    """The rule: three ints or floats (never booleans), finite, inside the joint limits."""
    return all(isinstance(v, int | float) and not isinstance(v, bool)
               and np.isfinite(v) and PROTOTYPE.rho_min <= v <= PROTOTYPE.rho_max for v in values)


ELEMENTS = st.one_of(
    st.floats(PROTOTYPE.rho_min - 20, PROTOTYPE.rho_max + 20),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-150, 100), st.booleans(), st.text(max_size=3),
    st.from_regex(r"-?[0-9]{1,2}(\.[0-9])?", fullmatch=True), st.complex_numbers(),
    st.none(),
)


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(ELEMENTS, min_size=3, max_size=3))
def test_an_action_is_accepted_exactly_when_it_is_three_real_numbers_in_limits(
    values: list,
) -> None:
    env = make("exact")
    env.reset(seed=6)
    try:
        obs, *_ = env.step(values)
    except ValueError:
        assert not _is_accepted(values), values
    else:
        assert _is_accepted(values), values
        np.testing.assert_array_equal(obs["joints"], np.array(values, dtype=float))
    finally:
        env.close()


@pytest.mark.parametrize(("kwargs", "fragment"), [
    ({"errors": ["realistic"]}, "errors must be the name"),
    ({"gauge_sigma": "0.02"}, "gauge_sigma must be a number"),
    ({"gauge_sigma": True}, "gauge_sigma must be a number"),
    ({"gauge_resolution": 1e-300}, "finer than any dial gauge"),
    ({"gauge_resolution": 5.0}, "gauge_resolution 5 mm is out of range"),
    ({"travel": float("inf")}, "travel"),
    ({"travel": "10"}, "travel"),
    ({"max_episode_steps": 2.5}, "max_episode_steps"),
    ({"clip_actions": "no"}, "clip_actions"),
    ({"gauges": "x-leg/y"}, "gauges must be a list"),
])
def test_bad_constructor_arguments_name_themselves(kwargs: dict, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        env_module.OrthoglideCalibrationEnv(backend="exact", **kwargs)


HUMAN_SCRIPT = """
import gymnasium as gym, orthoglide_env
try:
    gym.make("OrthoglideCalibration-v0", render_mode="human")
except ValueError as exc:
    print(exc)
"""


@needs_pybullet
@pytest.mark.parametrize("display", [None, ":65000"])
def test_human_rendering_without_a_display_is_a_clear_error(display: str | None) -> None:
    # In a subprocess: were the check missing, PyBullet's GUI would end the process.
    env = without_display() | ({} if display is None else {"DISPLAY": display})
    proc = subprocess.run([sys.executable, "-c", HUMAN_SCRIPT], capture_output=True,
                          text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "render_mode='human' needs a display" in proc.stdout
    assert ("DISPLAY" in proc.stdout) and "render_mode='rgb_array'" in proc.stdout


CHECK_ENV = ("import gymnasium as gym, orthoglide_env; "
             "from gymnasium.utils.env_checker import check_env; "
             "check_env(gym.make('OrthoglideCalibration-v0', backend={!r}).unwrapped)")


@pytest.mark.parametrize("backend", BACKENDS)
def test_check_env_with_default_arguments_is_clean(backend: str) -> None:
    # Headless, as on a CI machine: the render modes an instance advertises are the ones
    # it can draw, so check_env's render checks pass without opening a window.
    proc = subprocess.run([sys.executable, "-W", "always", "-c", CHECK_ENV.format(backend)],
                          capture_output=True, text=True, timeout=300, env=without_display())
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if "Warning" in line]
    assert warnings and all(EXPECTED_WARNING in line for line in warnings), proc.stderr


def test_instances_advertise_only_what_they_can_draw(monkeypatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    assert make("exact").metadata["render_modes"] == []
    if HAVE_PYBULLET:
        assert make("pybullet").metadata["render_modes"] == ["rgb_array"]
    # gym.make checks a requested mode against the class, which lists every mode.
    assert env_module.OrthoglideCalibrationEnv.metadata["render_modes"] == ["rgb_array",
                                                                           "human"]
