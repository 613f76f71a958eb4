"""How the ``optimal`` agent's plan changes with the lab's world.

    python benchmarks/world_plans.py [--budget 330] [--conditions lab] [--sigma 0.02]

The fixed plan from the lab's opening set-up (the paper's six stands, plungers down) under
``ideal`` and under ``--conditions``, each replayed on the nominal machine: its length
(the plan may stop before the budget), its moves, its revisits to Zero (re-mounts, which
drive there too, counted apart), how it approaches the postures it reads more than once
(always from the same side on every axis, or from both),
the moves that reverse an axis, and each mounting's plunger range (the span of its
nominal readings where the nominal tip is within its travel, mm; median over mountings)
and reach (its largest reading).  Then the TCP error after rigid motion each plan
predicts for itself, and what a planner under ``--conditions`` predicts for it (the
``ideal`` plan replayed with the world's terms): what knowing the world buys, by the
planner's own model.  The lead error and the screw's periodic error are not in that
model: base-fixed gauges see next to nothing of the ``full`` estimator's pitch table
(``benchmarks/terms.py``: the one-hour ``optimal`` plan removes none of its variance),
so the planner leaves it out.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calibrators.agents.optimal import fixed_plan
from calibrators.planning.search import Planner
from calibrators.planning.world_terms import directions
from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
from orthoglide_env.lab.slot_table import slot_table
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions


def plan_figures(steps: tuple, budget: float) -> dict[str, float]:
    """The figures of one plan (see the module's docstring)."""
    table = slot_table(PROTOTYPE)
    index = {tuple(p): i for i, p in enumerate(table.postures)}
    slots, engaged = list(PAPER_SLOTS), [True] * len(PAPER_SLOTS)
    readings: dict[tuple[int, int], list[float]] = {}
    mounting = list(range(len(slots)))
    rho, approach = np.zeros(3), np.ones(3)
    seen: dict[tuple[float, ...], set[tuple[float, ...]]] = {}
    figures = dict(length_s=0.0, moves=0, zero_revisits=0, remounts=0, reversals=0)
    for step in steps:
        if step.op == Op.STOP:
            figures["length_s"] = step.time_s
        elif step.op in (Op.LIFT, Op.ENGAGE):
            engaged[step.stand] = step.op == Op.ENGAGE
        elif step.op in (Op.MOVE, Op.REMOUNT):
            target = np.zeros(3) if step.op == Op.REMOUNT else np.array(step.rho)
            new = directions(rho, target, approach)
            figures["reversals"] += int(np.any(new != approach))
            rho, approach = target, new
            if step.op == Op.REMOUNT:
                figures["remounts"] += 1
                slots[step.stand], engaged[step.stand] = step.slot, True
                mounting[step.stand] = max(mounting) + 1
            else:
                figures["moves"] += 1
                figures["zero_revisits"] += int(not np.any(target))
            seen.setdefault(tuple(target), set()).add(tuple(approach))
            here = index[tuple(target)]
            for k, down in enumerate(engaged):
                y = table.reading[slots[k], here]
                tip = table.tip[slots[k], here]
                if down and 0.0 <= tip <= table.travel:  # NaN: it misses its bar
                    readings.setdefault((k, mounting[k]), []).append(float(y))
    figures["postures"] = len(seen)
    figures["both_sides"] = sum(len(sides) > 1 for sides in seen.values())
    figures["span_mm"] = float(np.median([np.ptp(v) for v in readings.values()]))
    figures["reach_mm"] = float(np.median([np.max(np.abs(v)) for v in readings.values()]))
    figures["budget_s"] = budget
    return figures


def replayed_mm(steps: tuple, sigma: float, budget: float, conditions: Conditions
                ) -> float:
    """The TCP error after rigid motion that a planner under ``conditions`` predicts for
    ``steps`` (a plan made under any conditions), replayed with its readings expected."""
    planner = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), sigma, budget,
                      conditions=conditions, design=PROTOTYPE)
    planner.expect_readings()
    index = {tuple(p): i for i, p in enumerate(planner.table.postures)}
    for step in steps:
        if step.op == Op.MOVE:
            planner.move(index[tuple(step.rho)], planner.priced_moves())
            planner.expect_readings()
        elif step.op == Op.REMOUNT:
            planner.remount(step.stand, step.slot)
            planner.expect_readings()
    return planner.predicted_rigid_mm()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--budget", type=float, default=330.0)
    parser.add_argument("--conditions", default="lab", choices=("lab", "workshop"))
    parser.add_argument("--sigma", type=float, default=0.02,
                        help="gauge repeatability (mm), read to 0.01 mm")
    args = parser.parse_args()
    sigma = weighting_sigma(float(np.hypot(args.sigma, 0.01 / np.sqrt(12))))
    print(f"| plan made under | predicted TCP after rigid, um | under {args.conditions}, um "
          "| length, s | moves | Zero revisits "
          "| re-mounts | postures | read from both sides | axis reversals | plunger span, mm "
          "| plunger reach, mm | planning, s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for conditions in (Conditions("ideal"), Conditions(args.conditions)):
        start = time.perf_counter()
        steps, predicted = fixed_plan(tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS), sigma,
                                      args.budget, PROTOTYPE, conditions)
        spent = time.perf_counter() - start
        f = plan_figures(steps, args.budget)
        there = replayed_mm(steps, sigma, args.budget, Conditions(args.conditions))
        print(f"| {conditions.label} | {predicted * 1e3:.1f} | {there * 1e3:.1f} | "
              f"{f['length_s']:.0f} | "
              f"{f['moves']:.0f} | {f['zero_revisits']:.0f} | {f['remounts']:.0f} | "
              f"{f['postures']:.0f} | {f['both_sides']:.0f} | {f['reversals']:.0f} | "
              f"{f['span_mm']:.2f} | {f['reach_mm']:.2f} | {spent:.0f} |")


if __name__ == "__main__":
    main()
