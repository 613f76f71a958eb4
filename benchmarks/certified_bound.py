"""Whether any plan of a lab, re-mounts counted whole, can come within a ratio of the bound:
a certified search over the slot sets the stands stand at.

    python benchmarks/certified_bound.py [--world lab:3600:dial+interferometer]
                                         [--ratio 1.25] [--most 20] [--cpu 120]
                                         [--share 4] [--setups LIST] [--remounts LIST]
                                         [--sigma 0.02] [--resolution 0.01]

The target is ``--ratio`` times the relaxation (:func:`calibrators.planning.bound.
best_design`, a re-mount priced as a share per reading).  Per choice of set-ups (the
laser's drives, the pivot), on the bound's model (:mod:`calibrators.planning.
slot_search`):

* ``R``: the fewest re-mounts from which on every plan is above the target: the bound
  with every slot free and the budget less ``R`` whole re-mounts passes it (tried up to
  ``--most``);
* for each ``r`` below ``R``: a branch and bound over the sets of at most ``r`` slots
  beyond the paper's, each node's convex problem stopped once it is decided against the
  target; certified (every plan that re-mounts ``r`` times is above the target), a set
  whose ``B`` is below it (room), or stopped after ``--cpu`` CPU seconds with the nodes
  left open.

Where the model is the same with the axes renamed (checked at random designs), the drives'
set-ups are searched one per rename (the laser on x answers for y and z).  Lines starting
``#`` are progress (CPU seconds of this process); the table follows, and the verdict.  The
prototype, the paper's stands; no lab episodes.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bound_table import dial_arguments, dial_weighting, parse_world

from calibrators.planning.bound import best_design, lab_model, problems
from calibrators.planning.slot_search import Search, axis_cycle, symmetric
from orthoglide_env.lab.operations import PAPER_SLOTS, SLOT_NAMES
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

UM = 1e3  # per mm


def _cpu() -> str:
    return f"{time.process_time():.0f} CPU s"


def _setup_name(setup: tuple[tuple[int, ...], bool]) -> str:
    drives, pivot = setup
    parts = ([f"laser on {''.join('xyz'[d] for d in drives)}"] if drives else []) + (
        ["pivot"] if pivot else [])
    return ", ".join(parts) or "dials alone"


def _renamed(setup: tuple[tuple[int, ...], bool]) -> list[tuple[tuple[int, ...], bool]]:
    """The set-up and its images as the axes are renamed in turn."""
    drives, pivot = setup
    return sorted({(tuple(sorted((d + k) % 3 for d in drives)), pivot) for k in range(3)})


def _integers(text: str, what: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v]
    except ValueError:
        raise ValueError(f"{what} must be integers joined by ',', got {text!r}") from None
    if any(v < 0 for v in values):
        raise ValueError(f"{what} must be at least 0, got {text!r}")
    return values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="lab:3600:dial+interferometer",
                        help="conditions:budget_s:instruments (instruments joined by +)")
    parser.add_argument("--ratio", type=float, default=1.25,
                        help="the target: this many times the relaxation")
    parser.add_argument("--most", type=int, default=20,
                        help="the most re-mounts tried for R, each set-up")
    parser.add_argument("--cpu", type=float, default=120.0,
                        help="CPU seconds of each search (one set-up, one r)")
    parser.add_argument("--share", type=float, default=4.0,
                        help="the second bound's price of a free slot's reading, in "
                             "re-mounts over the visits a slot can be read on")
    parser.add_argument("--setups", default="",
                        help="only these set-ups: the laser's drives as digits 0-2 (none: "
                             "-), a p for the pivot, joined by ',' (e.g. -,0,01,012p)")
    parser.add_argument("--remounts", default="",
                        help="only these r (joined by ','); R is still found")
    dial_arguments(parser)
    args = parser.parse_args()
    try:
        name, budget, owned = parse_world(args.world)
        only_r = set(_integers(args.remounts, "--remounts"))
    except ValueError as error:
        parser.error(str(error))
    if not (np.isfinite(args.ratio) and args.ratio > 0):
        parser.error(f"--ratio must be a positive number, got {args.ratio}")
    if not (np.isfinite(args.cpu) and args.cpu > 0):
        parser.error(f"--cpu must be a positive number of seconds, got {args.cpu}")
    if args.most < 0:
        parser.error(f"--most must be at least 0, got {args.most}")
    if not (np.isfinite(args.share) and args.share >= 0):
        parser.error(f"--share must be a number at least 0, got {args.share}")
    stands = len(PAPER_SLOTS)
    setups = [(drives, pivot) for drives, pivot, _ in problems(PROTOTYPE, budget, owned, stands)]
    if args.setups:
        texts = args.setups.split(",")
        wanted = [(tuple(int(c) for c in t if c.isdigit()), "p" in t) for t in texts]
        if any(not t or set(t) - set("-012p") for t in texts) or set(wanted) - set(setups):
            parser.error(f"--setups names set-ups the lab has not: {args.setups!r} "
                         f"(the lab's: {', '.join(_setup_name(s) for s in setups)})")
        setups = [s for s in setups if s in wanted]
    conditions = Conditions(name)
    sigma = dial_weighting(args)
    relaxed = best_design(PROTOTYPE, conditions, sigma, budget, owned)
    target = (args.ratio * relaxed.bound.bound_mm) ** 2
    print(f"# the relaxation {UM * relaxed.bound.bound_mm:.3f} um (design "
          f"{UM * relaxed.bound.design_mm:.3f}); the target {args.ratio:g}x: "
          f"{UM * np.sqrt(target):.3f} um, {_cpu()}", flush=True)
    model = lab_model(PROTOTYPE, conditions, sigma, budget, owned, stands)
    image = axis_cycle(model, PROTOTYPE, stands)
    renamed = image is not None and symmetric(model, image)
    print(f"# the model is {'' if renamed else 'not '}the same with the axes renamed, "
          f"{_cpu()}", flush=True)
    if renamed:
        setups = sorted({_renamed(s)[0] for s in setups}, key=setups.index)
    rows = []
    verdicts = []
    for setup in setups:
        def say(line: str, setup=setup) -> None:
            print(f"# {_setup_name(setup)}: {line}, {_cpu()}", flush=True)

        search = Search(model, PROTOTYPE, budget, owned, setup, target, stands,
                        args.share, say)
        least, tried = search.least_remounts(args.most)
        last = tried[-1][1]
        orbit = " = ".join(_setup_name(s) for s in (_renamed(setup) if renamed else [setup]))
        rows.append((orbit, f"r >= {least}" if least is not None else
                     f"r >= {args.most}: not above", last.lower, "every slot free",
                     search.solves))
        verdicts.append(least is not None)
        for r in range(least if least is not None else args.most + 1):
            if only_r and r not in only_r:
                verdicts.append(False)
                continue
            start, solves = time.process_time(), search.solves
            found = search.certify(r, args.cpu)
            spent = time.process_time() - start
            if found.below is not None:
                slots, solved = found.below
                what = (f"room: B of {', '.join(SLOT_NAMES[s] for s in slots) or 'none'} "
                        f"{UM * np.sqrt(solved.value):.3f} um")
            elif found.certified:
                what = "certified above"
            else:
                what = (f"stopped: {len(found.open)} nodes open, "
                        f"{len(found.undecided)} sets within the solver's gap")
            for held, allowed in found.open:
                print(f"# {_setup_name(setup)}, r = {r}: open: "
                      f"{', '.join(SLOT_NAMES[s] for s in held) or 'none'} held, "
                      f"{len(allowed)} slots allowed", flush=True)
            rows.append((orbit, f"r = {r}", found.least, f"{what}; {spent:.0f} CPU s",
                         search.solves - solves))
            verdicts.append(found.certified)
            print(f"# {_setup_name(setup)}, r = {r}: {what}, least closed "
                  f"{UM * np.sqrt(found.least):.3f} um, {spent:.0f} CPU s", flush=True)
    print(f"\n{args.world}: the relaxation {UM * relaxed.bound.bound_mm:.3f} um, the target "
          f"{args.ratio:g}x = {UM * np.sqrt(target):.3f} um\n")
    print("| set-ups | re-mounts | least certified µm | over the relaxation | what | "
          "problems solved |")
    print("|---|---|---|---|---|---|")
    for orbit, which, value, what, solves in rows:
        print(f"| {orbit} | {which} | {UM * np.sqrt(value):.3f} "
              f"| {np.sqrt(value) / relaxed.bound.bound_mm:.2f}x | {what} | {solves} |")
    if all(verdicts):
        print(f"\nEvery plan of the lab is above {args.ratio:g}x the relaxation: certified.")
    else:
        print(f"\nNot certified: some re-mounts of some set-ups are not above {args.ratio:g}x "
              "the relaxation (above).")


if __name__ == "__main__":
    main()
