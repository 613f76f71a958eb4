"""What to buy: each instrument set's TCP error after rigid motion at 1 h and 3 h.

    python benchmarks/buyer.py --machines 50 --jobs 2 --out results/buyer
    python benchmarks/buyer.py --machines 10 --out results/buyer --dry-run
    python benchmarks/buyer.py --machines 20 --agents optimal --sets dial --out results/buyer
    python benchmarks/buyer.py --machines 50 --agents optimal,active --out results/buyer --table

A machine builder's table under ``lab`` (seed 1, realistic machines, ``full``): per
instrument set (:data:`SETS`: the dial gauges alone, with the interferometer, with the
ballbar, all of them), per indicator (``--indicator dial`` or ``digital``, each read with
its own sigma and resolution, :data:`NOISE`) and per budget (1 h, 3 h), the best of the
set's agents by its median, with its 95 % distribution-free interval, p95, lab minutes,
z-RMS, chi-square rejections, failed trials and its median over the bound of the
instruments it reads (as ``headline.py --bound``, kept in the run's folder); and
closed-loop drives (``--drives scales``) with the gauges alone.  Each cell is one
``orthoglide compare`` run kept in ``--out`` (a run already there is read, not run again:
``compare --resume`` finishes one cut short, which loses at most its last ``--chunk`` of
machines); ``--dry-run`` prints the commands; ``--table`` prints the table of the runs
kept so far, each cell not yet run marked so, and runs nothing.

The whole table is 20 runs of every set's agents, and ``active`` costs most (a minute or
more of CPU per machine at 3 h).  ``--agents``, ``--sets`` and ``--budgets`` run a part of
it: only those agents of each set (``optimal``, whose plan is made once per run, is the
cheapest designed one), only those sets' rows, only those budgets.  The table printed
says which agents and which rows it holds.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

from headline import agent_instruments, cell, folder_bound, outside_bound

from calibrators.study.compare import Trial
from calibrators.study.statistics import summary

#: Each instrument set: its ``--instruments`` and the agents that plan with it.
SETS: dict[str, tuple[str, tuple[str, ...]]] = {
    "dial": ("dial", ("optimal", "active")),
    "dial+interferometer": ("dial,interferometer", ("optimal", "active", "iso230-2")),
    "dial+ballbar": ("dial,ballbar", ("optimal", "active", "ballbar")),
    "all": ("dial,interferometer,ballbar,tracker",
            ("optimal", "active", "iso230-2", "ballbar", "tracker")),
}
#: Each indicator's gauge sigma and resolution (mm): the dial gauges' defaults, and a
#: digital indicator read to its datasheets' 1 um (docs/conditions.md, ``digital_range``)
#: with a 2 um repeatability (an assumption, as docs/benchmarks.md reads one).
NOISE: dict[str, tuple[float, float]] = {"dial": (0.02, 0.01), "digital": (0.002, 0.001)}
#: The budgets of the table (h).
BUDGETS_H: tuple[float, ...] = (1.0, 3.0)
#: The rows: (instrument set, indicator, drives).
ROWS: tuple[tuple[str, str, str], ...] = (
    *((name, indicator, "screw") for name in SETS for indicator in ("dial", "digital")),
    ("dial", "dial", "scales"), ("dial", "digital", "scales"))


def folder_of(out: Path, row: tuple[str, str, str], budget: float) -> Path:
    """Where the compare run of ``row`` at ``budget`` seconds is kept."""
    name, indicator, drives = row
    return out / f"{name}-{indicator}-{drives}-{budget / 3600:g}h"


def command(row: tuple[str, str, str], budget: float, agents: tuple[str, ...],
            machines: int, jobs: int, chunk: int, folder: Path) -> list[str]:
    """The ``orthoglide compare`` arguments of one cell, run with ``agents``."""
    name, indicator, drives = row
    instruments = SETS[name][0]
    sigma, resolution = NOISE[indicator]
    return ["compare", "--agents", ",".join(agents), "--instruments", instruments, "--indicator",
            indicator, "--sigma", f"{sigma:g}", "--resolution", f"{resolution:g}", "--drives",
            drives, "--conditions", "lab", "--budget", f"{budget:g}",
            "--machines", str(machines), "--seed", "1", "--estimators", "full", "--jobs",
            str(jobs), "--chunk", str(chunk), "--quiet", "--out", str(folder)]


def best(folder: Path) -> str:
    """The cell of a kept run: its best agent by rigid median, as headline's row (um), with
    its median over the bound of the instruments it reads (kept in the folder); 'not run'
    when the folder holds no finished run."""
    if not (folder / "summary.csv").exists():
        return "not run"
    trials = [Trial.from_json(line) for line in (folder / "trials.jsonl").open()]
    agent = min(summary(trials), key=lambda r: r["tcp_after_mm"]["rigid"]["median"])["agent"]
    config = json.loads((folder / "config.json").read_text())
    bound = folder_bound(folder, config,
                         agent_instruments(agent, tuple(config.get("instruments", ("dial",)))))
    return f"{cell([t for t in trials if t.agent == agent], bound, outside_bound(agent))} `{agent}`"


def kept_differs(folder: Path, agents: tuple[str, ...], machines: int,
                 noise: tuple[float, float]) -> str:
    """Why the run kept in ``folder`` is not the cell asked for (other agents, machines or
    gauge sigma and resolution), or '' when it is or none is kept."""
    if not (folder / "config.json").exists():
        return ""
    config = json.loads((folder / "config.json").read_text())
    kept = (tuple(config["agents"]), config["machines"], (config["sigma"], config["resolution"]))
    if kept == (agents, machines, noise):
        return ""
    return (f"{folder} holds a run of {','.join(kept[0])} on {kept[1]} machines read with "
            f"sigma, resolution {kept[2][0]:g}, {kept[2][1]:g} mm, not {','.join(agents)} on "
            f"{machines} with {noise[0]:g}, {noise[1]:g}: give another --out")


def hours(text: str) -> tuple[float, ...]:
    """A comma list of positive budgets in hours, in seconds; ValueError otherwise."""
    try:
        found = tuple(3600.0 * float(h) for h in text.split(","))
    except ValueError:
        raise ValueError(f"--budgets takes hours, comma-separated, not {text!r}") from None
    if not all(math.isfinite(b) and b > 0 for b in found):
        raise ValueError(f"--budgets takes positive hours, not {text!r}")
    return found


def names(text: str, known: tuple[str, ...], what: str) -> tuple[str, ...]:
    """A comma list of ``known`` names, in ``known``'s order; ValueError naming the first
    unknown one."""
    given = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in given if n not in known]
    if unknown or not given:
        raise ValueError(f"unknown {what} {unknown[0] if unknown else repr(text)}; "
                         f"known: {', '.join(known)}")
    return tuple(n for n in known if n in given)


def agents_of(name: str, chosen: tuple[str, ...] | None) -> tuple[str, ...]:
    """The agents a set's cells run: its own (:data:`SETS`), or those of them ``chosen``;
    ValueError when the set has none of them."""
    own = SETS[name][1]
    if chosen is None:
        return own
    kept = tuple(a for a in own if a in chosen)
    if not kept:
        raise ValueError(f"set {name!r} has none of the agents {', '.join(chosen)} "
                         f"(its agents: {', '.join(own)}); leave it out with --sets")
    return kept


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True,
                        help="folder of the compare runs, one per cell (made if missing)")
    parser.add_argument("--machines", type=int, default=10,
                        help="machines per run (default: %(default)s)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="worker processes per run (default: %(default)s)")
    parser.add_argument("--agents", default=None, metavar="LIST",
                        help="only these of each set's agents, comma-separated, e.g. "
                             "optimal (default: every agent of the set)")
    parser.add_argument("--sets", default=",".join(SETS), metavar="LIST",
                        help="only these instrument sets' rows, comma-separated "
                             "(default: %(default)s)")
    parser.add_argument("--budgets", default=",".join(f"{b:g}" for b in BUDGETS_H),
                        metavar="LIST", help="budgets in hours, comma-separated "
                                             "(default: %(default)s)")
    parser.add_argument("--chunk", type=int, default=5,
                        help="machines per task of each run: a run cut short and resumed "
                             "loses at most these (default: %(default)s)")
    parser.add_argument("--dry-run", action="store_true",
                        help="print the compare commands, run nothing")
    parser.add_argument("--table", action="store_true",
                        help="print the table of the runs kept in --out, run nothing")
    args = parser.parse_args()
    if min(args.machines, args.jobs, args.chunk) < 1:
        parser.error("--machines, --jobs and --chunk must be at least 1")
    try:
        sets = names(args.sets, tuple(SETS), "set")
        everyone = tuple(dict.fromkeys(a for _, own in SETS.values() for a in own))
        chosen = None if args.agents is None else names(args.agents, everyone, "agent")
        agents = {name: agents_of(name, chosen) for name in sets}
        budgets = hours(args.budgets)
    except ValueError as error:
        parser.error(str(error))
    rows = [row for row in ROWS if row[0] in sets]
    cells = [(folder_of(args.out, row, budget), row, budget) for row in rows for budget in budgets]
    if args.dry_run:
        for folder, row, budget in cells:
            argv = command(row, budget, agents[row[0]], args.machines, args.jobs, args.chunk,
                           folder)
            print("orthoglide " + " ".join(argv))
        return
    # Every kept run is checked before the first run starts, not an hour into the table.
    for folder, row, _ in cells:
        if differs := kept_differs(folder, agents[row[0]], args.machines, NOISE[row[1]]):
            parser.error(differs)
    for folder, row, budget in cells:
        if args.table or (folder / "summary.csv").exists():
            continue
        argv = command(row, budget, agents[row[0]], args.machines, args.jobs, args.chunk,
                       folder)
        resume = ["--resume"] if (folder / "config.json").exists() else []
        subprocess.run([sys.executable, "-m", "calibrators.cli", *argv, *resume], check=True)
    print("| instruments | indicator | drives | " + " | ".join(
        f"{b / 3600:g} h: rigid µm median [95 %] (p95), min, z-RMS, chi2 rejected, failed, "
        "x bound, best agent" for b in budgets) + " |")
    print("|---|---|---|" + "---|" * len(budgets))
    for row in rows:
        print(f"| {row[0]} | {row[1]} | {row[2]} | " + " | ".join(
            best(folder_of(args.out, row, b)) for b in budgets) + " |")
    print(f"\n{args.machines} realistic machines per cell, lab, seed 1, gauge sigma and "
          "resolution " + ", ".join(f"{k} {s:g} and {r:g} mm" for k, (s, r) in NOISE.items())
          + ", full; agents: " + "; ".join(f"{n}: {', '.join(a)}" for n, a in agents.items())
          + ".")
    left = [n for n in SETS if n not in sets]
    if left:
        print(f"Sets left out: {', '.join(left)}.")


if __name__ == "__main__":
    main()
