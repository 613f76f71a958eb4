"""The headline under each world: compare's trials as a table with intervals.

    orthoglide compare --machines 50 --seed 1 --agents paper,random,tracker,optimal,active \
        --estimators extended,full --conditions C --jobs 2 --out results/head/C
    python benchmarks/headline.py results/head/ideal results/head/lab results/head/workshop

Per agent x estimator and per folder (one compare run each, its conditions in its
config): the TCP error after rigid motion (um), median with its 95 % distribution-free
interval, and p95; the median lab time (min); z-RMS; the fraction of trials whose
chi-square test rejects the model; failed trials (each counted as its uncalibrated
machine, as compare's summary counts them).  A folder is named by its conditions, and by
its budget and instruments too where the folders differ in them.

``--bound`` adds each agent's median over the bound of the instruments it reads
(:func:`calibrators.planning.bound.lower_bound`: its dials, and the interferometer and the
ballbar when the agent needs or plans over them; a tracker's or a step gauge's readings
are not in the bound, so their agents' ratio, marked ``*``, is over the dials' bound and
may fall below 1), and the bounds themselves; each is kept in the folder
(``bound-visits-<instruments>.json``) once computed.  ``--against AGENT`` adds every other
agent's ratio to AGENT paired on the same machines (median with its 95 % interval), the
share of machines where it is the better (a tie counts a half), and on how many of them
either fit failed.  The instruments' headline (docs/instruments.md):

    for c in lab workshop; do for b in 3600 10800; do
      nice orthoglide compare --machines 50 --seed 1 --estimators full --conditions $c \
        --budget $b --agents paper,optimal,active,tracker,iso230-2 \
        --instruments dial,interferometer,tracker --jobs 2 --quiet --out results/head/$c-$b
    done; done
    python benchmarks/headline.py results/head/*-* --bound --against active
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from calibrators.agents import get_agent
from calibrators.planning.bound import BOUND_INSTRUMENTS, Bound, lower_bound
from calibrators.study.compare import Trial
from calibrators.study.statistics import paired, summary
from orthoglide_env.instruments.dial import GaugeNoise, weighting_sigma
from orthoglide_env.lab.operations import PAPER_SLOTS
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.world.conditions import Conditions

UM = 1e3  # per mm


def fixed(value: float | None, digits: int, scale: float = 1.0) -> str:
    """``value * scale`` to ``digits`` decimals, or a dash where compare's summary has none
    (too few machines for an interval or a p95; every fit failed, so no z-RMS)."""
    return "-" if value is None else f"{scale * value:.{digits}f}"


def cell(trials: list[Trial], bound: Bound | None = None, mark: str = "") -> str:
    """One agent x estimator's row of compare's summary, in um (and its median over
    ``bound``)."""
    (row,) = summary(trials)
    rigid = row["tcp_after_mm"]["rigid"]
    low, high = rigid["ci95"] or (None, None)
    ratio = (f", {rigid['median'] / bound.bound_mm:.2f}x{mark}"
             if bound is not None and bound.bound_mm > 0 else "")
    return (f"{fixed(rigid['median'], 1, UM)} [{fixed(low, 1, UM)}, {fixed(high, 1, UM)}]"
            f" ({fixed(rigid['p95'], 1, UM)}), {row['time_s']['median'] / 60:.0f},"
            f" {fixed(row['z_rms'], 2)}, {fixed(row['chi2_rejected'], 2)}, {row['failed']}"
            f"{ratio}")


def agent_instruments(agent: str, owned: tuple[str, ...]) -> tuple[str, ...]:
    """The instruments of the bound an agent's row is held against: the dials, and those
    of :data:`BOUND_INSTRUMENTS` the lab owns that it needs or plans over (``optimal``,
    ``active``: every one the lab owns)."""
    found = get_agent(agent)
    reads = (*found.needs_instruments, *(owned if getattr(found, "plans_instruments", False)
                                         else ()))
    return ("dial", *(n for n in BOUND_INSTRUMENTS[1:] if n in reads and n in owned))


def outside_bound(agent: str) -> str:
    """``*`` when the agent reads an instrument the bound does not hold (the tracker, the
    step gauge: its ratio is over a bound without those readings), else ''."""
    found = get_agent(agent)
    reads = (*found.needs_instruments, *(("tracker",) if found.needs_tracker else ()))
    return "*" if any(n not in BOUND_INSTRUMENTS for n in reads) else ""


def folder_bound(folder: Path, config: dict, instruments: tuple[str, ...]) -> Bound:
    """The bound of a compare folder's lab with ``instruments``, from the folder when kept
    there, else computed and kept (named for the visit's pricing: a bound a folder kept
    before it, dial readings priced at a sixth of a visit, is not read)."""
    path = folder / f"bound-visits-{'+'.join(instruments)}.json"
    if path.exists():
        return Bound.from_dict(json.loads(path.read_text()))
    conditions = Conditions.from_dict({"name": config.get("conditions", "ideal"),
                                       "effects": config.get("effects"),
                                       "indicator": config.get("indicator", "dial"),
                                       "drives": config.get("drives", "screw")})
    design = (MachineDesign.from_dict(config["design"]) if "design" in config
              else PROTOTYPE)
    noise = GaugeNoise(config["sigma"], config["resolution"])
    found = lower_bound(design, conditions, float(weighting_sigma(noise.effective_sigma)),
                        float(config["budget_s"]), instruments, len(PAPER_SLOTS))
    path.write_text(json.dumps(found.to_dict()) + "\n")
    return found


def budget_label(seconds: float) -> str:
    """A budget as a reader says it: whole hours in h, anything else in s (330 s, not
    0.0916667 h)."""
    return f"{seconds / 3600:g} h" if seconds % 3600 == 0 else f"{seconds:g} s"


def labels(configs: list[dict]) -> list[str]:
    """Each folder's name: its conditions, with its budget and instruments where the
    folders differ in them."""
    names = [c.get("conditions", "ideal") for c in configs]
    if len({c.get("budget_s") for c in configs}) > 1:
        names = [f"{n} {budget_label(c['budget_s'])}"
                 for n, c in zip(names, configs, strict=True)]
    if len({tuple(c.get("instruments", ())) for c in configs}) > 1:
        names = [f"{n} {'+'.join(c.get('instruments', ['dial']))}"
                 for n, c in zip(names, configs, strict=True)]
    return names


def paired_lines(name: str, trials: list[Trial], against: str) -> list[str]:
    """Every other agent's ratio to ``against`` on the same machines, per estimator."""
    out = []
    for agent in dict.fromkeys(t.agent for t in trials):
        if agent == against:
            continue
        both = [t for t in trials if t.agent == agent] + [t for t in trials
                                                           if t.agent == against]
        for pair in paired(both):
            interval = ("[{:.2f}, {:.2f}]".format(*pair["ratio_ci95"]) if pair["ratio_ci95"]
                        else "-")
            out.append(f"| {name} | `{agent}` / `{against}` | `{pair['estimator']}` | "
                       f"{pair['ratio_median']:.2f} {interval} | {pair['win_rate']:.0%} | "
                       f"{pair['machines']} | {pair['failed']} |")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="compare --out folders")
    parser.add_argument("--bound", action="store_true",
                        help="each agent's median over the bound of its instruments")
    parser.add_argument("--against", default=None, metavar="AGENT",
                        help="every other agent's paired ratio to AGENT")
    args = parser.parse_args()
    configs = [json.loads((f / "config.json").read_text()) for f in args.folders]
    runs = {}
    for name, folder in zip(labels(configs), args.folders, strict=True):
        trials = [Trial.from_json(line) for line in (folder / "trials.jsonl").open()]
        runs[name] = trials
    bounds: dict[tuple[str, tuple[str, ...]], Bound] = {}
    if args.bound:
        for name, folder, config in zip(runs, args.folders, configs, strict=True):
            owned = tuple(config.get("instruments", ("dial",)))
            for agent in dict.fromkeys(t.agent for t in runs[name]):
                kind = agent_instruments(agent, owned)
                if (name, kind) not in bounds:
                    bounds[name, kind] = folder_bound(folder, config, kind)
    ratio = ", x bound" if args.bound else ""
    print("| agent | estimator | " + " | ".join(
        f"{name}: rigid µm median [95 % interval] (p95), min, z-RMS, chi2 rejected, failed"
        f"{ratio}" for name in runs) + " |")
    print("|---|---|" + "---|" * len(runs))
    # Folders may hold different agents: a row is every pair any folder ran, and a folder
    # that did not run it shows a dash.
    rows = list(dict.fromkeys((t.agent, t.estimator) for trials in runs.values()
                              for t in trials))
    for agent, estimator in rows:
        cells = []
        for (name, trials), config in zip(runs.items(), configs, strict=True):
            kind = agent_instruments(agent, tuple(config.get("instruments", ("dial",))))
            mine = [t for t in trials if (t.agent, t.estimator) == (agent, estimator)]
            cells.append(cell(mine, bounds.get((name, kind)), outside_bound(agent)) if mine
                         else "–")
        print(f"| `{agent}` | `{estimator}` | " + " | ".join(cells) + " |")
    if bounds:
        print("\n| world | instruments | bound µm | best continuous design µm | laser set up on "
              "| laser readings |")
        print("|---|---|---|---|---|---|")
        for (name, kind), b in bounds.items():
            drives = ", ".join("xyz"[d] for d in b.drives) or "-"
            print(f"| {name} | {'+'.join(kind)} | {UM * b.bound_mm:.2f} | "
                  f"{UM * b.design_mm:.2f} | {drives} | {b.laser_readings:.0f} |")
    if args.against:
        print("\n| world | paired ratio | estimator | median [95 % interval] | better on | "
              "machines | failed on either side |")
        print("|---|---|---|---|---|---|---|")
        for name, trials in runs.items():
            for line in paired_lines(name, trials, args.against):
                print(line)


if __name__ == "__main__":
    main()
