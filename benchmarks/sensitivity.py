"""What each effect of the world costs each strategy: every effect alone, at its ``lab``
and its ``workshop`` size.

    python benchmarks/sensitivity.py [--machines 20] [--agents paper,optimal,active,tracker]
                                     [--estimator extended] [--jobs 2] [--seed 2]

The same machines (same seed: the geometry is drawn before the world) run under
``ideal`` and then under each effect alone.  Per agent: the median TCP error after the
best-fit rigid motion (um) under ``ideal``, then per effect the median of the paired
increase over ``ideal`` on the same machines, with a 95 % interval of that median (the
order statistics of a binomial, distribution-free), and the fraction of trials whose
chi-square test rejects the model.  Failed trials are counted in the last column and
enter nothing else.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from calibrators.study.compare import Config, Trial, run
from calibrators.study.statistics import median_interval
from orthoglide_env.world.conditions import EFFECT_NAMES, Conditions

UM = 1e3  # per mm


def rigid(trials: list[Trial], agent: str) -> dict[int, float]:
    return {t.machine: t.tcp_after["rigid"] for t in trials if t.agent == agent and not t.failed}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=20)
    parser.add_argument("--agents", default="paper,optimal,active,tracker")
    parser.add_argument("--estimator", default="extended")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=2)
    args = parser.parse_args()
    agents = tuple(args.agents.split(","))

    def trials(conditions: Conditions) -> list[Trial]:
        print(f"  {conditions.label} ...", file=sys.stderr, flush=True)
        return run(Config(agents, (args.estimator,), seed=args.seed, conditions=conditions),
                   args.machines, jobs=args.jobs)

    base = trials(Conditions("ideal"))
    print(f"{args.machines} machines (realistic preset, sigma 0.02 mm, one-hour budget), "
          f"estimator {args.estimator}: TCP error after rigid motion, um")
    print(f"{'':22}" + "".join(f"{a:>30}" for a in agents))
    print(f"{'ideal (median)':22}" + "".join(
        f"{np.median(list(rigid(base, a).values())) * UM:30.1f}" for a in agents))
    for name in ("lab", "workshop"):
        for effect in EFFECT_NAMES:
            world = trials(Conditions(name, (effect,)))
            cells = []
            for agent in agents:
                before, after = rigid(base, agent), rigid(world, agent)
                common = sorted(set(before) & set(after))
                rise = np.array([after[m] - before[m] for m in common]) * UM
                low, high = median_interval(rise)
                mine = [t for t in world if t.agent == agent]
                rejected = np.mean([bool(t.chi2_rejected) for t in mine if not t.failed])
                failed = sum(bool(t.failed) for t in mine)
                cells.append(f"{np.median(rise):+7.1f} [{low:+6.1f},{high:+6.1f}] "
                             f"rej {rejected:4.2f} f{failed}")
            print(f"{name + ' ' + effect:22}" + "".join(f"{c:>30}" for c in cells))


if __name__ == "__main__":
    main()
