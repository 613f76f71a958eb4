"""Throughput of the lab's native vector env against one lab and Gymnasium's vector envs.

    python benchmarks/bench_lab_vector.py [--rounds 5] [--seconds 1.0]

``OrthoglideLab-v0`` on the exact backend (the collision test is always on), actions as
in a calibration: small random moves around Zero (80 %) and lever flicks (20 %),
autoresets at the end of the time budget included.  Every configuration is timed
``--rounds`` times, the rounds interleaved so that a change of load on the machine hits
all of them alike; the table gives the median machine-steps per second (a vector step of
N labs counts N) and its ratio to the single lab's median of the same run.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from throughput import (
    interleaved_rates,
    print_rates,
    round_arguments,
    single_runner,
    vector_runner,
)

import orthoglide_env

ID = orthoglide_env.LAB_ENV_ID


def plan(steps: int, n: int) -> list[dict[str, np.ndarray]]:
    """``steps`` batched lab actions for ``n`` labs."""
    rng = np.random.default_rng(0)
    out = []
    for _ in range(steps):
        flick = rng.random(n) < 0.2
        out.append({"op": np.where(flick, rng.integers(1, 3, n), 0),
                    "rho": rng.uniform(-8, 8, (n, 3)), "stand": rng.integers(6, size=n),
                    "slot": np.zeros(n, dtype=np.int64)})
    return out


def main() -> None:
    args = round_arguments(__doc__.splitlines()[0])
    # Rough rates (steps/s) only size the rounds; the table is measured below.
    configs: dict[str, tuple[int, int, Callable[[int], Callable[[], float]]]] = {
        "single lab": (1, 300, lambda s: single_runner(gym.make(ID, conditions="ideal"), [
            {key: value[0] for key, value in a.items()} for a in plan(s, 1)])),
        "native N=1": (1, 300, lambda s: vector_runner(
            gym.make_vec(ID, conditions="ideal", num_envs=1), plan(s, 1))),
        "native N=64": (64, 8000, lambda s: vector_runner(
            gym.make_vec(ID, conditions="ideal", num_envs=64), plan(s, 64))),
        "native N=1024": (1024, 20000, lambda s: vector_runner(
            gym.make_vec(ID, conditions="ideal", num_envs=1024), plan(s, 1024))),
        "AsyncVectorEnv x2": (2, 300, lambda s: vector_runner(gym.make_vec(
            ID, conditions="ideal", num_envs=2, vectorization_mode="async"), plan(s, 2))),
    }
    runners = {}
    for name, (n, guess, make) in configs.items():
        steps = max(3, int(args.seconds * guess) // n)
        runners[name] = (n, steps, make(steps))
    load = os.getloadavg()[0]
    rates = interleaved_rates(runners, args.rounds)
    print_rates(rates, "single lab", load, args.rounds, args.seconds)

if __name__ == "__main__":
    main()
