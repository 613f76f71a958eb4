"""Throughput of the native vector env against one env and Gymnasium's vector envs.

    python benchmarks/bench_vector.py [--rounds 5] [--seconds 1.0]

Exact backend (the only one the native vector env runs), the collision test on (it always
is), actions small random moves around Zero as in a calibration (bench_env.py), autoresets
and the resets of the single env after its truncation included.  Every configuration is
timed ``--rounds`` times, the rounds interleaved so that a change of load on the machine
hits all of them alike; the table gives the median steps/s (machine-steps: a vector step
of N envs counts N) and its ratio to the single env's median of the same run.

Memory: what numpy and Python allocate (tracemalloc) for the env's state after a reset,
and the peak of one step on top of it, per 1000 machines, for the native env of 1000 and
for 1000 separate single envs.
"""

from __future__ import annotations

import argparse
import gc
import os
import time
import tracemalloc
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import orthoglide_env

ID = orthoglide_env.ENV_ID


def single_runner(steps: int) -> Callable[[], float]:
    """One env, reset whenever its episode ends; returns the seconds of ``steps`` steps."""
    env = gym.make(ID, backend="exact")
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-8, 8, (steps, 3))

    def run() -> float:
        start = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run


def vector_runner(envs: gym.vector.VectorEnv, steps: int) -> Callable[[], float]:
    """A vector env (autoreset on); returns the seconds of ``steps`` vector steps."""
    envs.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-8, 8, (steps, envs.num_envs, 3))

    def run() -> float:
        start = time.perf_counter()
        for a in actions:
            envs.step(a)
        return time.perf_counter() - start

    return run


def native(n: int) -> gym.vector.VectorEnv:
    return gym.make_vec(ID, num_envs=n, vectorization_mode="vector_entry_point",
                        backend="exact")


def steps_for(seconds: float, rate: float) -> int:
    """Steps that take about ``seconds`` at ``rate`` steps per second."""
    return max(5, int(seconds * rate))


def memory_per_thousand() -> dict[str, tuple[float, float]]:
    """MB per 1000 machines (state after reset, peak of one step on top), native env of
    1000 and 1000 separate envs."""
    out = {}
    for name, build in (("native vector env", lambda: native(1000)),
                        ("1000 separate envs", lambda: gym.make_vec(
                            ID, num_envs=1000, vectorization_mode="sync", backend="exact"))):
        gc.collect()
        tracemalloc.start()
        envs = build()
        envs.reset(seed=0)
        state, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        envs.step(np.zeros((1000, 3)))
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        out[name] = (state / 1e6, (peak - state) / 1e6)
        envs.close()
        del envs
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0,
                        help="length of one timed round of each configuration")
    args = parser.parse_args()
    # Rough rates (steps/s) only size the rounds; the table is measured below.
    configs: dict[str, tuple[int, Callable[[int], Callable[[], float]]]] = {
        "single env": (1, single_runner),
        "native N=1": (1, lambda s: vector_runner(native(1), s)),
        "native N=64": (64, lambda s: vector_runner(native(64), s)),
        "native N=1024": (1024, lambda s: vector_runner(native(1024), s)),
        "SyncVectorEnv x8": (8, lambda s: vector_runner(gym.make_vec(
            ID, num_envs=8, vectorization_mode="sync", backend="exact"), s)),
        "AsyncVectorEnv x2": (2, lambda s: vector_runner(gym.make_vec(
            ID, num_envs=2, vectorization_mode="async", backend="exact"), s)),
    }
    guess = {"single env": 1000, "native N=1": 1000, "native N=64": 20000,
             "native N=1024": 30000, "SyncVectorEnv x8": 1000, "AsyncVectorEnv x2": 1000}
    runners = {name: (n, make(steps_for(args.seconds, guess[name]) // n or 1))
               for name, (n, make) in configs.items()}
    load = os.getloadavg()[0]
    for _, run in runners.values():
        run()  # warm-up: imports, caches, allocator pools
    rates: dict[str, list[float]] = {name: [] for name in runners}
    for _ in range(args.rounds):
        for name, (n, run) in runners.items():
            steps = steps_for(args.seconds, guess[name]) // n or 1
            rates[name].append(steps * n / run())
    print(f"cpus: {os.cpu_count()}, load average (1 min) before/after timing: {load:.2f}/"
          f"{os.getloadavg()[0]:.2f}; {args.rounds} interleaved rounds of ~{args.seconds:g} s")
    base = float(np.median(rates["single env"]))
    print(f"{'configuration':22}{'steps/s (median)':>18}{'min':>10}{'max':>10}"
          f"{'x single env':>14}")
    for name, values in rates.items():
        median = float(np.median(values))
        print(f"{name:22}{median:18.0f}{min(values):10.0f}{max(values):10.0f}"
              f"{median / base:14.1f}")
    print(f"{'memory per 1000 machines':28}{'state MB':>10}{'step peak MB':>14}")
    for name, (state, peak) in memory_per_thousand().items():
        print(f"{name:28}{state:10.1f}{peak:14.1f}")


if __name__ == "__main__":
    main()
