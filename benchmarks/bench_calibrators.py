"""Wall time of one `paper` calibration episode and of a 1000-machine comparison.

    python benchmarks/bench_calibrators.py [--machines 1000]

The comparison runs both strategies (paper, gauss-newton) on every machine, on every
core; they share one experiment (the same postures and readings), so 1000 machines are
1000 experiments and 2000 estimates.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import orthoglide_env
from calibrators.base import get_strategy
from calibrators.compare import Config, run


def episode_times(backend: str, strategy: str, repeats: int = 20) -> np.ndarray:
    env = gym.make(orthoglide_env.ENV_ID, backend=backend)
    out = []
    for seed in range(repeats):
        start = time.perf_counter()
        env.reset(seed=seed)
        get_strategy(strategy).run(env, verify=False)
        out.append(time.perf_counter() - start)
    env.close()
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=1000)
    args = parser.parse_args()
    print("one calibration episode (reset + experiment + estimate), median of 20:")
    for backend in ("pybullet", "exact"):
        for strategy in ("paper", "gauss-newton"):
            t = episode_times(backend, strategy)
            print(f"  {backend:9}{strategy:14}{1e3 * np.median(t):8.1f} ms")
    for backend in ("exact", "pybullet"):
        config = Config(("paper", "gauss-newton"), "realistic", 0.02, 0.01, backend, "full", 0)
        start = time.perf_counter()
        run(config, args.machines, progress=False)
        wall = time.perf_counter() - start
        print(f"compare --machines {args.machines} --backend {backend}: {wall:.1f} s "
              f"({1e3 * wall / args.machines:.1f} ms per machine)")


if __name__ == "__main__":
    main()
