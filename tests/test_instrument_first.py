"""The reference procedures' hand-over to the gauges' part: it starts from every gauge's
zero, read at Zero after the programme."""

from __future__ import annotations

import collections

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.instrument_first import InstrumentFirst
from calibrators.agents.iso230 import drive_steps, least_budget_s, programme_seconds
from calibrators.study.episodes import agent_rng, machine_seed, run_episode
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
from orthoglide_env.model.design import PROTOTYPE

V3 = orthoglide_env.LAB_V3_ENV_ID


@pytest.mark.parametrize("name, instrument", [("iso230-2", "interferometer"),
                                              ("ballbar", "ballbar"),
                                              ("step-gauge", "step-gauge")])
def test_the_gauges_part_starts_from_every_gauges_zero(name: str, instrument: str):
    """What the lab shows when the programme is done, the gauges' part's first
    observation, reads every stand at Zero (its filter takes in only what it sees from its
    start), on a realistic machine under ``lab``."""
    env = gym.make(V3, backend="exact", conditions="lab", errors="realistic",
                   instruments=["dial", instrument], budget_s=3 * 3600.0)
    seed = machine_seed(1, 0)
    observation, info = env.reset(seed=seed)
    agent = get_agent(name)
    assert isinstance(agent, InstrumentFirst)
    agent.reset(env.unwrapped, observation, agent_rng(seed))
    while agent.queue:
        observation, *_, info = env.step(agent.act(observation, info))
        assert not info["refused"] and not info["overtravel"]
    assert np.all(observation["valid"] == 1)
    assert np.array_equal(env.unwrapped.records[-1].rho, (0.0, 0.0, 0.0))


@pytest.mark.slow
def test_iso230_2s_gauges_read_every_leg_where_they_read_two():
    """Machine 23 of seed 1 under ``lab`` at one hour, where the gauges' part read the
    stands of two legs only before it started from their zeros (the third leg's stands
    had their zero reading of the reset and nothing else): each stand is now read by the
    gauges' part, after the programme (which ends at the least budget: one run a drive)."""
    env = gym.make(V3, backend="exact", conditions="lab", errors="realistic",
                   instruments=["dial", "interferometer"], budget_s=3600.0)
    episode = run_episode(env, get_agent("iso230-2"), machine_seed(1, 23))
    end = least_budget_s(PROTOTYPE, len(PAPER_SLOTS))
    after = collections.Counter(r.mounting for r in episode.records if r.time_s > end + 1.0
                                and not r.mounting.startswith("interferometer"))
    assert len(after) == len(PAPER_SLOTS), after


def test_iso230_2s_gauges_leave_the_laser_unread_in_v4():
    """In ``OrthoglideLab-v4`` (the lab ``compare`` makes for the interferometer) the
    laser's readings on moves are the programme's alone: the gauges' part that follows,
    played as ``compare`` plays it (:func:`run_episode`), leaves the laser it left set up
    unread on its moves, which pay no dwell (a re-mount's reading at Zero reads it, as in
    every version); in v3 every one of them reads it."""
    readings = {}
    for env_id in (V3, orthoglide_env.LAB_V4_ENV_ID):
        env = gym.make(env_id, backend="exact", conditions="ideal", errors="realistic",
                       instruments=["dial", "interferometer"], budget_s=3600.0)
        agent = get_agent("iso230-2")
        episode = run_episode(env, agent, machine_seed(1, 0))
        readings[env_id] = [r for r in episode.records if isinstance(r.spec, InterferometerAxis)]
    # Every move of the programme after the first set-up reads it, and its set-ups.
    programme = drive_steps(len(PAPER_SLOTS), PROTOTYPE, agent.runs)
    first = next(i for i, s in enumerate(programme) if s["op"] == Op.ALIGN)
    read = sum(s["op"] in (Op.MOVE, Op.ALIGN) for s in programme[first:])
    end = programme_seconds(PROTOTYPE, len(PAPER_SLOTS), agent.runs)
    laser = readings[orthoglide_env.LAB_V4_ENV_ID]
    assert sum(r.time_s <= end + 1e-6 for r in laser) == read
    assert all(r.rho == (0.0, 0.0, 0.0) for r in laser[read:])
    assert any(r.rho != (0.0, 0.0, 0.0) for r in readings[V3][read:])
