"""Timing helpers shared by the env throughput benchmarks (bench_vector, bench_lab_vector).

A configuration is a name, its machines per step and a runner: a function that plays a
fixed plan of actions and returns the seconds it took.  Rounds are interleaved so that a
change of load on the machine hits every configuration alike.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np


def round_arguments(description: str) -> argparse.Namespace:
    """The options every throughput benchmark takes: ``--rounds`` and ``--seconds``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0,
                        help="length of one timed round of each configuration")
    return parser.parse_args()


def single_runner(env: gym.Env, plan: Sequence[Any]) -> Callable[[], float]:
    """One env, reset whenever its episode ends; returns the seconds of the plan."""
    env.reset(seed=0)

    def run() -> float:
        start = time.perf_counter()
        for action in plan:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run


def vector_runner(envs: gym.vector.VectorEnv, plan: Sequence[Any]) -> Callable[[], float]:
    """A vector env (autoreset on); returns the seconds of the plan's vector steps."""
    envs.reset(seed=0)

    def run() -> float:
        start = time.perf_counter()
        for action in plan:
            envs.step(action)
        return time.perf_counter() - start

    return run


def interleaved_rates(runners: dict[str, tuple[int, int, Callable[[], float]]], rounds: int
                      ) -> dict[str, list[float]]:
    """Machine-steps per second of every ``(machines per step, steps, runner)``, one value
    per round, after one warm-up run each (imports, caches, allocator pools)."""
    for _, _, run in runners.values():
        run()
    rates: dict[str, list[float]] = {name: [] for name in runners}
    for _ in range(rounds):
        for name, (n, steps, run) in runners.items():
            rates[name].append(steps * n / run())
    return rates


def print_rates(rates: dict[str, list[float]], base: str, load: float, rounds: int,
                seconds: float) -> None:
    """The table: median, min and max steps/s of each configuration and its ratio to
    ``base``'s median."""
    print(f"cpus: {os.cpu_count()}, load average (1 min) before/after timing: {load:.2f}/"
          f"{os.getloadavg()[0]:.2f}; {rounds} interleaved rounds of ~{seconds:g} s")
    reference = float(np.median(rates[base]))
    print(f"{'configuration':22}{'steps/s (median)':>18}{'min':>10}{'max':>10}"
          f"{'x ' + base:>14}")
    for name, values in rates.items():
        median = float(np.median(values))
        print(f"{name:22}{median:18.0f}{min(values):10.0f}{max(values):10.0f}"
              f"{median / reference:14.1f}")
