"""What the world adds to a held dial plan, family by family: the fit's own error bars and
the realised errors with one effect family switched off at a time.

    python benchmarks/world_ladder.py [--conditions lab] [--budget 3600] [--machines 20]
                                      [--seed 1] [--sigma 0.02] [--plan kept|greedy]
                                      [--families lead,backlash,...]

``optimal`` plays on machines 0 .. ``--machines`` - 1 (``realistic`` errors, exact
backend, dial gauges alone), its planner always told the full ``--conditions`` (as
``world_excess.py --effects``: a planner told the world it plays in would plan other
operations), so every row reads the same operations.  ``--plan greedy`` leaves the phased
plan out of ``optimal``'s candidates (:func:`calibrators.planning.phased.phased_plan`), so
it plays its greedy plan (an experiment, not an agent).  Rows:

* the full world's readings fitted by ``full`` told the full world, told it without each
  family, told the lead error alone and told ``ideal``: the fit's predicted error after
  rigid motion (its covariance over the machine's errors and the drives' terms, no truth
  read) says what carrying each family's unknowns costs the plan's readings; with
  honest error bars (z-RMS near 1) it is the realised error's RMS over machines;
* the world without each family played and fitted told so: what the family costs on the
  machines, per machine over the full world's row (paired, the same machines).

Beside them the plan on the bound's model (:func:`calibrators.planning.bound.plan_counts`)
and with its readings counted at their a-priori contact (``plan_ladder.py``'s last
rungs).  The medians' intervals are distribution-free (95 %).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from world_excess import plan_as_told, z_rms

import calibrators.agents.optimal as optimal
from calibrators.estimators.catalogue import for_study
from calibrators.planning.bound import at_contact_model, lab_model, plan_counts
from calibrators.planning.instruments import step_actions
from calibrators.study.compare import Config, agent_episodes, scored_trials
from calibrators.study.statistics import median_interval, paired
from calibrators.study.trials import Trial
from orthoglide_env.world.conditions import EFFECT_NAMES, Conditions

UM = 1e3  # per mm
#: The effect families that act on a lab of dial gauges (the thermometer's and the
#: tracker's are their instruments', which such a lab does not own).
DIAL_FAMILIES: tuple[str, ...] = tuple(e for e in EFFECT_NAMES
                                       if e not in ("thermometer", "tracker"))


def without(conditions: Conditions, family: str) -> Conditions:
    """``conditions`` with ``family`` switched off."""
    return replace(conditions, effects=tuple(e for e in conditions.effects if e != family))


def fitted(episodes: list, told: Conditions | str, sigma: float) -> list[Trial]:
    """``episodes``' readings fitted by ``full`` told ``told``, scored."""
    estimates = for_study("full", sigma, told, "realistic").fit_many(
        [e.run.measurements for e in episodes])
    return scored_trials(episodes, "full", estimates)


def predicted_um(trials: list[Trial]) -> np.ndarray:
    """The fit's predicted error after rigid motion of each trial (µm; NaN where the fit
    failed)."""
    return UM * np.array([np.nan if t.failed else t.predicted_rigid_mm for t in trials])


def realised(trials: list[Trial], full: list[Trial]) -> str:
    """The realised error's median [95 %] and RMS over machines (µm), failed fits scored
    as :func:`~calibrators.study.statistics.paired` scores them, and per machine over the
    ``full`` world's trials: median ratio [95 %]."""
    error = UM * np.array([t.tcp_after["rigid"] for t in trials])
    low, high = median_interval(error)
    text = (f"{np.median(error):.2f} [{low:.2f}, {high:.2f}] | "
            f"{np.sqrt(np.mean(error**2)):.2f}")
    if trials is full:
        return text + " | -"
    both = [replace(t, agent="this") for t in trials] + [replace(t, agent="full")
                                                         for t in full]
    row = paired(both)[0]
    ci = "[{:.2f}, {:.2f}]".format(*row["ratio_ci95"]) if row["ratio_ci95"] else "-"
    return text + f" | {row['ratio_median']:.3f} {ci}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--conditions", default="lab", choices=("lab", "workshop"))
    parser.add_argument("--budget", type=float, default=3600.0, help="lab seconds")
    parser.add_argument("--machines", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--sigma", type=float, default=0.02, help="dial repeatability, mm")
    parser.add_argument("--plan", default="kept", choices=("kept", "greedy"))
    parser.add_argument("--families", default=",".join(DIAL_FAMILIES),
                        help="the effect families to switch off, one at a time")
    args = parser.parse_args()
    families = tuple(f for f in args.families.split(",") if f)
    if unknown := sorted(set(families) - set(DIAL_FAMILIES)):
        parser.error(f"unknown families {unknown}; they are {list(DIAL_FAMILIES)}")
    if args.machines < 6:
        parser.error("--machines must be at least 6 (a median's 95 % interval)")
    world = Conditions(args.conditions)
    plan_as_told(world)
    if args.plan == "greedy":
        optimal.phased_plan = lambda *given: None

    def episodes(conditions: Conditions) -> list:
        config = Config(agents=("optimal",), estimators=("full",), conditions=conditions,
                        seed=args.seed, sigma=args.sigma, budget_s=args.budget)
        return agent_episodes(config, "optimal", list(range(args.machines)))

    full_episodes = episodes(world)
    sigma = full_episodes[0].run.sigma
    (slots, engaged, weighting, _, design, *_), (steps, _) = next(
        iter(optimal.made_plans().items()))
    model = lab_model(design, world, weighting, args.budget, ("dial",), len(slots))
    counts = plan_counts(model, design, slots, engaged, step_actions(steps))
    print(f"{args.conditions}, {args.budget:.0f} s, dials alone, optimal's {args.plan} plan, "
          f"{args.machines} machines, seed {args.seed}, sigma {args.sigma} mm, the full fit; "
          f"the plan on the bound's model {UM * np.sqrt(model.value(counts)):.3f} um, its "
          f"readings at a-priori contact "
          f"{UM * np.sqrt(at_contact_model(model, design).value(counts)):.3f} um")
    full = fitted(full_episodes, world, sigma)
    reference = predicted_um(full)
    print("\n| world played, fit told | fit's predicted, median µm | over the full, per "
          "machine | realised median [95 %] | RMS | per machine over the full [95 %] "
          "| z-RMS |")
    print("|---|---|---|---|---|---|---|")

    def line(name: str, trials: list[Trial], played_as_told: bool) -> None:
        """A row: the fit's predicted error, and where the fit was told the world it
        played, the realised error."""
        mine = predicted_um(trials)  # machine by machine, as the reference's
        shown = realised(trials, full) if played_as_told else "- | - | -"
        print(f"| {name} | {np.nanmedian(mine):.3f} | {np.nanmedian(mine / reference):.3f} "
              f"| {shown} | {z_rms(trials):.2f} |", flush=True)

    line(f"{world.label}, told {world.label}", full, True)
    for family in families:
        line(f"{world.label}, told without {family}",
             fitted(full_episodes, without(world, family), sigma), False)
    line(f"{world.label}, told the lead error alone",
         fitted(full_episodes, replace(world, effects=("lead",)), sigma), False)
    line(f"{world.label}, told ideal", fitted(full_episodes, Conditions("ideal"), sigma), False)
    for family in families:
        less = without(world, family)
        line(f"without {family}, told so", fitted(episodes(less), less, sigma), True)

if __name__ == "__main__":
    main()
