"""A machine builder's whole calibration, on a virtual machine of the second design.

    python examples/end_to_end.py [--out e2e] [--seed 5] [--budget 1800]

Every step is an ``orthoglide`` command, as on a real machine; only the technician is
simulated, and only through ``orthoglide pose`` (what the virtual machine's gauges read at
a posture, and where its tool is):

1. the "real" machine: a realistic random machine of ``examples/designs/small.json`` in
   the lab's world, written to ``truth.json`` (``calibrate --save-truth``; nothing else of
   that run is used);
2. ``plan --agent optimal-stay --budget 1800 --conditions lab``: the procedure and its
   sheet, the stands kept where they are set up;
3. the technician fills the sheet: one ``pose`` per drive step, its gauges' readings;
4. ``fit`` the sheet (``--plan`` checks it) into an estimate file;
5. ``compensate`` a grid of workspace targets: the commands and their predicted errors;
   the technician drives each command (``pose``) and the tool's true position is
   compared with its target after the best-fit rigid motion;
6. ``plan --verify`` and ``verify``: the paper's third experiment.

Change ``DESIGN`` to your machine's design file to try it on yours.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import sys
from pathlib import Path

import numpy as np

from calibrators.cli import main
from orthoglide_env.scoring import best_rigid_motion

DESIGN = str(Path(__file__).resolve().parent / "designs" / "small.json")


def orthoglide(*argv: str) -> str:
    """Run one command as a user would, its standard output returned; stop on an error."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = main([str(a) for a in argv])
    if status:
        sys.exit(f"orthoglide {' '.join(map(str, argv))} failed ({status})")
    return out.getvalue()


def pose(truth: Path, rho: list[float], seed: int) -> dict:
    """The technician at the virtual machine: drive to ``rho``, read every gauge."""
    return json.loads(orthoglide("pose", "--machine", truth, "--design", DESIGN, "--rho", *rho,
                                 "--conditions", "lab", "--seed", seed, "--json"))


def fill(sheet: Path, truth: Path, seed: int) -> None:
    """Write the readings into ``sheet`` row by row: one pose per step (each reading of a
    step is one of that pose's gauges, the paper's six at the middle of the legs)."""
    rows = list(csv.DictReader(sheet.open()))
    read: dict[int, dict] = {}
    kept = []
    for row in rows:
        step = int(row["step"])
        if step not in read:
            rho = [float(row[f"rho_{a}"]) for a in "xyz"]
            read[step] = pose(truth, rho, seed * 100_000 + step)
        gauges = {(g["leg"], g["axis"]): g for g in read[step]["gauges"]}
        if row["at"] != "0.5" or (row["leg"], row["axis"]) not in gauges:
            sys.exit(f"step {step}: gauge {row['mounting']} is not one pose reads")
        gauge = gauges[(row["leg"], row["axis"])]
        # The real machine is not the nominal one the plan was made on: a plunger can
        # leave its travel where the plan expected a reading.  The technician strikes
        # that row out.
        if gauge["valid"]:
            row["reading_mm"] = repr(gauge["reading"])
            kept.append(row)
    print(f"{sheet}: {len(kept)} of {len(rows)} readings taken ({len(rows) - len(kept)} "
          "out of their gauge's travel on this machine, struck out)")
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(kept)


def main_() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="e2e", help="folder for every file (default e2e)")
    parser.add_argument("--seed", type=int, default=5, help="the machine drawn (default 5)")
    parser.add_argument("--budget", type=float, default=1800.0,
                        help="the calibration's lab time, s (default 1800)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth = out / "truth.json"
    orthoglide("calibrate", "--design", DESIGN, "--conditions", "lab", "--seed", args.seed,
               "--agent", "paper-once", "--backend", "exact", "--params", "paper6",
               "--save-truth", truth)
    # The technician reads the set-up's six gauges (what ``pose`` reads): no re-mount.
    print(orthoglide("plan", "--agent", "optimal-stay", "--budget", args.budget, "--conditions",
                     "lab", "--design", DESIGN, "--out", out / "plan").strip())
    fill(out / "plan" / "readings.csv", truth, args.seed)
    estimate = out / "estimate.json"
    fitted = json.loads(orthoglide("fit", out / "plan" / "readings.csv", "--plan",
                                   out / "plan" / "plan.json", "--design", DESIGN,
                                   "--conditions", "lab", "--save-estimate", estimate,
                                   "--json"))
    for warning in fitted["warnings"]:
        print(f"fit warning: {warning}")
    # Targets over the scoring grid's cube, inside the control limits of the small design.
    grid = np.linspace(-30.0, 30.0, 4)
    targets = np.array(np.meshgrid(grid, grid, grid, indexing="ij")).reshape(3, -1).T
    (out / "targets.csv").write_text("x,y,z\n" + "".join(
        f"{x:g},{y:g},{z:g}\n" for x, y, z in targets))
    compensated = json.loads(orthoglide("compensate", estimate, "--targets",
                                        out / "targets.csv", "--out", out / "controller",
                                        "--json"))
    reached = np.array([pose(truth, t["command"], 1)["tcp"] for t in compensated["targets"]])
    predicted = np.array([t["predicted_rigid_mm"] for t in compensated["targets"]])
    rotation, translation = best_rigid_motion(targets[None], reached[None],
                                              np.ones((1, len(targets)), bool))
    moved = reached @ rotation[0].T + translation[0]
    rigid = np.linalg.norm(moved - targets, axis=1)
    raw = np.linalg.norm(reached - targets, axis=1)
    print(f"{len(targets)} compensated targets: TCP error after the best-fit rigid motion "
          f"{np.sqrt(np.mean(rigid**2)) * 1000:.1f} um RMS (max {rigid.max() * 1000:.1f}) "
          f"against {np.sqrt(np.mean(predicted**2)) * 1000:.1f} um predicted; raw "
          f"{np.sqrt(np.mean(raw**2)) * 1000:.1f} um RMS")
    print(orthoglide("plan", "--agent", "paper", "--verify", estimate, "--design", DESIGN,
                     "--conditions", "lab", "--out", out / "verify").strip())
    fill(out / "verify" / "readings.csv", truth, args.seed + 1)
    print(orthoglide("verify", estimate, out / "verify" / "readings.csv").strip()
          .splitlines()[-1])


if __name__ == "__main__":
    main_()
