"""Every instrument a lab may own, by the name commands and envs use, and the check of a
lab's list of them (each instrument's model is its own module beside this one)."""

from __future__ import annotations

from collections.abc import Iterable

#: Every instrument a lab may own, by the name commands and envs use.
INSTRUMENT_NAMES: tuple[str, ...] = ("dial", "interferometer", "step-gauge", "ballbar",
                                     "tracker")


def check_instruments(names: Iterable[str]) -> tuple[str, ...]:
    """``names`` in :data:`INSTRUMENT_NAMES` order, or ``ValueError`` naming an unknown
    one, or a lab without its dial gauges (its stands carry them)."""
    names = list(names)
    if not names or not all(isinstance(n, str) for n in names):
        raise ValueError(f"instruments must be a list of names from "
                         f"{list(INSTRUMENT_NAMES)}, got {names!r}")
    unknown = [n for n in names if n not in INSTRUMENT_NAMES]
    if unknown:
        raise ValueError(f"unknown instrument(s) {unknown}; instruments are "
                         f"{', '.join(INSTRUMENT_NAMES)}")
    if "dial" not in names:
        raise ValueError("instruments must include 'dial': the lab's stands carry dial "
                         "gauges")
    return tuple(n for n in INSTRUMENT_NAMES if n in names)
