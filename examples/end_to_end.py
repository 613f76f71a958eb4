"""A machine builder's whole calibration, on a virtual machine of the second design.

    python examples/end_to_end.py [--out e2e] [--seed 5] [--budget 1800]

Every step is a call of the workflow's Python API (:mod:`calibrators.workflow`), as on a
real machine, each writing the files its ``orthoglide`` command writes; only the
technician is simulated, and only through ``examples/fill_sheet.py``'s :func:`pose` (what
the virtual machine's gauges read at a posture, and where its tool is, as ``orthoglide
pose`` says it):

1. the "real" machine: a realistic random machine of ``examples/designs/small.json`` in
   the lab's world, written to ``truth.json`` (drawn as ``calibrate --seed`` draws it;
   nothing else of that lab is used);
2. ``Plan`` with the agent ``optimal-stay``, a 1800 s budget, lab conditions: the
   procedure and its sheet, the stands kept where they are set up;
3. the technician fills the sheet: one pose per drive step, its gauges' readings;
4. ``Fit`` the sheet (its plan checks it) into an estimate file;
5. ``Compensate`` a grid of workspace targets: the commands and their predicted errors;
   the technician drives each command (a pose) and the tool's true position is compared
   with its target after the best-fit rigid motion;
6. ``VerificationPlan`` and ``Verify``: the paper's third experiment.

``--design FILE`` tries it on your machine's design.
"""

from __future__ import annotations

import argparse
from contextlib import closing
from pathlib import Path

import numpy as np
from fill_sheet import fill, pose

from calibrators.agents import get_agent
from calibrators.measurements import Measurements
from calibrators.study.episodes import machine_seed, run_episode
from calibrators.study.labs import make_lab
from calibrators.workflow.compensate import Compensate, read_estimate, read_targets
from calibrators.workflow.fit import Fit
from calibrators.workflow.page import write_page
from calibrators.workflow.plan import Plan, Procedure
from calibrators.workflow.verify import VerificationPlan, Verify
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S
from orthoglide_env.model.design import MachineDesign, load_design
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.scoring import best_rigid_motion
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import write_machine_file

DESIGN = str(Path(__file__).resolve().parent / "designs" / "small.json")
LAB = Conditions("lab")


def draw_truth(path: Path, design: MachineDesign, seed: int) -> None:
    """The "real" machine, written to ``path``: the machine and world a lab of the design
    draws for ``calibrate --seed seed`` (a realistic machine, noisy gauges)."""
    agent = get_agent("paper-once")
    with closing(make_lab(agent, errors=DEFAULT_PRESET, gauge_sigma=DEFAULT_SIGMA,
                          gauge_resolution=DEFAULT_RESOLUTION, backend="exact",
                          thermometer=False, budget_s=DEFAULT_BUDGET_S,
                          design=design, conditions=LAB)) as env:
        episode = run_episode(env, agent, machine_seed(seed, 0))
    write_machine_file(path, episode.truth, episode.world)


def write_plan(procedure: Procedure, folder: Path, then: str) -> None:
    """Write the plan's files and page into ``folder`` and say what was written, as
    ``orthoglide plan`` does (``then``: the command that reads the filled sheet)."""
    plan, sheet = procedure.write(folder)
    page, pictures = write_page(procedure, folder, then)
    print(f"{procedure.summary()}; wrote {page}, {sheet}, {plan} and {len(pictures)} "
          "pictures")
    for note in procedure.notes:
        print(f"note: {note}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="e2e", help="folder for every file (default e2e)")
    parser.add_argument("--seed", type=int, default=5, help="the machine drawn (default 5)")
    parser.add_argument("--budget", type=float, default=1800.0,
                        help="the calibration's lab time, s (default 1800)")
    parser.add_argument("--design", default=DESIGN, metavar="FILE",
                        help="the machine's design file (default examples/designs/small.json)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth = out / "truth.json"
    design = load_design(args.design)
    draw_truth(truth, design, args.seed)
    # The technician reads the set-up's six gauges (what ``pose`` reads): no re-mount.
    procedure = Plan(design, agent="optimal-stay", conditions=LAB,
                     budget_s=args.budget).run()
    write_plan(procedure, out / "plan", "orthoglide fit readings.csv --plan plan.json")
    fill(out / "plan" / "readings.csv", truth, design, args.seed)
    readings = Measurements.read(out / "plan" / "readings.csv", design)
    calibration = Fit(readings, conditions=LAB, plan=procedure).run()
    calibration.write(out)
    for warning in calibration.estimate.warnings:
        print(f"fit warning: {warning}")
    # From here on, what the estimate file holds, as a controller's operator has it.
    estimate = read_estimate(out / "estimate.json")
    # Targets over the scoring grid's cube, inside the control limits of the small design.
    grid = np.linspace(-30.0, 30.0, 4)
    targets = np.array(np.meshgrid(grid, grid, grid, indexing="ij")).reshape(3, -1).T
    (out / "targets.csv").write_text("x,y,z\n" + "".join(
        f"{x:g},{y:g},{z:g}\n" for x, y, z in targets))
    controller = Compensate(estimate, read_targets(out / "targets.csv")).run()
    controller.write(out / "controller")
    compensation = controller.compensation
    reached = np.array([pose(truth, design, list(rho), 1)["tcp"]
                        for rho in compensation.commands])
    predicted = compensation.predicted["rigid"]
    rotation, translation = best_rigid_motion(targets[None], reached[None],
                                              np.ones((1, len(targets)), bool))
    moved = reached @ rotation[0].T + translation[0]
    rigid = np.linalg.norm(moved - targets, axis=1)
    raw = np.linalg.norm(reached - targets, axis=1)
    print(f"{len(targets)} compensated targets: TCP error after the best-fit rigid motion "
          f"{np.sqrt(np.mean(rigid**2)) * 1000:.1f} um RMS (max {rigid.max() * 1000:.1f}) "
          f"against {np.sqrt(np.mean(predicted**2)) * 1000:.1f} um predicted; raw "
          f"{np.sqrt(np.mean(raw**2)) * 1000:.1f} um RMS")
    check = VerificationPlan(estimate, agent="paper", conditions=LAB).run()
    write_plan(check, out / "verify",
               f"orthoglide verify {out / 'estimate.json'} readings.csv")
    fill(out / "verify" / "readings.csv", truth, design, args.seed + 1)
    result = Verify(estimate, Measurements.read(out / "verify" / "readings.csv",
                                                estimate.readings.design)).run()
    print(("PASSED: " if result.passed else "FAILED: ") + result.reason)


if __name__ == "__main__":
    main()
