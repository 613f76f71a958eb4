"""Whether a reference procedure's gauges' part runs on the lab's clock: per agent, budget
and machine, the largest gap between the end of a step as its plan times it and the lab's
clock after it, and whether the episode ended on a step the lab refused as ending past the
budget.

    python benchmarks/procedure_clock.py [--agents iso230-2,ballbar,step-gauge]
        [--budgets 1500,3000,3600] [--machines 2] [--conditions lab] [--gauges optimal]

Each agent plays in a lab owning the dial gauges and its instrument, on the nominal
machine (the one ``orthoglide plan`` writes its procedure from) and on ``--machines``
realistic machines of seed 1, dial sigma 0.02 mm.  With ``--gauges optimal`` (the gauges'
part a written procedure takes) the gap is measured step by step against the plan made
where the programme left the lab; with ``active`` (``compare``'s) only the refusals and
the end are shown: its planner takes the lab's clock at every step.  A budget a procedure
refuses (``iso230-2`` below its programme's 2959.4 s, ``step-gauge`` below its 1366.3 s)
is shown refused, in its one line.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from contextlib import closing
from typing import Any

import numpy as np

from calibrators.agents import get_agent
from calibrators.agents.instrument_first import InstrumentFirst
from calibrators.agents.optimal import fixed_plan, lab_setup, leaves_laser_unread, move_dwell_s
from calibrators.study.compare import Config
from calibrators.study.episodes import machine_seed, run_episode
from calibrators.study.labs import make_lab, nominal_options
from orthoglide_env.lab.engine import TIME_UP
from orthoglide_env.world.conditions import Conditions

#: The instruments each reference procedure's lab owns.
INSTRUMENTS = {"iso230-2": ("dial", "interferometer"), "ballbar": ("dial", "ballbar"),
               "step-gauge": ("dial", "step-gauge")}


class ClockWatch:
    """Follows one episode: the gauges' plan from where the programme left the lab, the
    largest gap between its steps' planned ends and the lab's clock, and the refusals."""

    def __init__(self, agent: InstrumentFirst, lab: Any) -> None:
        self.agent, self.lab = agent, lab
        self.plan: tuple | None = None
        self.gap_s, self.done, self.late, self.refused = 0.0, 0, 0, 0

    def reset(self, i: int, observation: dict[str, np.ndarray]) -> None:
        self.before = observation

    def step(self, i: int, action: Mapping[str, Any], observation: dict[str, np.ndarray],
             info: Mapping[str, Any]) -> None:
        refused = str(info.get("refused", ""))
        self.late += refused.endswith(TIME_UP)
        self.refused += bool(refused) and not refused.endswith(TIME_UP)
        if self.agent.started and self.plan is None and self.agent.gauges == "optimal":
            inner = self.agent.inner
            self.start_s = float(self.before["time"][0])
            asked = leaves_laser_unread(inner)
            self.plan, _ = fixed_plan(*lab_setup(self.lab, self.before, inner.reserved_s),
                                      criterion=inner.criterion, remounts=inner.remounts,
                                      dwell_s=move_dwell_s(self.before, asked),
                                      laser_asked=asked)
        if self.plan is not None and not refused:
            if self.done + 1 < len(self.plan):
                planned = self.start_s + self.plan[self.done + 1].time_s
                self.gap_s = max(self.gap_s, abs(planned - float(observation["time"][0])))
            self.done += 1
        self.before = observation


def measure(name: str, budget_s: float, machine: int, conditions: Conditions, gauges: str
            ) -> tuple[ClockWatch, float]:
    """Agent ``name``'s episode on ``machine`` (-1: the nominal one) with its gauges' part
    played by ``gauges``: the watch and the lab's clock at the end."""
    agent = get_agent(name)
    agent.gauges = gauges
    config = Config((name,), ("full",), budget_s=budget_s, seed=1, conditions=conditions,
                    instruments=INSTRUMENTS[name])
    settings = {k: v for k, v in config.lab_kwargs(agent).items()
                if k not in ("tracker", "reference")}
    if machine < 0:
        settings["errors"] = "nominal"
    with closing(make_lab(agent, **settings)) as env:
        watch = ClockWatch(agent, env.unwrapped)
        episode = run_episode(env, agent, machine_seed(1, max(machine, 0)),
                              nominal_options(config.design) if machine < 0 else None,
                              watch=watch)
    return watch, episode.time_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", default=",".join(INSTRUMENTS))
    parser.add_argument("--budgets", default="1500,3000,3600")
    parser.add_argument("--machines", type=int, default=2)
    parser.add_argument("--conditions", default="lab")
    parser.add_argument("--gauges", choices=("optimal", "active"), default="optimal")
    args = parser.parse_args()
    conditions = Conditions(args.conditions)
    for name in args.agents.split(","):
        for budget in (float(b) for b in args.budgets.split(",")):
            for machine in range(-1, args.machines):
                try:
                    watch, end = measure(name, budget, machine, conditions, args.gauges)
                except ValueError as exc:  # a budget the procedure refuses, on every machine
                    print(f"{name:10s} {budget:5.0f} s  refused: {exc}", flush=True)
                    break
                gap = f"{watch.gap_s:6.2f} s" if args.gauges == "optimal" else "     -  "
                print(f"{name:10s} {budget:5.0f} s  {'nominal' if machine < 0 else machine:>7}"
                      f"  max |planned end - lab clock| {gap}  refused past the budget "
                      f"{watch.late}, otherwise {watch.refused}  ends at {end:.1f} s",
                      flush=True)


if __name__ == "__main__":
    main()
