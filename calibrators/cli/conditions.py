"""``orthoglide conditions``: the table of the real lab's effects, their sizes under the
``lab`` and ``workshop`` conditions and their sources (docs/conditions.md shows the same)."""

from __future__ import annotations

import argparse

from orthoglide_env.world.table import EFFECTS


def _range(low: float, high: float, signed: bool) -> str:
    sign = "+-" if signed else ""
    return f"{sign}{low:g}" if low == high else f"{sign}({low:g} to {high:g})"


def table() -> str:
    """The effects table as Markdown."""
    lines = ["| effect | parameter | lab | workshop | unit | what | source |",
             "|---|---|---|---|---|---|---|"]
    for effect, rows in EFFECTS.items():
        for name, size in rows.items():
            lines.append(f"| {effect} | {name} | {_range(*size.lab, size.signed)} | "
                         f"{_range(*size.workshop, size.signed)} | {size.unit} | "
                         f"{size.meaning} | {size.source} |")
    return "\n".join(lines) + "\n"


def run(args: argparse.Namespace) -> None:
    print(table(), end="")


def add(p: argparse.ArgumentParser) -> None:
    p.set_defaults(func=run)
