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
from calibrators.agents.iso230 import least_budget_s, programme_seconds
from calibrators.study.episodes import agent_rng, machine_seed, run_episode
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.lab.operations import PAPER_SLOTS
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


def test_iso230_2s_gauges_read_the_laser_at_every_move_in_v4():
    """In ``OrthoglideLab-v4`` (the lab ``compare`` makes for the interferometer) the
    gauges' part that follows the programme, ``active`` (``laser_at_every_move``: its refits
    use those readings), still reads the laser it left set up at every move, as in v3: the
    episode, played as ``compare`` plays it (:func:`run_episode`), is v3's record for
    record, and the laser is read after the programme at postures other than Zero."""
    episodes = {}
    for env_id in (V3, orthoglide_env.LAB_V4_ENV_ID):
        env = gym.make(env_id, backend="exact", conditions="ideal", errors="realistic",
                       instruments=["dial", "interferometer"], budget_s=3600.0)
        agent = get_agent("iso230-2")
        episodes[env_id] = run_episode(env, agent, machine_seed(1, 0)).records
    v3, v4 = episodes[V3], episodes[orthoglide_env.LAB_V4_ENV_ID]
    assert [(r.mounting, r.rho, r.reading, r.time_s) for r in v4] == \
        [(r.mounting, r.rho, r.reading, r.time_s) for r in v3]
    end = programme_seconds(PROTOTYPE, len(PAPER_SLOTS), agent.runs)
    assert any(isinstance(r.spec, InterferometerAxis) and r.time_s > end + 1e-6
               and r.rho != (0.0, 0.0, 0.0) for r in v4)
