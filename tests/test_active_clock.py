"""``active``'s replay of the fixed plan's re-mounts on the lab's clock: due when the lab's
clock reaches the plan's time for them, from wherever the lab's clock stood when the agent
began, and dropped when one would no longer end within the budget."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents.names import get_agent
from calibrators.agents.optimal import fixed_plan, lab_setup
from calibrators.planning.belief import PlannedOperation
from orthoglide_env.lab.operations import Op

#: A short ideal-world experiment: its fixed plan re-mounts a stand after 5 minutes.
BUDGET_S = 600.0


def _lab(budget_s: float = BUDGET_S) -> gym.Env:
    return gym.make(orthoglide_env.LAB_ENV_ID, backend="exact", conditions="ideal",
                    errors="realistic", gauge_sigma=0.02, budget_s=budget_s)


def _play(env: gym.Env, agent, observation) -> list[tuple[int, float, float, str]]:
    """Each step of the rest of the episode: its operation, the lab's clock before and
    after it, and why it was refused ("": it was not)."""
    info: dict = {}
    steps = []
    done = False
    while not done:
        chosen = agent.act(observation, info)
        before = float(observation["time"][0])
        observation, _, terminated, truncated, info = env.step(chosen)
        steps.append((int(chosen["op"]), before, float(observation["time"][0]),
                      str(info.get("refused", ""))))
        done = terminated or truncated
    return steps


def test_a_re_mount_that_no_longer_fits_is_dropped_and_the_moves_go_on() -> None:
    """A re-mount the plan puts 60 s before the end takes 2 minutes: replayed, the lab
    would refuse it and end the episode there.  The agent drops it and keeps choosing
    moves that fit, to the end of its budget."""
    env = _lab()
    observation, _ = env.reset(seed=4)
    agent = get_agent("active")
    agent.reset(env, observation, np.random.default_rng(0))
    free = next(s for s in range(len(env.unwrapped.slots)) if s not in agent.planner.slots)
    late = BUDGET_S - 60.0
    agent.remounts.append(PlannedOperation(Op.REMOUNT, stand=0, slot=free, time_s=late))
    steps = _play(env, agent, observation)
    assert not [s for s in steps if s[3]]
    assert not [s for s in steps if s[0] == Op.REMOUNT and s[1] >= late]
    moves_after = [s for s in steps if s[0] == Op.MOVE and s[1] >= late]
    assert len(moves_after) >= 3  # 60 s hold several moves of 5-13 s
    assert steps[-1][2] <= BUDGET_S
    env.close()


@pytest.mark.slow
def test_re_mounts_are_due_on_the_lab_s_clock_from_where_the_agent_began() -> None:
    """Begun 6 minutes into the lab's clock (three re-mounts of a stand onto its own slot,
    as a reference procedure's programme takes time first), the agent re-mounts no stand
    before the lab's clock has run the plan's time for it from there: its plan for the
    19 minutes left re-mounts a stand after 5."""
    env = _lab(1500.0)
    observation, _ = env.reset(seed=4)
    for _ in range(3):
        observation, *_ = env.step({"op": int(Op.REMOUNT), "rho": np.zeros(3), "stand": 0,
                                    "slot": int(observation["slot"][0])})
    start = float(observation["time"][0])
    assert start > 300.0
    planned = [s.time_s for s in fixed_plan(*lab_setup(env.unwrapped, observation))[0]
               if s.op == Op.REMOUNT]
    assert planned and planned[0] < start  # the plan's clock alone would make it due now
    agent = get_agent("active")
    agent.reset(env, observation, np.random.default_rng(0))
    played = [s[1] for s in _play(env, agent, observation) if s[0] == Op.REMOUNT]
    assert played and played[0] >= start + planned[0]
    env.close()
