"""What a dial plan pays that the bound of its own slots does not: a ladder on the bound's
model, each part added to the bound's problem one at a time, then together.

    python benchmarks/plan_ladder.py [--conditions lab] [--budget 3600] [--sigma 0.02]
                                     [--resolution 0.01]

For each plan ``optimal`` weighs in a lab of dials alone (the greedy plan,
:func:`calibrators.planning.search.greedy_plan`, and the plan on its slots and re-mounts
that reads as their bound's design does, :func:`calibrators.planning.phased.phased_plan`):
``B(E)`` of its slots (:func:`calibrators.planning.bound.held_design`: any of them on any
visit, at most six a visit, its re-mounts whole), then ``B`` with one part of what the
plan pays added: its stands at six slots at a time in its own order (``phases``), its
driving, its levers, its budget left unspent (each taken off ``B``'s budget), and all of
them together; then the plan on the bound's model (:func:`~calibrators.planning.bound.
plan_counts`), its readings counted at their a-priori contact instead of whole, and the
plan and ``B`` on the model without the lead error (the planner's criterion has none in a
lab of dials: a constant of every dial plan, which compresses the ratios).  Certified
bounds (µm), over the relaxation (:func:`~calibrators.planning.bound.best_design`) and
over ``B(E)``.  The prototype, the paper's stands; no lab episodes (seconds per plan).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bound_table import dial_arguments, dial_weighting

from calibrators.planning.bound import (
    at_contact_model,
    best_design,
    held_design,
    lab_model,
    plan_counts,
)
from calibrators.planning.instruments import step_actions
from calibrators.planning.phased import overhead_s, phased_plan, plan_phases
from calibrators.planning.search import Planner, greedy_plan
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import EFFECT_NAMES, Conditions

UM = 1e3  # per mm


def ladder(steps: tuple, conditions: Conditions, sigma: float, budget_s: float
           ) -> list[tuple[str, float]]:
    """The rungs (name, mm) of the plan of ``steps`` from the paper's stands."""
    slots, engaged = tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS)
    phases, remounts = plan_phases(slots, steps)
    added = tuple(sorted({s for phase in phases for s in phase} - set(slots)))
    levers = TIME.lift_s * sum(s.op in (Op.LIFT, Op.ENGAGE) for s in steps)
    driving = overhead_s(steps) - levers
    unspent = budget_s - steps[-1].time_s

    def bound(less_s: float = 0.0, phased: bool = False) -> float:
        return held_design(PROTOTYPE, conditions, sigma, budget_s - less_s, ("dial",), added,
                           len(remounts), phases=phases if phased else ()).bound.bound_mm

    model = lab_model(PROTOTYPE, conditions, sigma, budget_s, ("dial",), len(slots))
    actions = step_actions(steps)
    counts = plan_counts(model, PROTOTYPE, slots, engaged, actions)
    leadless = Conditions(conditions.name, tuple(e for e in EFFECT_NAMES if e != "lead"))
    plain = lab_model(PROTOTYPE, leadless, sigma, budget_s, ("dial",), len(slots))
    return [
        (f"B(E), its {len(added)} slots, {len(remounts)} re-mounts", bound()),
        ("+ six stands at a time, in its order", bound(phased=True)),
        (f"+ its driving ({driving:.0f} s)", bound(driving)),
        (f"+ its levers ({levers:.0f} s)", bound(levers)),
        (f"+ its budget left ({unspent:.0f} s)", bound(unspent)),
        ("+ all four", bound(driving + levers + unspent, phased=True)),
        ("the plan on the bound's model", float(np.sqrt(model.value(counts)))),
        ("the plan, its readings counted at a-priori contact", float(np.sqrt(
            at_contact_model(model, PROTOTYPE).value(counts)))),
        ("without the lead error: B(E)", held_design(
            PROTOTYPE, leadless, sigma, budget_s, ("dial",), added,
            len(remounts)).bound.bound_mm),
        ("without the lead error: the plan", float(np.sqrt(plain.value(plan_counts(
            plain, PROTOTYPE, slots, engaged, actions))))),
    ]


#: The last rungs of :func:`ladder` are on the model without the lead error: over its own
#: ``B(E)``, the first of them, and not over the relaxation.
LEADLESS: int = 2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--conditions", default="lab", choices=("lab", "workshop"))
    parser.add_argument("--budget", type=float, default=3600.0, help="lab seconds")
    dial_arguments(parser)
    args = parser.parse_args()
    if not (np.isfinite(args.budget) and args.budget > 0):
        parser.error(f"--budget must be a positive number of seconds, got {args.budget}")
    conditions = Conditions(args.conditions)
    sigma = dial_weighting(args)
    relaxed = best_design(PROTOTYPE, conditions, sigma, args.budget).bound.bound_mm
    print(f"the relaxation {UM * relaxed:.3f} um ({args.conditions}, {args.budget:.0f} s, "
          f"dials alone)")

    def opened() -> Planner:
        planner = Planner(list(PAPER_SLOTS), [True] * len(PAPER_SLOTS), sigma, args.budget,
                          design=PROTOTYPE, conditions=conditions)
        planner.expect_readings()
        return planner

    start = time.process_time()
    planner = opened()
    greedy = tuple(greedy_plan(planner))
    plans = [("greedy", greedy, planner.predicted_rigid_mm(), time.process_time() - start)]
    start = time.process_time()
    phased = phased_plan(opened(), greedy)
    if phased is not None:
        plans.append(("phased", *phased, time.process_time() - start))
    for name, steps, predicted, cpu in plans:
        rungs = ladder(steps, conditions, sigma, args.budget)
        with_lead = len(rungs) - LEADLESS
        print(f"\n{name} plan: predicted {UM * predicted:.3f} um (the planner's criterion), "
              f"{cpu:.1f} CPU s to make\n")
        print("| rung | µm | over the relaxation | over B(E) |")
        print("|---|---|---|---|")
        for i, (what, value) in enumerate(rungs):
            over = f"{value / relaxed:.2f}x" if i < with_lead else "-"
            own = rungs[0 if i < with_lead else with_lead][1]
            print(f"| {what} | {UM * value:.3f} | {over} | {value / own:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
