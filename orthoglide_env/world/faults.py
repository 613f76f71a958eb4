"""Faults in the lab: which kinds can happen (``faults=``), when they do, and the record
of what happened where (the truth, for scoring only).

A lab with faults draws them from a stream of its own, seeded from the episode's stream
at reset without drawing from it: a run without faults is unchanged bit for bit, and a
run with faults takes the same readings as without until the first one.  Their rates
and sizes are in :data:`~orthoglide_env.world.table.FAULTS`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from orthoglide_env.world.table import FAULTS, Size

FAULT_KINDS: tuple[str, ...] = tuple(FAULTS)
HOUR: float = 3600.0
#: The horizon (s) a schedule is drawn over when the lab has no budget.
HORIZON_S: float = 8 * HOUR
#: Mixed into the episode stream's state to seed the fault stream (any fixed number: it
#: only has to differ from what seeds anything else).
_FAULT_TAG: int = 0x0FA17


@dataclass(frozen=True)
class Faults:
    """The kinds of fault that can happen in a lab (:data:`FAULT_KINDS`); none by
    default."""

    kinds: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.kinds, str) or not all(isinstance(k, str) for k in self.kinds):
            raise ValueError(f"faults must be a list of fault kinds, got {self.kinds!r}")
        unknown = [k for k in self.kinds if k not in FAULT_KINDS]
        if unknown:
            raise ValueError(f"unknown fault kind {unknown[0]!r}; kinds are "
                             f"{', '.join(FAULT_KINDS)}")
        object.__setattr__(self, "kinds", tuple(k for k in FAULT_KINDS if k in self.kinds))

    @property
    def active(self) -> bool:
        return bool(self.kinds)

    @property
    def label(self) -> str:
        return ",".join(self.kinds) if self.kinds else "none"


NO_FAULTS: Faults = Faults()


def as_faults(value: Any) -> Faults:
    """``value`` as :class:`Faults`: one already, None, a comma-separated string of kinds
    ("" for none) or a list of them; ``ValueError`` naming the rule otherwise."""
    if value is None:
        return NO_FAULTS
    if isinstance(value, Faults):
        return value
    if isinstance(value, str):
        return Faults(tuple(k.strip() for k in value.split(",") if k.strip()))
    if isinstance(value, list | tuple):
        return Faults(tuple(value))
    raise ValueError(f"faults must be a list of fault kinds ({', '.join(FAULT_KINDS)}), "
                     f"got {value!r}")


def size_row(kind: str, parameter: str, condition: str) -> tuple[float, float]:
    """The range of ``parameter`` (``rate`` or ``size``) of fault ``kind`` under
    ``condition`` (``ideal`` takes the ``lab`` column)."""
    row: Size = FAULTS[kind][parameter]
    return row.at("workshop" if condition == "workshop" else "lab")


@dataclass
class FaultEvent:
    """One fault that happened: its ``kind``, the lab time (s) and step it acted at, where
    (a stand and its mounting's name, or a joint), and its size (the table's unit)."""

    kind: str
    time_s: float
    step: int = -1
    stand: int = -1
    mounting: str = ""
    joint: int = -1
    size: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FaultEvent:
        return cls(**data)


def fault_stream(stream: np.random.Generator) -> np.random.Generator:
    """The fault stream of an episode whose stream is ``stream`` (nothing is drawn from
    it: its state seeds the new one)."""
    state = stream.bit_generator.state["state"]
    words = state["state"] if isinstance(state, dict) else state
    return np.random.default_rng([int(words) % 2**64, int(words) >> 64, _FAULT_TAG])


def schedule(faults: Faults, stream: np.random.Generator, condition: str,
             horizon_s: float) -> list[tuple[float, str]]:
    """When each fault of ``faults`` happens within ``horizon_s`` of lab time (s), drawn
    from ``stream``: (time, kind) in time order."""
    horizon = horizon_s if np.isfinite(horizon_s) else HORIZON_S
    events = []
    for kind in faults.kinds:
        rate = size_row(kind, "rate", condition)[0] / HOUR
        t = stream.exponential(1 / rate)
        while t < horizon:
            events.append((float(t), kind))
            t += stream.exponential(1 / rate)
    return sorted(events)


def draw_size(kind: str, stream: np.random.Generator, condition: str) -> float:
    """A size of fault ``kind`` (table unit), drawn from ``stream``."""
    row = FAULTS[kind]["size"]
    low, high = size_row(kind, "size", condition)
    value = stream.uniform(low, high)
    return float(value * stream.choice((-1.0, 1.0))) if row.signed else float(value)


def happened(events: list[dict[str, Any]]) -> list[str]:
    """The kinds of the fault ``events`` (``FaultEvent.to_dict``) that acted on something
    (a knock of no mounted stand did not), each once, in :data:`FAULT_KINDS` order."""
    acted = {e["kind"] for e in events
             if e["stand"] >= 0 or e["kind"] in ("thermal-step", "lost-steps")}
    return [k for k in FAULT_KINDS if k in acted]
