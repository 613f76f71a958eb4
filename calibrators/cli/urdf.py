"""``orthoglide urdf``: a machine's true geometry as a URDF file, for other simulators."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from calibrators.cli.common import add_machine, machine_of
from orthoglide_env.sim.urdf import write_urdf

#: ``-o -`` writes to standard output.
STDOUT = "-"


def run(args: argparse.Namespace) -> None:
    text = write_urdf(machine_of(args))
    if args.out == STDOUT:
        sys.stdout.write(text)
        return
    path = Path(args.out)
    if path.is_dir():
        raise ValueError(f"-o {path}: is a directory; give the URDF file to write")
    path.write_text(text)
    print(f"wrote {path}")


def add(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "urdf", help="write a machine's URDF (its errors baked in) for other simulators",
        description="Write the URDF of a machine, its geometric errors baked in (lengths in "
        "metres, as URDF has them). URDF holds trees only: the five loops a simulator must "
        "close (each parallelogram's second bar, the y and z legs' platform joints) are "
        "listed in a comment at the top of the file.",
    )
    add_machine(p)
    p.add_argument("-o", "--out", required=True, metavar="FILE",
                   help=f"URDF file to write, replaced if it exists ('{STDOUT}': standard "
                   "output; required)")
    p.set_defaults(func=run)
