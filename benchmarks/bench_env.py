"""Environment throughput: steps per second of one env and of an AsyncVectorEnv of 2.

    python benchmarks/bench_env.py [--steps 3000]

Actions are small random moves around Zero (the gauges stay in contact, as in a
calibration); resets are not timed.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import orthoglide_env


def make(backend: str, motion: str = "quasi-static"):
    return lambda: gym.make(orthoglide_env.ENV_ID, backend=backend, motion=motion)


def single(backend: str, steps: int, motion: str = "quasi-static") -> float:
    env = make(backend, motion)()
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-8, 8, (steps, 3))
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def vector(backend: str, steps: int, workers: int, motion: str = "quasi-static") -> float:
    envs = gym.vector.AsyncVectorEnv([make(backend, motion) for _ in range(workers)])
    envs.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-8, 8, (steps // workers, workers, 3))
    start = time.perf_counter()
    for a in actions:
        envs.step(a)
    rate = len(actions) * workers / (time.perf_counter() - start)
    envs.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()
    print(f"{'backend':10}{'motion':14}{'1 env steps/s':>15}{'Async x2 steps/s':>18}"
          f"{'speed-up':>10}")
    for backend, motion, steps in (("pybullet", "quasi-static", args.steps),
                                   ("pybullet", "dynamic", args.steps // 10),
                                   ("exact", "quasi-static", args.steps)):
        one = single(backend, steps, motion)
        two = vector(backend, steps, 2, motion)
        print(f"{backend:10}{motion:14}{one:15.0f}{two:18.0f}{two / one:10.2f}")


if __name__ == "__main__":
    main()
