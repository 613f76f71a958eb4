"""The ``orthoglide`` command: one module per sub-command.

Each command module has ``add(subparsers)``, which declares its options and sets
``func``.  Every failure a user can cause ends in one line on stderr and exit status 2,
without a traceback.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from . import calibrate, compare, fit, pose, render
from .common import Parser, UsageError

COMMANDS = (pose, render, calibrate, fit, compare)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="orthoglide", description="Virtual Orthoglide calibration workbench.")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        for option in ("sigma", "resolution"):
            value = getattr(args, option, None)
            if value is not None and not (np.isfinite(value) and value >= 0):
                raise UsageError(f"--{option} must be a finite number >= 0")
        args.func(args)
    except (UsageError, ValueError, OSError, RuntimeError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"orthoglide {args.command}: error: {message}", file=sys.stderr)
        return 2
    return 0


__all__ = ["UsageError", "build_parser", "main"]
