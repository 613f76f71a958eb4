"""Where a designed plan stands against the bound: each plan ``optimal`` weighs, on the
planner's criterion and on the bound's own model, over the bound.

    python benchmarks/plan_gap.py [--conditions lab] [--budget 3600]
                                  [--instruments dial,ballbar] [--sigma 0.02]
                                  [--resolution 0.01] [--warm-bins 6 [--no-warm-bound]]
                                  [--stay] [--laser-at-every-move] [--phased]

``optimal`` (:func:`calibrators.agents.optimal.fixed_plan`) makes the greedy plan and, in
a lab that owns the interferometer or the ballbar, a plan from each rounded design
(:func:`calibrators.planning.rounding.plan_bundles`), and keeps the one whose criterion
predicts least, or in a lab with a warm-up the one least on the model with the timed
terms unknown in six bins (the last column with ``--warm-bins 6``); the last rows are the
bound's own design rounded so (:func:`calibrators.planning.rounding.bound_bundles`),
and the design of the bound with the stands held at the paper's slots rounded so,
which ``optimal`` does not weigh.
Per plan: its predicted TCP error after rigid motion (the planner's
criterion, um), its readings counted on the bound's model
(:func:`calibrators.planning.bound.plan_counts`) and their error there (um), that over
the bound (:func:`calibrators.planning.bound.lower_bound`), its dial, bar and laser
readings, its set-ups (operation at lab minute) and its re-mounts (a plan that never
re-mounts is bounded by the stands held at the paper's slots as well:
``benchmarks/bound_table.py``).  The bound's model knows the world's
terms but the lead error, so a plan whose ratio here is near 1 and whose realised error
(``compare --bound``) is far above it is held by the world, not by its plan.  With
``--warm-bins K`` each plan is also counted on the model whose timed terms (the warm-up,
the stands' drift) are unknown, its readings in K bins of time
(:mod:`calibrators.planning.warm_bound`), over that bound (with ``--no-warm-bound``, the
value alone: ``optimal`` keeps its plan by it).  With ``--stay`` every plan is made
without re-mounts, as ``optimal-stay`` makes them.  The plans are for a lab whose moves ask
(``OrthoglideLab-v4``: a plan reads the laser on its laser bundles only, and its other
moves pay no dwell); with ``--laser-at-every-move``, every move after a set-up reads the
laser and waits its dwell, as in ``OrthoglideLab-v1`` to ``-v3`` and as ``optimal`` and
``active`` play in every version (their ``laser_at_every_move``).  With ``--phased``,
each plan that re-mounts is followed by the plan on its slots, re-mounts and instrument
runs (the laser's, the bar's) whose dials read as the design of the bound of its phases
does (:func:`calibrators.planning.phased.phased_plan`, which ``optimal`` weighs under a
world's conditions in a lab without the bar), and by ``B`` of the plan's slots and
re-mounts with its laser's drives and its bar's pivot set up as the plan sets them up
(:func:`calibrators.planning.bound.held_design`, no phases: below both plans).  The
prototype, the paper's stands; no lab episodes (a few CPU-minutes at three hours).
"""

from __future__ import annotations

import argparse

import numpy as np
from bound_table import dial_arguments, dial_weighting

from calibrators.planning.bound import BAR, best_design, bound_model, held_design, plan_counts
from calibrators.planning.instruments import step_actions
from calibrators.planning.phased import phased_plan, plan_phases
from calibrators.planning.rounding import bound_bundles, plan_bundles, relaxed_plan
from calibrators.planning.search import Planner, greedy_plan
from calibrators.planning.warm_bound import steps_value, warm_design, warm_models
from orthoglide_env.lab.operations import PAPER_SLOTS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import CONDITION_NAMES, Conditions

UM = 1e3  # per mm


def lab_arguments(parser: argparse.ArgumentParser) -> None:
    """The bound's lab on the command line: its conditions, budget, instruments and the
    bins of time of the bound with the timed terms unknown."""
    parser.add_argument("--conditions", default="lab", choices=CONDITION_NAMES)
    parser.add_argument("--budget", type=float, default=3600.0, help="lab seconds")
    parser.add_argument("--instruments", default="dial,ballbar",
                        help="what the lab owns, comma-separated (dial, interferometer, "
                             "ballbar)")
    parser.add_argument("--warm-bins", type=int, default=0,
                        help="bins of time of the bound with the warm-up unknown (0: none)")


def lab_options(parser: argparse.ArgumentParser,
                args: argparse.Namespace) -> tuple[tuple[str, ...], Conditions]:
    """The instruments owned and the conditions of :func:`lab_arguments`' options, or the
    parser's one-line error for a bad one."""
    owned = tuple(args.instruments.split(","))
    unknown = sorted(set(owned) - {"dial", "interferometer", "ballbar"})
    if unknown or "dial" not in owned:
        parser.error(f"--instruments must name dial and any of interferometer, "
                     f"ballbar, got {args.instruments!r}")
    if not (np.isfinite(args.budget) and args.budget > 0):
        parser.error(f"--budget must be a positive number of seconds, got {args.budget}")
    conditions = Conditions(args.conditions)
    if args.warm_bins < 0 or (args.warm_bins and "warmup" not in conditions):
        parser.error(f"--warm-bins must be 0 or, with a warm-up, positive, got {args.warm_bins}")
    return owned, conditions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    lab_arguments(parser)
    dial_arguments(parser)
    parser.add_argument("--stay", action="store_true",
                        help="plans that never re-mount a stand (optimal-stay's)")
    parser.add_argument("--laser-at-every-move", action="store_true",
                        help="plans for a lab whose every move reads the laser set up "
                             "(OrthoglideLab-v1 to -v3)")
    parser.add_argument("--no-warm-bound", action="store_true",
                        help="with --warm-bins, the plans on that model without its bound "
                             "(CPU-minutes with the laser at three hours)")
    parser.add_argument("--phased", action="store_true",
                        help="each plan that re-mounts also read as the design of the bound "
                             "of its own phases, its instruments' runs kept (phased_plan), "
                             "and that bound without the phases (B of its slots)")
    args = parser.parse_args()
    if args.no_warm_bound and not args.warm_bins:
        parser.error("--no-warm-bound prices the plans on the model of --warm-bins K: give both")
    owned, conditions = lab_options(parser, args)
    sigma = dial_weighting(args)
    slots, engaged = tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS)
    found = best_design(PROTOTYPE, conditions, sigma, args.budget, owned).bound
    model = bound_model(PROTOTYPE, conditions, sigma, "interferometer" in owned,
                        *(("ballbar" in owned,) if "ballbar" in owned else ()))
    instruments = tuple(n for n in owned if n != "dial")
    asked = not args.laser_at_every_move

    def opened() -> Planner:
        planner = Planner(list(slots), list(engaged), sigma, args.budget, design=PROTOTYPE,
                          conditions=conditions, instruments=instruments,
                          laser_asked=asked)
        planner.expect_readings()
        return planner

    def own_bound(steps: tuple) -> float:
        """``B`` of the slots and re-mounts of a plan of ``steps`` with its laser's drives
        and its bar's pivot set up (mm): a bound of the plans that re-mount so with those
        set-ups."""
        remounts = plan_phases(slots, steps)[1]
        drives = tuple(sorted({s.axis for s in steps if s.op == Op.ALIGN}))
        pivot = any(s.op == Op.PIVOT for s in steps)
        return held_design(PROTOTYPE, conditions, sigma, args.budget, owned,
                           tuple(slot for _, slot in remounts), len(remounts),
                           setups=((drives, pivot),)).bound.bound_mm

    print(f"bound {UM * found.bound_mm:.3f} um (design {UM * found.design_mm:.3f} um)")
    warm, held = None, None
    if args.warm_bins and args.no_warm_bound:
        warm = warm_models(PROTOTYPE, conditions, sigma, args.budget, owned,
                           bins=args.warm_bins)
    elif args.warm_bins:
        held, warm = warm_design(PROTOTYPE, conditions, sigma, args.budget, owned,
                                 bins=args.warm_bins)
        print(f"with the timed terms unknown, {args.warm_bins} bins: bound "
              f"{UM * held.bound.bound_mm:.3f} um (design {UM * held.bound.design_mm:.3f} um)")
    print("| plan | predicted µm | on the bound's model µm | x bound | dial, bar, laser "
          "readings | set-ups (min), re-mounts |" + (" timed terms unknown µm, x its bound |"
                                                    if warm else ""))
    print("|---|---|---|---|---|---|" + ("---|" if warm else ""))
    groups = plan_bundles(slots, sigma, args.budget, PROTOTYPE, conditions, instruments,
                          asked)
    rounded = [(f"the bound's design{stands}: " + " + ".join(b.label for b in bundles), bundles)
               for stands, bundles in (
                   ("", bound_bundles(PROTOTYPE, conditions, sigma, args.budget, owned)),
                   (" with the stands held", bound_bundles(PROTOTYPE, conditions, sigma,
                                                           args.budget, owned, False)))
               if bundles]

    def row(name: str, steps: tuple, predicted_mm: float) -> None:
        counts = plan_counts(model, PROTOTYPE, slots, engaged, step_actions(steps))
        on_model = float(np.sqrt(model.value(counts)))
        setups = ", ".join([f"{Op(s.op).name.lower()} {s.time_s / 60:.0f}" for s in steps
                            if s.op in (Op.ALIGN, Op.PIVOT)]
                           + [f"{sum(s.op == Op.REMOUNT for s in steps)} re-mounts"])
        extra = ""
        if warm is not None:
            on_warm = float(np.sqrt(steps_value(warm, PROTOTYPE, slots, engaged, tuple(steps))))
            extra = f" {UM * on_warm:.3f}, " + (f"{on_warm / held.bound.bound_mm:.2f} |"
                                                if held else "- |")
        print(f"| {name} | {UM * predicted_mm:.3f} | {UM * on_model:.3f} | "
              f"{on_model / found.bound_mm:.2f} | {counts[model.laser == -1].sum():.0f}, "
              f"{counts[model.laser == BAR].sum():.0f}, {counts[model.laser >= 0].sum():.0f}"
              f" | {setups} |{extra}", flush=True)

    weighed = [("greedy", None)] + [(" + ".join(b.label for b in group), group)
                                    for group in groups]
    for k, (name, bundles) in enumerate(weighed + rounded):
        planner = opened()
        steps = tuple(greedy_plan(planner, remounts=not args.stay) if bundles is None
                      else relaxed_plan(planner, bundles, not args.stay))
        row(name, steps, planner.predicted_rigid_mm())
        # optimal's own candidates only: it phases no rounded bound's design.
        phased = (phased_plan(opened(), steps) if args.phased and k < len(weighed)
                  and any(s.op == Op.REMOUNT for s in steps) else None)
        if phased is not None:
            row(f"{name}, phased (B of its slots, re-mounts and set-ups "
                f"{UM * own_bound(steps):.3f})", *phased)


if __name__ == "__main__":
    main()
