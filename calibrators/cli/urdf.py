"""``orthoglide urdf``: a machine's true geometry as a URDF file, for other simulators."""

from __future__ import annotations

import argparse

from calibrators.cli.common import STDOUT, add_machine, machine_of, write_output
from orthoglide_env.sim.urdf import write_urdf


def run(args: argparse.Namespace) -> None:
    text = write_urdf(machine_of(args))
    write_output(args.out, text, "URDF")


def add(p: argparse.ArgumentParser) -> None:
    p.description = ("Write the URDF of a machine, its geometric errors baked in (lengths in "
        "metres, as URDF has them). URDF holds trees only: the five loops a simulator must "
        "close (each parallelogram's second bar, the y and z legs' platform joints) are "
        "listed in a comment at the top of the file.")
    add_machine(p)
    p.add_argument("-o", "--out", required=True, metavar="FILE",
                   help=f"URDF file to write, replaced if it exists ('{STDOUT}': standard "
                   "output; required)")
    p.set_defaults(func=run)
