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

import argparse
import os
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import orthoglide_env

ID = orthoglide_env.LAB_ENV_ID


def actions(rng: np.random.Generator, steps: int, n: int) -> list[dict[str, np.ndarray]]:
    """``steps`` batched lab actions for ``n`` labs."""
    out = []
    for _ in range(steps):
        flick = rng.random(n) < 0.2
        out.append({"op": np.where(flick, rng.integers(1, 3, n), 0),
                    "rho": rng.uniform(-8, 8, (n, 3)), "stand": rng.integers(6, size=n),
                    "slot": np.zeros(n, dtype=np.int64)})
    return out


def single_runner(steps: int) -> Callable[[], float]:
    """One lab, reset whenever its episode ends; returns the seconds of ``steps`` steps."""
    env = gym.make(ID)
    env.reset(seed=0)
    plan = [{key: value[0] for key, value in a.items()}
            for a in actions(np.random.default_rng(0), steps, 1)]

    def run() -> float:
        start = time.perf_counter()
        for a in plan:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run


def vector_runner(envs: gym.vector.VectorEnv, steps: int) -> Callable[[], float]:
    """A vector env (autoreset on); returns the seconds of ``steps`` vector steps."""
    envs.reset(seed=0)
    plan = actions(np.random.default_rng(0), steps, envs.num_envs)

    def run() -> float:
        start = time.perf_counter()
        for a in plan:
            envs.step(a)
        return time.perf_counter() - start

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0,
                        help="length of one timed round of each configuration")
    args = parser.parse_args()
    # Rough rates (steps/s) only size the rounds; the table is measured below.
    configs: dict[str, tuple[int, int, Callable[[int], Callable[[], float]]]] = {
        "single lab": (1, 300, single_runner),
        "native N=1": (1, 300, lambda s: vector_runner(gym.make_vec(ID, num_envs=1), s)),
        "native N=64": (64, 8000, lambda s: vector_runner(gym.make_vec(ID, num_envs=64), s)),
        "native N=1024": (1024, 20000,
                          lambda s: vector_runner(gym.make_vec(ID, num_envs=1024), s)),
        "AsyncVectorEnv x2": (2, 300, lambda s: vector_runner(gym.make_vec(
            ID, num_envs=2, vectorization_mode="async"), s)),
    }
    steps = {name: max(3, int(args.seconds * guess) // n) for name, (n, guess, _) in
             configs.items()}
    runners = {name: (n, make(steps[name])) for name, (n, _, make) in configs.items()}
    load = os.getloadavg()[0]
    for _, run in runners.values():
        run()  # warm-up: imports, caches, allocator pools
    rates: dict[str, list[float]] = {name: [] for name in runners}
    for _ in range(args.rounds):
        for name, (n, run) in runners.items():
            rates[name].append(steps[name] * n / run())
    print(f"cpus: {os.cpu_count()}, load average (1 min) before/after timing: {load:.2f}/"
          f"{os.getloadavg()[0]:.2f}; {args.rounds} interleaved rounds of ~{args.seconds:g} s")
    base = float(np.median(rates["single lab"]))
    print(f"{'configuration':22}{'steps/s (median)':>18}{'min':>10}{'max':>10}"
          f"{'x single lab':>14}")
    for name, values in rates.items():
        median = float(np.median(values))
        print(f"{name:22}{median:18.0f}{min(values):10.0f}{max(values):10.0f}"
              f"{median / base:14.1f}")


if __name__ == "__main__":
    main()
