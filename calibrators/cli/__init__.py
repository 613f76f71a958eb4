"""The ``orthoglide`` command: one module per sub-command.

Each command module has ``add(parser)``, which declares its options and sets
``func``.  Every failure a user can cause ends in one line on stderr and exit status 2,
without a traceback; so does Ctrl-C, with status 130.  A reader that stops early
(``orthoglide ... | head``) ends the command quietly, with status 1 as Python's own recipe
for a broken pipe has it.

A command's module imports at its top what its options need, and what the command runs
with in its ``run``: ``orthoglide --help``, ``--version`` and most commands' ``--help``
start without SciPy, Gymnasium or PyBullet (``tests/test_startup.py``).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from types import ModuleType

try:
    from calibrators.cli.parser import Parser, UsageError
except KeyboardInterrupt:
    # Ctrl-C while the command line loads (the console script imports this package
    # before main runs): one line and SIGINT's status, as main gives.
    print("orthoglide: interrupted", file=sys.stderr)
    raise SystemExit(130) from None

#: Each command, in the order ``orthoglide --help`` lists them, with its line there.  A
#: command's module (``calibrators.cli.NAME``: its options and what it does) is imported
#: only when the command is asked for, so that ``--help``, ``--version`` and a quick
#: command do not pay for the others' imports (SciPy, Gymnasium, PyBullet).
COMMANDS: dict[str, str] = {
    "pose": "simulate one posture of a machine and read its gauges",
    "render": "write a PNG picture of a machine at a posture",
    "urdf": "write a machine's URDF (its errors baked in) for other simulators",
    "calibrate": ("calibrate a virtual machine: an agent's experiment in the lab, then one "
                  "estimator"),
    "plan": ("write a designed experiment as a procedure a technician follows: steps, stand "
             "places, pictures, a readings sheet and a printable page"),
    "session": ("a sequential experiment with a person or a script at the machine: says each step, "
                "reads the readings typed in, says the next"),
    "fit": "calibrate a real machine from measured gauge readings",
    "compensate": ("the controller's values from an estimate file: compensated commands, joint "
                   "offsets, pitch-error tables, backlash, the calibrated machine"),
    "verify": ("the paper's third experiment: a verification run's readings through the "
               "compensated controller against the estimate's prediction"),
    "compare": "agents x estimators on the same random machines, at an equal time budget",
    "design": "print a machine design as JSON (default: the prototype's)",
    "conditions": ("print the table of the lab's and the workshop's effects, with their sizes and "
                   "sources (Markdown)"),
}
#: The distribution whose metadata carries the version.
DISTRIBUTION = "orthoglide-workbench"


def version() -> str:
    """The installed package's version (from its metadata, the one place it is set)."""
    from importlib import metadata

    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "unknown (the package is not installed)"


class _Version(argparse.Action):
    """``--version``: the version read from the package's metadata when it is asked for,
    not on every start-up (a command, its ``--help``) as argparse's own action has it."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=default,
                         help=help or "show program's version number and exit")

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        formatter = parser._get_formatter()
        formatter.add_text(f"{parser.prog} {version()}")
        parser._print_message(formatter.format_help(), sys.stdout)
        parser.exit()


def command_module(name: str) -> ModuleType:
    """The module of command ``name`` (imported now, if it was not)."""
    return importlib.import_module(f"{__name__}.{name}")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line; with ``only``, the options of that command alone (the
    others are listed, their modules not imported: what one run needs)."""
    parser = Parser(prog="orthoglide", description="Virtual Orthoglide calibration workbench.")
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", required=True)
    for name, summary in COMMANDS.items():
        p = sub.add_parser(name, help=summary)
        if only is None or name == only:
            command_module(name).add(p)
    return parser


def _command(argv: list[str]) -> str:
    """The command ``argv`` names ('' when none: the top-level options alone)."""
    return next((a for a in argv if not a.startswith("-")), "")


def run(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the command; a user's mistake is one line and status 2."""
    argv = sys.argv[1:] if argv is None else list(argv)
    command = _command(argv)
    parser = build_parser(command if command in COMMANDS else "")
    args = parser.parse_args(argv)
    try:
        # Imported once the command line is parsed: --help and --version need none of it.
        from calibrators.study.engines import imports_kept
        from orthoglide_env.instruments.dial import (
            DEFAULT_RESOLUTION,
            DEFAULT_SIGMA,
            check_noise,
        )

        sigma, resolution = (getattr(args, name, None) for name in ("sigma", "resolution"))
        check_noise(DEFAULT_SIGMA if sigma is None else sigma,
                    DEFAULT_RESOLUTION if resolution is None else resolution,
                    names=("--sigma", "--resolution"))
        with imports_kept():
            args.func(args)
    except BrokenPipeError:
        raise  # an OSError, but no mistake of the user's: main ends quietly
    except (UsageError, ValueError, OSError, RuntimeError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"orthoglide {args.command}: error: {message}", file=sys.stderr)
        return 2
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
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
    except KeyboardInterrupt:
        # Ctrl-C before a command handles it itself (while its modules load, say): one
        # line and the shell's status for SIGINT, no traceback.
        print(" ".join(("orthoglide", _command(argv))).strip() + ": interrupted",
              file=sys.stderr)
        return 130


__all__ = ["COMMANDS", "UsageError", "build_parser", "command_module", "main", "version"]
