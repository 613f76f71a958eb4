"""``orthoglide compensate``: from an estimate file to the values a controller takes."""

from __future__ import annotations

import argparse
import json

import numpy as np

from calibrators.workflow.compensate import (
    TARGET_COLUMNS,
    Compensate,
    read_estimate,
    read_targets,
)


def run(args: argparse.Namespace) -> None:
    est = read_estimate(args.estimate)
    controller = Compensate(est, read_targets(args.targets) if args.targets else None).run()
    written = controller.write(args.out)
    if args.json:
        print(json.dumps({"joint_offsets": controller.joint_offsets(),
                          "targets": controller.targets(),
                          "files": [str(p) for p in written]}))
        return
    for path in written:
        print(f"wrote {path}")
    print("joint offsets (drho, mm): " + ", ".join(
        f"{axis} {value:+.4f}" for axis, value in zip("xyz", est.theta[:3], strict=True)))
    if controller.compensation is not None:
        rigid = controller.compensation.predicted["rigid"]
        print(f"{len(rigid)} targets: predicted error after the best-fit rigid motion "
              f"{np.sqrt(np.mean(rigid**2)):.4f} mm RMS, {rigid.max():.4f} mm at most "
              "(raw and after translation in commands.csv)")


def add(p: argparse.ArgumentParser) -> None:
    p.description = ("Write, into --out, what a controller takes from a calibration: "
        "joint_offsets.csv (axis, drho_mm, sigma_mm: the encoder offsets the paper put into "
        "its control software), pitch_table.csv and backlash.csv when the fit has them "
        "(--params full), machine.json and machine.urdf (the calibrated machine) and, with "
        "--targets, commands.csv: per target the commands rho (mm) that put the tool there "
        "(the estimated machine's inverse kinematics less the pitch-error table's value) "
        "and its predicted error raw, after translation and after the best-fit rigid "
        "motion over the targets (mm).")
    p.add_argument("estimate", help="estimate file (calibrate or fit --save-estimate)")
    p.add_argument("--targets", metavar="FILE.csv",
                   help=f"tool targets, one per line, columns {','.join(TARGET_COLUMNS)} "
                        "(mm, world frame)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder to write into (made if missing; files are replaced)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: joint_offsets, targets (each with target, "
                        "command and predicted_raw_mm, predicted_translation_mm, "
                        "predicted_rigid_mm) and the files written")
    p.set_defaults(func=run)
