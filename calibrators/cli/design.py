"""``orthoglide design``: a machine design as JSON, every key given (the prototype's, or a
design file's completed with the prototype's values)."""

from __future__ import annotations

import argparse

from calibrators.cli.common import STDOUT, machine_design_of, write_output


def run(args: argparse.Namespace) -> None:
    text = machine_design_of(args).to_json()
    write_output(args.out, text, "design")


def add(p: argparse.ArgumentParser) -> None:
    p.description = ("Print a machine design as JSON, every key given: the prototype's, or "
        "with --design the file's, its left-out keys filled in. A copy is a starting point "
        "for a design file of another machine (see docs/machines.md, 'Machine designs').")
    p.add_argument("--design", metavar="FILE",
                   help="design file (JSON or TOML) to complete and print instead")
    p.add_argument("-o", "--out", default=STDOUT, metavar="FILE",
                   help=f"JSON file to write, replaced if it exists (default '{STDOUT}': "
                   "standard output)")
    p.set_defaults(func=run)
