"""Environment throughput: steps per second of one env and of an AsyncVectorEnv of 2.

    python benchmarks/bench_env.py [--steps 3000]

Actions are small random moves around Zero (the gauges stay in contact, as in a
calibration); resets are not timed.  A speed-up from workers needs idle cores: the first
line measures what two processes of pure Python arithmetic gain on this machine right now
(about 2 on two idle cores), the ceiling for the vector env's speed-up, and the "round
trip" column what one AsyncVectorEnv worker adds to every step: with two workers a step
of ``s`` µs gives at best ``2 s / (s + round trip)``.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import time

import gymnasium as gym
import numpy as np

import orthoglide_env


def make(backend: str, motion: str = "quasi-static"):
    return lambda: gym.make(orthoglide_env.ENV_ID, backend=backend, motion=motion,
                            conditions="ideal")


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


def _spin(n: int) -> None:
    total = 0
    for k in range(n):
        total += k


def parallel_ceiling(n: int = 4_000_000) -> float:
    """Speed-up of two processes over one on the same CPU-bound work, measured now."""
    start = time.perf_counter()
    _spin(n)
    _spin(n)
    serial = time.perf_counter() - start
    start = time.perf_counter()
    workers = [multiprocessing.Process(target=_spin, args=(n,)) for _ in range(2)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    return serial / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()
    print(f"cpus: {os.cpu_count()}, load average: {os.getloadavg()[0]:.2f}, two-process "
          f"ceiling: {parallel_ceiling():.2f}x")
    # "round trip": what one AsyncVectorEnv worker adds to a step (pipes, process
    # wake-ups, shared memory); a vector step cannot be shorter than step + round trip.
    print(f"{'backend':10}{'motion':14}{'1 env steps/s':>15}{'round trip µs':>15}"
          f"{'Async x2 steps/s':>18}{'speed-up':>10}")
    for backend, motion, steps in (("pybullet", "quasi-static", args.steps),
                                   ("pybullet", "dynamic", args.steps // 10),
                                   ("exact", "quasi-static", args.steps)):
        one = single(backend, steps, motion)
        trip = 1e6 / vector(backend, steps // 2, 1, motion) - 1e6 / one
        two = vector(backend, steps, 2, motion)
        print(f"{backend:10}{motion:14}{one:15.0f}{trip:15.0f}{two:18.0f}{two / one:10.2f}")


if __name__ == "__main__":
    main()
