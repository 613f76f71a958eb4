"""What agents do in their episodes, from their notebooks: how many readings, at how many
postures, how often they return to a posture, how many dials read at once, and re-mounts.

    python benchmarks/episode_habits.py --agents active,policy:FILE [--machines 10]
        [--budget 330] [--conditions lab] [--sigma 0.02] [--seed 1] [--design FILE]

Each agent plays the comparison's machines (``orthoglide compare``'s: machine ``i`` of
``--seed``, the same lab) and its notebook is read, never the truth.  A reading event is
one lab step that wrote readings; a visit is a run of reading events at one posture; a
revisit is a visit to a posture read before; a re-mount is a mounting first read after
the episode's first reading event.  The table gives each count's median over the
machines, so that two agents' habits can be set side by side (why one reads more than
the other in the same time).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from calibrators.agents.names import get_agent
from calibrators.study import compare
from orthoglide_env.model.design import load_design
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import CONDITION_NAMES, DEFAULT_CONDITIONS, Conditions


@dataclass(frozen=True)
class Habits:
    """One episode's counts (see the module)."""

    readings: int
    events: int
    postures: int
    visits: int
    revisits: int
    longest_stay: int
    remounts: int
    time_s: float

    @property
    def dials_per_event(self) -> float:
        """The readings of one reading event, on average."""
        return self.readings / self.events if self.events else 0.0


def habits(records: list, time_s: float) -> Habits:
    """The counts of one notebook's ``records`` (the lab's, in order) of an episode that
    ended at ``time_s``."""
    if not records:
        return Habits(0, 0, 0, 0, 0, 0, 0, time_s)
    events: dict[int, tuple[float, ...]] = {}
    for record in records:
        events.setdefault(record.step, tuple(np.round(record.rho, 6)))
    places = list(events.values())
    stays = [1]
    for before, after in pairwise(places):
        if after == before:
            stays[-1] += 1
        else:
            stays.append(1)
    first = min(events)
    remounts = len({r.mounting for r in records if r.step > first}
                   - {r.mounting for r in records if r.step == first})
    postures = len(set(places))
    return Habits(len(records), len(places), postures, len(stays), len(stays) - postures,
                  max(stays), remounts, time_s)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--agents", required=True, help="agents, comma separated")
    parser.add_argument("--machines", type=int, default=10)
    parser.add_argument("--budget", type=float, default=330.0, help="lab seconds")
    parser.add_argument("--conditions", default=DEFAULT_CONDITIONS, choices=CONDITION_NAMES)
    parser.add_argument("--sigma", type=float, default=0.02, help="dial sigma (mm)")
    parser.add_argument("--seed", type=int, default=1, help="the comparison's seed")
    parser.add_argument("--design", metavar="FILE", help="the machines' design file")
    args = parser.parse_args(argv)
    if args.machines < 1:
        parser.error(f"--machines must be at least 1, got {args.machines}")
    agents = tuple(a for a in args.agents.split(",") if a)
    try:
        config = compare.Config(agents, ("full",), budget_s=args.budget,
                                errors=DEFAULT_PRESET, sigma=args.sigma, seed=args.seed,
                                conditions=Conditions(args.conditions),
                                design=load_design(args.design))
        for agent in agents:
            get_agent(agent)  # an unknown name or policy file: one line before any play
    except ValueError as error:
        parser.error(str(error))
    print(f"{args.machines} machines ({config.world}); medians over the machines")
    fields = ("readings", "events", "dials_per_event", "postures", "visits", "revisits",
              "longest_stay", "remounts", "time_s")
    print(f"{'agent':>40} " + " ".join(f"{f:>15}" for f in fields))
    for agent in agents:
        episodes = compare.agent_episodes(config, agent, list(range(args.machines)))
        rows = [habits(e.run.records, e.run.time_s) for e in episodes]
        medians = [float(np.median([getattr(r, f) for r in rows])) for f in fields]
        print(f"{agent[-40:]:>40} " + " ".join(f"{m:>15.4g}" for m in medians))


if __name__ == "__main__":
    main()
