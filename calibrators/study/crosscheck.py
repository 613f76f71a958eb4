"""The PyBullet cross-check of a comparison: its first machines re-run on the PyBullet lab
in lockstep with the exact lab, and the largest differences of readings and tool
positions between the two."""

from __future__ import annotations

from contextlib import closing
from functools import partial

import gymnasium as gym
import numpy as np

from calibrators.agents import get_agent
from calibrators.study.compare import Config
from calibrators.study.episodes import machine_seed, run_episodes
from calibrators.study.labs import lab_id


def verify_pybullet(config: Config, machines: int) -> dict[str, float]:
    """Re-run the first ``machines`` machines of ``config`` with every agent on the
    PyBullet lab in lockstep with the exact lab (the same seed, actions and, with ideal
    gauges, no rounding to tell them apart): the largest reading and TCP differences (mm)
    over every step."""
    worst = {"reading_mm": 0.0, "tcp_mm": 0.0, "steps": 0}
    for index in range(machines):
        for name in config.agents:
            agent = get_agent(name)
            kwargs = {**config.lab_kwargs(agent), "gauge_sigma": 0.0,
                      "gauge_resolution": 0.0}
            envs = gym.vector.SyncVectorEnv([
                partial(gym.make, lab_id(kwargs), **{**kwargs, "backend": backend})
                for backend in ("exact", "pybullet")])
            seed = machine_seed(config.seed, index)
            with closing(envs):
                run_episodes(envs, [agent], [seed, seed], lockstep=True,
                             on_step=partial(_widen_gaps, worst, envs))
    return worst


def _widen_gaps(worst: dict[str, float], envs: gym.vector.SyncVectorEnv,
                observation: dict[str, np.ndarray]) -> None:
    """Widen ``worst`` to this step's reading and TCP differences between the two labs of
    ``envs``; count the step."""
    both = (observation["valid"] == 1).all(axis=0)
    gap = np.abs(observation["gauges"][0] - observation["gauges"][1])[both]
    tcp = [env.unwrapped.tcp() for env in envs.envs]
    worst["reading_mm"] = max(worst["reading_mm"], float(gap.max(initial=0)))
    worst["tcp_mm"] = max(worst["tcp_mm"], float(np.abs(tcp[0] - tcp[1]).max()))
    worst["steps"] += 1
