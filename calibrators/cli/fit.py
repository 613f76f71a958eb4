"""``orthoglide fit``: calibrate a real machine from measured gauge readings."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from calibrators.cli import estimator_options
from calibrators.cli.common import (
    READINGS_CONDITIONS,
    UsageError,
    add_conditions,
    add_gauges,
    conditions_of,
    fit_conditions_of,
    given_design,
    held_design,
)
from calibrators.measurements import Measurements
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.world.conditions import Conditions

if TYPE_CHECKING:
    from calibrators.workflow.plan import Procedure


def run(args: argparse.Namespace) -> None:
    from calibrators.cli.output import emit, report, save
    from calibrators.estimators.paper_linear import NeedsExactFit
    from calibrators.workflow.fit import Fit
    from calibrators.workflow.plan import SheetError

    # --sigma and --resolution were checked with every command's (calibrators.cli.run);
    # left out, they are the plan's gauges, else the dial gauges' (Fit's).
    plan = _read_plan(args.plan) if args.plan else None
    try:
        data = Measurements.read(args.file, _design(args, plan))
    except ValueError as exc:
        if plan is None or args.design:
            raise
        Measurements.read(args.file)  # a file at fault by itself says so
        raise UsageError(f"--plan {args.plan}: the readings are of another design than the "
                         f"plan's: {str(exc).splitlines()[0]}") from None
    try:
        fit = Fit(data, estimator=estimator_options.estimator(args), sigma=args.sigma,
                  resolution=args.resolution,
                  conditions=fit_conditions_of(args, _conditions(args, plan)), plan=plan)
    except SheetError as exc:
        raise UsageError(f"--plan {args.plan}: {exc}") from None
    except NeedsExactFit as exc:
        raise estimator_options.use_exact(exc) from None
    if args.to_csv:
        data.to_csv(args.to_csv)
    try:
        est = fit.run().estimate
    except NeedsExactFit as exc:
        raise estimator_options.use_exact(exc) from None
    save(est, args)
    emit(report(est, None), args.json)


def _conditions(args: argparse.Namespace, plan: Procedure | None) -> Conditions:
    """The world the readings were taken in: the options', else the plan's (it was planned
    for it), else :data:`READINGS_CONDITIONS`."""
    given = (args.conditions, args.effects, args.indicator) != (None, None, None)
    if plan is not None and not given:
        return Conditions.from_dict(plan.conditions)
    return conditions_of(args, default=READINGS_CONDITIONS)


def _read_plan(path: str) -> Procedure:
    from calibrators.workflow.plan import Procedure

    try:
        return Procedure.read(path)
    except ValueError as exc:
        raise UsageError(f"--plan {path}: {exc}") from None


def _design(args: argparse.Namespace, plan: Procedure | None) -> MachineDesign | None:
    """The design the readings are of: ``--design``'s, else the plan's (it holds its
    design), else None (the readings file's, or the prototype); a ``--design`` other than
    the plan's is refused."""
    if plan is None:
        return given_design(args)
    return held_design(args, MachineDesign.from_dict(plan.design), "plan", args.plan)


def add(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="readings, .csv or .json (docs/measurements.md)")
    add_gauges(p, planned=True)
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the --holdout draw (default: %(default)s)")
    p.add_argument("--design", metavar="FILE", help="design of the machine the readings come "
                   "from, JSON or TOML (see docs/machines.md; default: the "
                   "readings file's, else the prototype)")
    estimator_options.add(p)
    add_conditions(p, measured=True)
    p.add_argument("--plan", metavar="PLAN.json",
                   help="the plan.json of orthoglide plan whose readings sheet this is: each "
                        "row is checked against its step")
    p.add_argument("--to-csv", metavar="FILE.csv",
                   help="also write the readings as CSV (shortest round-trip numbers)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)
