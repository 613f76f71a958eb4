"""Wall time of one calibration episode in the lab, and of a comparison.

    python benchmarks/bench_calibrators.py [--machines 100]

An episode is the lab's reset, the paper agent's experiment and one estimate.  The
comparison runs the paper agent with the paper and extended estimators on every machine,
in one process and in two.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.estimators.catalogue import for_study
from calibrators.study.compare import Config, run
from calibrators.study.episodes import run_episode
from orthoglide_env.world.conditions import IDEAL


def episode_times(backend: str, estimator: str, repeats: int = 10) -> np.ndarray:
    env = gym.make(orthoglide_env.LAB_ENV_ID, backend=backend, conditions="ideal")
    out = []
    for seed in range(repeats):
        start = time.perf_counter()
        episode = run_episode(env, get_agent("paper"), seed)
        for_study(estimator, episode.sigma).fit(episode.measurements)
        out.append(time.perf_counter() - start)
    env.close()
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=100)
    args = parser.parse_args()
    print("one calibration episode (reset + paper agent + estimate), median of 10:")
    for backend in ("pybullet", "exact"):
        for estimator in ("paper", "paper6", "extended"):
            t = episode_times(backend, estimator)
            print(f"  {backend:9}{estimator:10}{1e3 * np.median(t):8.1f} ms")
    config = Config(("paper",), ("paper", "extended"), conditions=IDEAL)
    for jobs in (1, 2):
        start = time.perf_counter()
        run(config, args.machines, jobs=jobs)
        wall = time.perf_counter() - start
        print(f"compare --agents paper --estimators paper,extended --machines {args.machines} "
              f"--jobs {jobs}: {wall:.1f} s ({1e3 * wall / args.machines:.1f} ms per machine)")


if __name__ == "__main__":
    main()
