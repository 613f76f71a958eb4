"""compare's batched pipeline against its per-machine path, and its memory.

    python benchmarks/bench_compare.py [--machines 1000] [--per-machine 100]
        [--estimators paper,paper6,extended] [--memory-machines 10000] [--repeat 3]

For each estimator, the paper agent on ``--machines`` realistic machines (exact backend,
one process): the batched path (``run_chunk(batched=True)`` in compare's chunks: every
agent's episodes of a chunk in the lab vector env, the fits and scores batched) and the
per-machine path (``run_chunk(batched=False)`` one machine at a time: its episode in a
lone lab step by step, then its fit and its scores, each a batch of one) on the first
``--per-machine`` machines, in the same run, both after a warm-up on another machine and
each the fastest of ``--repeat`` runs taken in turns; the time per machine of each, their
ratio, and the largest difference between the two paths' trials on the machines both ran
(parameters, scores, predicted errors, mm).  Then the episodes alone (the agent in the
lab, no estimate).  Then, per estimator, the batched path under ``--conditions`` (default
``lab``: every effect of the world on) against the same run under ``ideal``, each the
fastest of ``--repeat`` runs taken in turns, and their ratio.  Last, the peak resident
memory (``getrusage`` max RSS) of a fresh process that runs ``--memory-machines``
machines through the batched path with the paper estimator.  BLAS runs single-threaded,
as in compare's workers.
"""

from __future__ import annotations

import argparse
import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import orthoglide_env  # noqa: E402
from calibrators.agents import get_agent  # noqa: E402
from calibrators.study.compare import CHUNK, Config, Trial, run_chunk  # noqa: E402
from calibrators.study.episodes import run_episode, run_episodes  # noqa: E402
from orthoglide_env.world.conditions import IDEAL, Conditions  # noqa: E402

#: Machines per chunk of the per-machine path: one, every stage a batch of one.
PER_MACHINE_CHUNK: int = 1


def timed(config: Config, machines: int, batched: bool) -> tuple[float, list[Trial]]:
    """Seconds and trials of ``run_chunk`` over ``machines`` machines in chunks."""
    size = CHUNK if batched else PER_MACHINE_CHUNK
    start = time.perf_counter()
    trials = []
    for first in range(0, machines, size):
        trials += run_chunk(config, list(range(first, min(first + size, machines))), set(),
                            batched=batched)
    return time.perf_counter() - start, trials


def largest_gap(a: list[Trial], b: list[Trial]) -> float:
    """Largest difference (mm) between two runs' parameters, scores and predicted errors."""
    gap = 0.0
    for x, y in zip(a, b, strict=False):
        assert x.key == y.key and x.failed == y.failed
        pairs = [(x.error, y.error), ([x.predicted_rigid_mm], [y.predicted_rigid_mm]),
                 (list(x.tcp_after.values()), list(y.tcp_after.values())),
                 (list(x.tcp_before.values()), list(y.tcp_before.values()))]
        for u, v in pairs:
            if u:
                gap = max(gap, float(np.nanmax(np.abs(np.subtract(u, v)), initial=0.0)))
    return gap


def episodes_only(machines: int, per_machine: int) -> tuple[float, float]:
    """Seconds per machine of the paper agent's episodes: in the lab vector env (chunks of
    compare's size) and one lone lab at a time."""
    seeds = list(range(machines))
    start = time.perf_counter()
    for first in range(0, machines, CHUNK):
        chunk = seeds[first:first + CHUNK]
        envs = gym.make_vec(orthoglide_env.LAB_ENV_ID, num_envs=len(chunk), gauge_sigma=0.01,
                             conditions="ideal")
        run_episodes(envs, [get_agent("paper") for _ in chunk], chunk)
        envs.close()
    batched = (time.perf_counter() - start) / machines
    env = gym.make(orthoglide_env.LAB_ENV_ID, gauge_sigma=0.01, conditions="ideal")
    start = time.perf_counter()
    for seed in seeds[:per_machine]:
        run_episode(env, get_agent("paper"), seed)
    return batched, (time.perf_counter() - start) / per_machine


MEMORY_RUN = """
import resource, sys, time
from calibrators.study.compare import Config, run
start = time.perf_counter()
trials = run(Config(("paper",), ("paper",), conditions=IDEAL), int(sys.argv[1]))
print(len(trials), time.perf_counter() - start,
      resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""


def world_costs(args: argparse.Namespace) -> None:
    """The batched path's time per machine under ``args.conditions`` against ``ideal``."""
    print(f"{'estimator':12}{'ideal ms/machine':>20}{args.conditions + ' ms/machine':>24}"
          f"{'ratio':>8}")
    for name in args.estimators.split(","):
        ideal = Config(("paper",), (name,), conditions=IDEAL)
        world = replace(ideal, conditions=Conditions(args.conditions))
        for config in (ideal, world):
            run_chunk(config, [args.machines + 1], set(), batched=True)
        best = {"ideal": float("inf"), "world": float("inf")}
        for _ in range(args.repeat):
            best["ideal"] = min(best["ideal"], timed(ideal, args.machines, True)[0])
            best["world"] = min(best["world"], timed(world, args.machines, True)[0])
        ms = {key: 1e3 * value / args.machines for key, value in best.items()}
        print(f"{name:12}{ms['ideal']:20.1f}{ms['world']:24.1f}"
              f"{ms['world'] / ms['ideal']:8.2f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=1000)
    parser.add_argument("--per-machine", type=int, default=100,
                        help="machines the per-machine path runs (the first ones)")
    parser.add_argument("--estimators", default="paper,paper6,extended")
    parser.add_argument("--memory-machines", type=int, default=10000)
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs of each path; the fastest counts")
    parser.add_argument("--conditions", default="lab",
                        help="the world the batched path is timed in against ideal "
                             "('' to skip)")
    args = parser.parse_args()
    load = os.getloadavg()[0]
    print(f"paper agent, {args.machines} realistic machines (per-machine path: the first "
          f"{args.per_machine}), exact backend, one process; load average {load:.2f} on "
          f"{os.cpu_count()} cpus")
    print(f"{'estimator':12}{'batched ms/machine':>20}{'per-machine ms/machine':>24}"
          f"{'ratio':>8}{'largest gap mm':>16}")
    for name in args.estimators.split(","):
        config = Config(("paper",), (name,), conditions=IDEAL)
        # Warm up both paths (imports, cached tables) on machines outside the timed ones.
        for batched in (True, False):
            run_chunk(config, [args.machines + 1], set(), batched=batched)
        # The fastest of --repeat runs of each path, taken in turns: on a shared machine
        # the slower runs measure the neighbours.
        fast = slow = float("inf")
        for _ in range(args.repeat):
            seconds, batched = timed(config, args.machines, True)
            fast = min(fast, seconds)
            seconds, alone = timed(config, args.per_machine, False)
            slow = min(slow, seconds)
        fast_ms, slow_ms = 1e3 * fast / args.machines, 1e3 * slow / args.per_machine
        print(f"{name:12}{fast_ms:20.1f}{slow_ms:24.1f}{slow_ms / fast_ms:8.1f}"
              f"{largest_gap(batched, alone):16.2e}", flush=True)
    batched_s, alone_s = episodes_only(args.machines, args.per_machine)
    print(f"{'episodes':12}{1e3 * batched_s:20.1f}{1e3 * alone_s:24.1f}"
          f"{alone_s / batched_s:8.1f}", flush=True)
    if args.conditions:
        world_costs(args)
    if args.memory_machines:
        out = subprocess.run([sys.executable, "-c", MEMORY_RUN, str(args.memory_machines)],
                             capture_output=True, text=True, check=True).stdout.split()
        print(f"{args.memory_machines} machines (paper agent, paper estimator, batched, one "
              f"process): {out[0]} trials in {float(out[1]):.0f} s, peak RSS "
              f"{float(out[2]):.0f} MB")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
