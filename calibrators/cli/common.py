"""What several commands share: the parser class, usage errors, machine and noise options."""

from __future__ import annotations

import argparse
from typing import NoReturn

import numpy as np

from orthoglide_env.gauges import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.geometry import MachineParams, check_rho, random_machine


class UsageError(Exception):
    """Bad input from the user: reported in one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """Reports a bad command line in one line (argparse adds a usage block; ``-h`` has it)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def machine_of(args: argparse.Namespace) -> MachineParams:
    if getattr(args, "machine", None):
        return MachineParams.from_json(args.machine)
    return random_machine(args.seed, args.errors)


def rho_of(values: list[float]) -> np.ndarray:
    return check_rho(np.array(values, dtype=float))


def vec(values: list[float], digits: int) -> str:
    return "(" + ", ".join(f"{v:.{digits}f}" for v in values) + ")"


def noise_of(args: argparse.Namespace) -> tuple[float, float]:
    if args.noise_free:
        return 0.0, 0.0
    return (DEFAULT_SIGMA if args.sigma is None else args.sigma), DEFAULT_RESOLUTION


def add_noise_options(p: argparse.ArgumentParser) -> None:
    group = p.add_mutually_exclusive_group()
    group.add_argument("--noise-free", action="store_true", help="ideal gauges")
    group.add_argument("--sigma", type=float, default=None,
                       help=f"gauge repeatability (mm, default {DEFAULT_SIGMA})")


def add_machine_posture(p: argparse.ArgumentParser) -> None:
    p.add_argument("--machine", required=True, help="machine JSON file")
    p.add_argument("--rho", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                   help="joint targets, control coordinates (mm)")
