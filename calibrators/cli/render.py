"""``orthoglide render``: a PNG picture of a machine at a posture."""

from __future__ import annotations

import argparse

from calibrators.cli.common import add_machine_posture, machine_of, rho_of


def run(args: argparse.Namespace) -> None:
    machine = machine_of(args)
    rho = rho_of(args.rho, machine.design)
    from orthoglide_env.sim.report import render_png

    path = render_png(machine, rho, args.out)
    print(f"wrote {path}")


def add(p: argparse.ArgumentParser) -> None:
    add_machine_posture(p)
    p.add_argument("--out", required=True, metavar="FILE", help="PNG file to write, "
                   "replaced if it exists (required)")
    p.set_defaults(func=run)
