"""``orthoglide conditions``: the table of the real lab's effects, their sizes under the
``lab`` and ``workshop`` conditions and their sources (docs/conditions.md shows the same), then
the instruments' own errors (``docs/instruments.md`` shows those)."""

from __future__ import annotations

import argparse

from orthoglide_env.world.table import (
    BALLBAR_LENGTHS_MM,
    BALLBAR_LENGTHS_SOURCE,
    EFFECTS,
    INSTRUMENT_ERRORS,
    STEP_GAUGE_FACES,
    STEP_GAUGE_PITCH_MM,
    STEP_GAUGE_SOURCE,
    Size,
)


def _range(low: float, high: float, signed: bool) -> str:
    sign = "+-" if signed else ""
    return f"{sign}{low:g}" if low == high else f"{sign}({low:g} to {high:g})"


def _rows(table: dict[str, dict[str, Size]], first: str) -> str:
    lines = [f"| {first} | parameter | lab | workshop | unit | what | source |",
             "|---|---|---|---|---|---|---|"]
    for effect, rows in table.items():
        for name, size in rows.items():
            lines.append(f"| {effect} | {name} | {_range(*size.lab, size.signed)} | "
                         f"{_range(*size.workshop, size.signed)} | {size.unit} | "
                         f"{size.meaning} | {size.source} |")
    return "\n".join(lines) + "\n"


def table() -> str:
    """The effects table as Markdown."""
    return _rows(EFFECTS, "effect")


def instruments_table() -> str:
    """The instruments' own errors as Markdown (an instrument the lab owns)."""
    return _rows(INSTRUMENT_ERRORS, "instrument")


def instruments_shapes() -> str:
    """The instruments' shapes, with their sources: the ballbar's lengths, the step
    gauge's faces."""
    lengths = ", ".join(f"{v:g}" for v in BALLBAR_LENGTHS_MM)
    return (f"ballbar lengths: {lengths} mm ({BALLBAR_LENGTHS_SOURCE})\n"
            f"step-gauge faces: {STEP_GAUGE_FACES}, {STEP_GAUGE_PITCH_MM:g} mm apart "
            f"({STEP_GAUGE_SOURCE})\n")


def run(args: argparse.Namespace) -> None:
    print(table(), end="")
    print()
    print(instruments_table(), end="")
    print()
    print(instruments_shapes(), end="")


def add(p: argparse.ArgumentParser) -> None:
    p.set_defaults(func=run)
