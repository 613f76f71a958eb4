"""The ``orthoglide`` command: one module per sub-command.

Each command module has ``add(subparsers)``, which declares its options and sets
``func``.  Every failure a user can cause ends in one line on stderr and exit status 2,
without a traceback.  A reader that stops early (``orthoglide ... | head``) ends the
command quietly, with status 1 as Python's own recipe for a broken pipe has it.
"""

from __future__ import annotations

import argparse
import os
import sys
from importlib import metadata

from calibrators.cli import (
    calibrate,
    compare,
    compensate,
    conditions,
    design,
    fit,
    plan,
    pose,
    render,
    session,
    urdf,
    verify,
)
from calibrators.cli.common import Parser, UsageError
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA, check_noise

COMMANDS = (pose, render, urdf, calibrate, plan, session, fit, compensate, verify, compare,
            design, conditions)
#: The distribution whose metadata carries the version.
DISTRIBUTION = "orthoglide-workbench"


def version() -> str:
    """The installed package's version (from its metadata, the one place it is set)."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "unknown (the package is not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="orthoglide", description="Virtual Orthoglide calibration workbench.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add(sub)
    return parser


def run(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the command; a user's mistake is one line and status 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        sigma, resolution = (getattr(args, name, None) for name in ("sigma", "resolution"))
        check_noise(DEFAULT_SIGMA if sigma is None else sigma,
                    DEFAULT_RESOLUTION if resolution is None else resolution,
                    names=("--sigma", "--resolution"))
        args.func(args)
    except BrokenPipeError:
        raise  # an OSError, but no mistake of the user's: main ends quietly
    except (UsageError, ValueError, OSError, RuntimeError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"orthoglide {args.command}: error: {message}", file=sys.stderr)
        return 2
    return 0


def main(argv: list[str] | None = None) -> int:
    try:
        try:
            return run(argv)
        finally:
            # Flushed here, so that a reader gone away is seen here and not at exit.
            sys.stdout.flush()
    except BrokenPipeError:
        # Python's documented recipe: further writes (the interpreter's own flush at exit)
        # go to devnull instead of failing again with a traceback.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


__all__ = ["COMMANDS", "UsageError", "build_parser", "main", "version"]
