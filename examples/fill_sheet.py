"""Fill a plan's readings sheet from a virtual machine, as a technician would on a real one.

    orthoglide calibrate --agent paper --seed 3 --save-truth truth.json   # a "real" machine
    orthoglide plan --agent paper --out plan
    python examples/fill_sheet.py truth.json plan/readings.csv
    orthoglide fit plan/readings.csv --plan plan/plan.json --save-estimate est.json

The technician is simulated through :func:`pose` alone (what ``orthoglide pose`` says):
at each step's posture the machine file's machine, in its world, is driven and its six
mid-leg dial gauges are read, one pose per step.  So it fills the sheets of plans whose
stands stay at the paper's six places (``paper``, ``paper-once``, ``optimal-stay``, and
``plan --verify`` of any of them); a row of another gauge is refused.  A row whose
plunger leaves its travel on this machine is struck out, as the page tells the
technician to.  ``examples/end_to_end.py`` runs the whole workflow with it.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.model.design import MachineDesign, load_design
from orthoglide_env.model.errors import check_rho
from orthoglide_env.sim.report import pose_in_world
from orthoglide_env.world.machine_file import read_machine_file


def pose(truth: Path, design: MachineDesign, rho: list[float], seed: int) -> dict:
    """The technician at the virtual machine ``truth`` (a machine file of ``design``):
    drive to ``rho``, read every gauge; what ``orthoglide pose --json`` prints."""
    machine, world = read_machine_file(truth, design)
    return pose_in_world(machine, check_rho(np.array(rho, dtype=float), design=machine.design),
                         world.conditions, seed=seed, sigma=DEFAULT_SIGMA,
                         resolution=DEFAULT_RESOLUTION, world=world)


def fill(sheet: Path, truth: Path, design: MachineDesign, seed: int) -> None:
    """Write the readings into ``sheet`` row by row: one pose per step (each reading of a
    step is one of that pose's gauges, the paper's six at the middle of the legs)."""
    rows = list(csv.DictReader(sheet.open()))
    read: dict[int, dict] = {}
    kept = []
    for row in rows:
        step = int(row["step"])
        if step not in read:
            rho = [float(row[f"rho_{a}"]) for a in "xyz"]
            read[step] = pose(truth, design, rho, seed * 100_000 + step)
        gauges = {(g["leg"], g["axis"]): g for g in read[step]["gauges"]}
        if row["at"] != "0.5" or (row["leg"], row["axis"]) not in gauges:
            sys.exit(f"step {step}: gauge {row['mounting']} is not one pose reads")
        gauge = gauges[(row["leg"], row["axis"])]
        # The real machine is not the nominal one the plan was made on: a plunger can
        # leave its travel where the plan expected a reading.  The technician strikes
        # that row out.
        if gauge["valid"]:
            row["reading_mm"] = repr(float(gauge["reading"]))
            kept.append(row)
    print(f"{sheet}: {len(kept)} of {len(rows)} readings taken ({len(rows) - len(kept)} "
          "out of their gauge's travel on this machine, struck out)")
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(kept)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("truth", type=Path,
                        help="the virtual machine: a machine file (calibrate --save-truth)")
    parser.add_argument("sheet", type=Path,
                        help="the readings.csv orthoglide plan wrote; filled in place")
    parser.add_argument("--design", metavar="FILE",
                        help="the machine's design file, as given to plan (default: the "
                             "prototype)")
    parser.add_argument("--seed", type=int, default=0,
                        help="the stream of the gauges' noise (default: %(default)s)")
    args = parser.parse_args()
    fill(args.sheet, args.truth, load_design(args.design), args.seed)


if __name__ == "__main__":
    main()
