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

import gc
import os
import tracemalloc
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

ID = orthoglide_env.ENV_ID


def plan(steps: int, n: int | None) -> np.ndarray:
    """Small random moves around Zero, as in a calibration: ``steps`` actions of one env
    (``n`` None) or vector actions of ``n`` envs."""
    shape = (steps, 3) if n is None else (steps, n, 3)
    return np.random.default_rng(0).uniform(-8, 8, shape)


def native(n: int) -> gym.vector.VectorEnv:
    return gym.make_vec(ID, conditions="ideal", num_envs=n, vectorization_mode="vector_entry_point",
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
                            ID, conditions="ideal", num_envs=1000, vectorization_mode="sync",
                            backend="exact"))):
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
    args = round_arguments(__doc__.splitlines()[0])
    # Rough rates (steps/s) only size the rounds; the table is measured below.
    configs: dict[str, tuple[int, int, Callable[[int], Callable[[], float]]]] = {
        "single env": (1, 1000, lambda s: single_runner(
            gym.make(ID, conditions="ideal", backend="exact"), plan(s, None))),
        "native N=1": (1, 1000, lambda s: vector_runner(native(1), plan(s, 1))),
        "native N=64": (64, 20000, lambda s: vector_runner(native(64), plan(s, 64))),
        "native N=1024": (1024, 30000, lambda s: vector_runner(native(1024), plan(s, 1024))),
        "SyncVectorEnv x8": (8, 1000, lambda s: vector_runner(gym.make_vec(
            ID, conditions="ideal", num_envs=8, vectorization_mode="sync", backend="exact"),
            plan(s, 8))),
        "AsyncVectorEnv x2": (2, 1000, lambda s: vector_runner(gym.make_vec(
            ID, conditions="ideal", num_envs=2, vectorization_mode="async", backend="exact"),
            plan(s, 2))),
    }
    runners = {}
    for name, (n, guess, make) in configs.items():
        steps = steps_for(args.seconds, guess) // n or 1
        runners[name] = (n, steps, make(steps))
    load = os.getloadavg()[0]
    rates = interleaved_rates(runners, args.rounds)
    print_rates(rates, "single env", load, args.rounds, args.seconds)
    print(f"{'memory per 1000 machines':28}{'state MB':>10}{'step peak MB':>14}")
    for name, (state, peak) in memory_per_thousand().items():
        print(f"{name:28}{state:10.1f}{peak:14.1f}")


if __name__ == "__main__":
    main()
