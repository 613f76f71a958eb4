"""The ``active`` agent's sweep cost: machines, one hour each, wall time on ``--jobs``
workers, against the target of 100 machines within 2 minutes on 2 cores.

    python benchmarks/bench_active.py [--machines 100] [--jobs 2] [--conditions lab]
                                      [--budget 3600]

(``--budget``: the lab seconds of each machine; a shorter one makes a smaller case to
count instructions on, whose start-up plan has fewer re-mount checks.)

Runs ``compare``'s own path (``calibrators.study.compare.run``: the batched lab, the batched
fits) for ``active`` with the ``extended`` estimator and reports the wall time (each
worker's one-off planning start-up included, as a sweep pays it), the seconds per
machine and the ratio to the target; then the sha256 of every trial's JSON line (its
readings, hence its plan, its time and its errors), which another revision's run must
print too for its plans to be the same, and the sweep's CPU seconds.
"""

from __future__ import annotations

import argparse
import hashlib
import resource
import time

from calibrators.study.compare import Config, run
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S
from orthoglide_env.world.conditions import Conditions

#: The target: machines and wall seconds (issue: 100 machines within 2 minutes, 2 cores).
TARGET_MACHINES, TARGET_S = 100, 120.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=TARGET_MACHINES)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--conditions", default="lab")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S, metavar="S")
    args = parser.parse_args()
    if args.machines < 1 or args.jobs < 1 or not args.budget > 0:
        parser.error("--machines and --jobs must be at least 1, --budget a positive number "
                     "of seconds")
    config = Config(("active",), ("extended",), seed=args.seed,
                    conditions=Conditions(args.conditions), budget_s=args.budget)
    start, cpu = time.perf_counter(), _cpu_seconds()
    trials = run(config, args.machines, jobs=args.jobs)
    wall, cpu = time.perf_counter() - start, _cpu_seconds() - cpu
    hours = sum(t.time_s for t in trials) / 3600
    failed = sum(bool(t.failed) for t in trials)
    target = TARGET_S * args.machines / TARGET_MACHINES
    print(f"active x extended, {args.conditions}, {args.machines} machines ({hours:.1f} "
          f"machine-hours, {failed} failed) on {args.jobs} workers: {wall:.1f} s wall, "
          f"{wall / args.machines:.2f} s per machine; the target's pace would be "
          f"{target:.0f} s ({wall / target:.1f}x that)")
    digest = hashlib.sha256("\n".join(t.to_json() for t in trials).encode()).hexdigest()
    print(f"trials (plans, readings, errors): sha256 {digest}; {cpu:.1f} CPU seconds (the "
          "workers' included): on a loaded machine, what compares")


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its finished workers."""
    own, workers = (resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                          resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + workers.ru_utime + workers.ru_stime


if __name__ == "__main__":
    main()
