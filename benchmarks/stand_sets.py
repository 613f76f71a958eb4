"""What whole re-mounts leave of the bound's stand freedom: the bound of the plans that
re-mount at most ``r`` times, per world.

    python benchmarks/stand_sets.py [--world lab:3600:dial] [--exhaustive 2] [--greedy 8]
                                    [--setups all] [--sigma 0.02] [--resolution 0.01]

The bound (:func:`calibrators.planning.bound.best_design`) lets the stands read any slot
at a share of a re-mount per reading.  ``B(E)``
(:func:`calibrators.planning.bound.held_design`) holds them at the paper's slots and the
set ``E`` beyond them, and takes ``|E|`` whole re-mounts off the budget; every plan that
re-mounts ``r`` times reads within some ``E`` of at most ``r`` slots, so the least ``B``
over them bounds those plans.  Per world: the relaxation; ``B`` of every ``E`` of up to
``--exhaustive`` slots (certified: the bound of the plans that re-mount at most that
often); a greedy search up to ``--greedy`` slots (add the slot that lowers ``B`` most,
then one pass of swaps; the best ``E`` found per ``r`` is an upper estimate of the bound
of the plans that re-mount ``r`` times, not a bound); and ``B`` of the slots and
re-mounts of ``optimal``'s kept plan (:func:`calibrators.agents.optimal.fixed_plan`)
beside that plan's value on the bound's model (:func:`~calibrators.planning.bound.
plan_counts`).  With ``--setups relaxation`` every ``B`` is solved at the relaxation's
design's set-ups alone (then not a bound: a plan may set up otherwise).  Lines starting
``#`` are progress (CPU seconds of this process); the table follows.  The prototype, the
paper's stands; no lab episodes.
"""

from __future__ import annotations

import argparse
import itertools
import time
from collections.abc import Callable

import numpy as np
from bound_table import dial_arguments, dial_weighting, parse_world

from calibrators.agents.optimal import fixed_plan
from calibrators.planning.bound import (
    Design,
    best_design,
    dial_grid,
    held_design,
    lab_model,
    plan_counts,
    start_slots,
)
from calibrators.planning.instruments import step_actions
from orthoglide_env.lab.operations import PAPER_SLOTS, SLOT_NAMES, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

UM = 1e3  # per mm
Held = Callable[[tuple[int, ...], int, float], Design]


def _cpu() -> str:
    return f"{time.process_time():.0f} CPU s"


def _names(slots: tuple[int, ...]) -> str:
    return ", ".join(SLOT_NAMES[s] for s in slots) or "none"


def exhaustive(held: Held, candidates: tuple[int, ...], most: int
               ) -> list[tuple[float, tuple[int, ...], Design]]:
    """Per ``r`` up to ``most``: the certified least ``B`` over every ``E`` of at most ``r``
    of ``candidates`` (mm: the bound of the plans that re-mount at most ``r`` times), and
    the ``E`` of ``r`` slots whose design is least with its :class:`Design`."""
    out: list[tuple[float, tuple[int, ...], Design]] = []
    lowest = np.inf  # mm^2, over every r so far
    for r in range(most + 1):
        best: tuple[tuple[int, ...], Design] | None = None
        sets = list(itertools.combinations(candidates, r))
        for i, slots in enumerate(sets):
            found = held(slots, r, best[1].bound.design_mm ** 2 if best else np.inf)
            lowest = min(lowest, found.bound.bound_mm ** 2)
            if best is None or found.bound.design_mm < best[1].bound.design_mm:
                best = (slots, found)
            if (i + 1) % 50 == 0 or i + 1 == len(sets):
                print(f"# r = {r}: {i + 1} of {len(sets)} sets, least design "
                      f"{UM * best[1].bound.design_mm:.3f} um, certified "
                      f"{UM * np.sqrt(lowest):.3f} um, {_cpu()}", flush=True)
        assert best is not None
        out.append((float(np.sqrt(lowest)), *best))
    return out


def greedy(held: Held, candidates: tuple[int, ...], slots: tuple[int, ...], found: Design,
           most: int) -> list[tuple[tuple[int, ...], Design]]:
    """From ``slots`` (whose ``B`` is ``found``) up to ``most`` slots: per ``r``, the slot
    whose addition lowers ``B`` most, then one pass of swaps (each slot in turn replaced by
    the first other, in the catalogue's order, that lowers ``B``); the set found per ``r``
    and its design."""
    out = []
    for r in range(len(slots) + 1, most + 1):
        best: tuple[tuple[int, ...], Design] | None = None
        for s in sorted(set(candidates) - set(slots)):
            trial = tuple(sorted((*slots, s)))
            got = held(trial, r, best[1].bound.design_mm ** 2 if best else np.inf)
            if best is None or got.bound.design_mm < best[1].bound.design_mm:
                best = (trial, got)
        assert best is not None
        slots, found = best
        for out_slot in list(slots):
            if out_slot not in slots:
                continue
            for s in sorted(set(candidates) - set(slots)):
                trial = tuple(sorted((*(x for x in slots if x != out_slot), s)))
                got = held(trial, r, found.bound.design_mm ** 2)
                if got.bound.design_mm < found.bound.design_mm:
                    slots, found = trial, got
                    break
        print(f"# r = {r}: {_names(slots)}: {UM * found.bound.bound_mm:.3f} um "
              f"(design {UM * found.bound.design_mm:.3f}), {_cpu()}", flush=True)
        out.append((slots, found))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="lab:3600:dial",
                        help="conditions:budget_s:instruments (instruments joined by +)")
    parser.add_argument("--exhaustive", type=int, default=2,
                        help="every set of up to this many slots beyond the paper's")
    parser.add_argument("--greedy", type=int, default=8,
                        help="the greedy search's most slots beyond the paper's")
    parser.add_argument("--setups", choices=("all", "relaxation"), default="all",
                        help="every set-up of the lab, or the relaxation's design's alone")
    parser.add_argument("--sets", default="",
                        help="also B of these sets of slots beyond the paper's, each with a "
                             "re-mount per slot (slot names joined by ',', sets by ';')")
    parser.add_argument("--no-plan", action="store_true", help="without optimal's plan")
    dial_arguments(parser)
    args = parser.parse_args()
    try:
        name, budget, owned = parse_world(args.world)
    except ValueError as error:
        parser.error(str(error))
    if not 0 <= args.exhaustive <= args.greedy:
        parser.error("--exhaustive must be between 0 and --greedy")
    given = [text.split(",") for text in args.sets.split(";") if text]
    if unknown := sorted({n for names in given for n in names} - set(SLOT_NAMES)):
        parser.error(f"--sets names slots not in the catalogue: {', '.join(unknown)} "
                     f"(e.g. {SLOT_NAMES[0]})")
    given = [tuple(sorted(SLOT_NAMES.index(n) for n in names)) for names in given]
    conditions = Conditions(name)
    sigma = dial_weighting(args)
    relaxed = best_design(PROTOTYPE, conditions, sigma, budget, owned)
    print(f"# the relaxation {UM * relaxed.bound.bound_mm:.3f} um (design "
          f"{UM * relaxed.bound.design_mm:.3f}), laser on {relaxed.drives}, pivot "
          f"{relaxed.pivot}, {_cpu()}", flush=True)
    setups = None if args.setups == "all" else ((relaxed.drives, relaxed.pivot),)

    def held(slots: tuple[int, ...], remounts: int, stop_above: float) -> Design:
        return held_design(PROTOTYPE, conditions, sigma, budget, owned, slots, remounts,
                           setups=setups, stop_above=stop_above)

    model = lab_model(PROTOTYPE, conditions, sigma, budget, owned, len(PAPER_SLOTS))
    start = start_slots(PROTOTYPE, len(PAPER_SLOTS))
    readable = np.flatnonzero((dial_grid(model) >= 0).any(axis=0))
    candidates = tuple(int(s) for s in readable if s not in start)
    certified = exhaustive(held, candidates, args.exhaustive)
    held0 = certified[0][2].bound.bound_mm
    searched = greedy(held, candidates, certified[-1][1], certified[-1][2], args.greedy)
    rows = [(f"held, r = 0{' (the relaxation’s set-ups)' if setups else ''}",
             certified[0][0], "")]
    rows += [(f"plans re-mounting at most {r} times, certified", value,
              f"least at {_names(slots)}: design {UM * found.bound.design_mm:.3f}")
             for r, (value, slots, found) in enumerate(certified) if r]
    rows += [(f"r = {len(slots)}, best E found (not certified)", found.bound.bound_mm,
              f"{_names(slots)}: design {UM * found.bound.design_mm:.3f}")
             for slots, found in searched]
    for slots in given:
        found = held(slots, len(slots), np.inf)
        print(f"# given {_names(slots)}: {UM * found.bound.bound_mm:.3f} um, {_cpu()}",
              flush=True)
        rows.append((f"r = {len(slots)}, given E (not certified)", found.bound.bound_mm,
                     f"{_names(slots)}: design {UM * found.bound.design_mm:.3f}, "
                     f"laser on {found.drives}, pivot {found.pivot}"))
    if not args.no_plan:
        steps, predicted = fixed_plan(tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS), sigma,
                                      budget, PROTOTYPE, conditions,
                                      instruments=tuple(n for n in owned if n != "dial"),
                                      warm_judged=True)
        moved = [s.slot for s in steps if s.op == Op.REMOUNT]
        on_model = float(np.sqrt(model.value(plan_counts(
            model, PROTOTYPE, tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS),
            step_actions(steps)))))
        own = held(tuple(moved), len(moved), np.inf)
        print(f"# optimal's plan: {len(moved)} re-mounts to {_names(tuple(sorted(set(moved))))}, "
              f"predicted {UM * predicted:.3f} um, on the bound's model {UM * on_model:.3f} "
              f"um, {_cpu()}", flush=True)
        rows += [(f"B of `optimal`'s own slots, r = {len(moved)}", own.bound.bound_mm,
                  f"{_names(tuple(sorted(set(moved) - set(start))))}: design "
                  f"{UM * own.bound.design_mm:.3f}"),
                 ("`optimal`'s plan on the bound's model", on_model,
                  f"predicted {UM * predicted:.3f}")]
    print(f"\n{args.world}, set-ups: {args.setups}; the relaxation "
          f"{UM * relaxed.bound.bound_mm:.3f} um\n")
    print("| what | µm | over the relaxation | over held r = 0 | slots beyond the paper's, "
          "design µm |")
    print("|---|---|---|---|---|")
    for what, value, note in rows:
        print(f"| {what} | {UM * value:.3f} | {value / relaxed.bound.bound_mm:.2f}x "
              f"| {value / held0:.2f}x | {note} |", flush=True)


if __name__ == "__main__":
    main()
