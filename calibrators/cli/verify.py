"""``orthoglide verify``: the paper's third experiment, readings through the compensated
controller held against the estimate's prediction."""

from __future__ import annotations

import argparse
import json

from calibrators.cli.common import READINGS_CONDITIONS, add_conditions, conditions_of


def run(args: argparse.Namespace) -> None:
    from calibrators.measurements import Measurements
    from calibrators.workflow.compensate import read_estimate
    from calibrators.workflow.verify import Verify

    est = read_estimate(args.estimate)
    data = Measurements.read(args.readings, est.readings.design)
    given = args.conditions is not None or args.effects is not None
    result = Verify(est, data, conditions_of(args, default=READINGS_CONDITIONS) if given
                    else None, check_world=args.check_world).run()
    if args.json:
        print(json.dumps(result.to_dict()))
        return
    print(f"{'mounting':<16}{'posture':<22}{'before':>10}{'after':>10}{'predicted':>11}"
          f"{'residual':>10}   (mm: each mounting's readings minus its first)")
    for r in result.rows:
        print(f"{r['mounting']:<16}{r['posture']:<22}{r['before_mm']:>10.4f}"
              f"{r['after_mm']:>10.4f}{r['predicted_mm']:>11.4f}{r['residual_mm']:>10.4f}")
    print(("PASSED: " if result.passed else "FAILED: ") + result.reason)


def add(p: argparse.ArgumentParser) -> None:
    p.description = ("Read the filled sheet of 'orthoglide plan --verify EST' and report, per "
        "reading, the leg-parallelism deviation before compensation (the estimated machine "
        "at the uncompensated commands), after it (the readings), the predicted one and the "
        "residual, then pass or fail: a chi-square test of the readings against the "
        "estimate's prediction, with its error bars, the new stands' installation errors, "
        "the conditions' effects and the instruments' noise.  The readings may be any "
        "instrument's (the file's instrument column): a tracker's frame and a ballbar's "
        "pivot are unknowns, as in the fit.")
    p.add_argument("estimate", help="estimate file (calibrate or fit --save-estimate)")
    p.add_argument("readings", help="the verification's readings, .csv or .json")
    add_conditions(p, measured=True)
    p.add_argument("--check-world", action="store_true",
                   help="also fit the readings told the conditions and fail when they show a "
                        "world worse than those (the estimate's error bars are then too "
                        "narrow; see docs/world.md)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: passed, reason, chi2, dof, "
                        "deviations_before, deviations_after, readings")
    p.set_defaults(func=run)
