"""What to buy: each instrument set's TCP error after rigid motion at 1 h and 3 h.

    python benchmarks/buyer.py --machines 50 --jobs 2 --out results/buyer
    python benchmarks/buyer.py --machines 10 --out results/buyer --dry-run

A machine builder's table under ``lab`` (seed 1, realistic machines, dial sigma 0.02 mm,
``full``): per instrument set (:data:`SETS`: the dial gauges alone, with the
interferometer, with the ballbar, all of them), per indicator (``--indicator dial`` or
``digital``) and per budget (1 h, 3 h), the best of the set's agents by its median, with
its 95 % distribution-free interval; and closed-loop drives (``--drives scales``) with the
gauges alone.  Each cell is one ``orthoglide compare`` run kept in ``--out`` (a run
already there is read, not run again: ``compare --resume`` finishes one cut short);
``--dry-run`` prints the commands.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from calibrators.study.compare import Trial
from calibrators.study.statistics import summary

UM = 1e3  # per mm
#: Each instrument set: its ``--instruments`` and the agents that plan with it.
SETS: dict[str, tuple[str, str]] = {
    "dial": ("dial", "optimal,active"),
    "dial + interferometer": ("dial,interferometer", "optimal,active,iso230-2"),
    "dial + ballbar": ("dial,ballbar", "optimal,active,ballbar"),
    "all": ("dial,interferometer,ballbar,tracker", "optimal,active,iso230-2,ballbar,tracker"),
}
BUDGETS: tuple[float, ...] = (3600.0, 10800.0)
#: The rows: (instrument set, indicator, drives).
ROWS: tuple[tuple[str, str, str], ...] = (
    *((name, indicator, "screw") for name in SETS for indicator in ("dial", "digital")),
    ("dial", "dial", "scales"), ("dial", "digital", "scales"))


def folder_of(out: Path, row: tuple[str, str, str], budget: float) -> Path:
    """Where the compare run of ``row`` at ``budget`` seconds is kept."""
    name, indicator, drives = row
    return out / f"{name.replace(' + ', '+')}-{indicator}-{drives}-{budget / 3600:g}h"


def command(row: tuple[str, str, str], budget: float, machines: int, jobs: int,
            folder: Path) -> list[str]:
    """The ``orthoglide compare`` arguments of one cell."""
    name, indicator, drives = row
    instruments, agents = SETS[name]
    return ["compare", "--agents", agents, "--instruments", instruments, "--indicator",
            indicator, "--drives", drives, "--conditions", "lab", "--budget", f"{budget:g}",
            "--machines", str(machines), "--seed", "1", "--estimators", "full", "--jobs",
            str(jobs), "--quiet", "--out", str(folder)]


def best(folder: Path) -> str:
    """The cell of a kept run: its best agent's rigid median [95 %] (um), by median."""
    trials = [Trial.from_json(line) for line in (folder / "trials.jsonl").open()]
    rows = summary(trials)
    top = min(rows, key=lambda r: r["tcp_after_mm"]["rigid"]["median"])
    rigid = top["tcp_after_mm"]["rigid"]
    low, high = (UM * v for v in rigid["ci95"])
    return f"{UM * rigid['median']:.1f} [{low:.1f}, {high:.1f}] `{top['agent']}`"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True,
                        help="folder of the compare runs, one per cell (made if missing)")
    parser.add_argument("--machines", type=int, default=10,
                        help="machines per run (default: %(default)s)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="worker processes per run (default: %(default)s)")
    parser.add_argument("--dry-run", action="store_true",
                        help="print the compare commands, run nothing")
    args = parser.parse_args()
    if args.machines < 1 or args.jobs < 1:
        parser.error("--machines and --jobs must be at least 1")
    cells = [(row, budget) for row in ROWS for budget in BUDGETS]
    for row, budget in cells:
        folder = folder_of(args.out, row, budget)
        argv = command(row, budget, args.machines, args.jobs, folder)
        if args.dry_run:
            print("orthoglide " + " ".join(argv))
            continue
        if (folder / "summary.csv").exists():
            continue
        resume = ["--resume"] if (folder / "config.json").exists() else []
        subprocess.run([sys.executable, "-m", "calibrators.cli", *argv, *resume], check=True)
    if args.dry_run:
        return
    print("| instruments | indicator | drives | " + " | ".join(
        f"{b / 3600:g} h: rigid µm median [95 %], best agent" for b in BUDGETS) + " |")
    print("|---|---|---|" + "---|" * len(BUDGETS))
    for row in ROWS:
        print(f"| {row[0]} | {row[1]} | {row[2]} | " + " | ".join(
            best(folder_of(args.out, row, b)) for b in BUDGETS) + " |")
    print(f"\n{args.machines} realistic machines per cell, lab, seed 1, dial sigma 0.02 mm, "
          "full.")


if __name__ == "__main__":
    main()
