"""Conditions: which of the real lab's effects act, and at which size.

``ideal`` has none (the textbook machine, today's numbers bit for bit); ``lab`` and
``workshop`` have every effect of :data:`~orthoglide_env.world.table.EFFECTS` at their
sizes.  Any effect can be switched off on its own (``effects``), so each can be studied
alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from orthoglide_env.world.table import EFFECTS

CONDITION_NAMES: tuple[str, ...] = ("ideal", "lab", "workshop")
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
DEFAULT_CONDITIONS: str = "ideal"


@dataclass(frozen=True)
class Conditions:
    """The world a lab's machines live in: ``name`` (:data:`CONDITION_NAMES`) and the
    ``effects`` that act (all of the name's when None; none under ``ideal``)."""

    name: str = DEFAULT_CONDITIONS
    effects: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or self.name not in CONDITION_NAMES:
            raise ValueError(f"unknown conditions {self.name!r}; choose from "
                             f"{list(CONDITION_NAMES)}")
        if self.effects is None:
            on = () if self.name == "ideal" else EFFECT_NAMES
        else:
            if isinstance(self.effects, str) or not all(isinstance(e, str)
                                                        for e in self.effects):
                raise ValueError(f"effects must be a list of effect names, got "
                                 f"{self.effects!r}")
            unknown = sorted(set(self.effects) - set(EFFECT_NAMES))
            if unknown:
                raise ValueError(f"unknown effect(s) {unknown}; effects are "
                                 f"{list(EFFECT_NAMES)}")
            if self.name == "ideal" and self.effects:
                raise ValueError("the ideal conditions have no effects: name 'lab' or "
                                 "'workshop' for their sizes")
            on = tuple(e for e in EFFECT_NAMES if e in self.effects)
        object.__setattr__(self, "effects", on)

    def __contains__(self, effect: str) -> bool:
        return effect in self.effects  # type: ignore[operator]

    @property
    def active(self) -> bool:
        """Whether any effect acts (else the lab draws nothing for the world)."""
        return bool(self.effects)

    def size(self, effect: str, parameter: str) -> tuple[float, float]:
        """The range (table units) of ``parameter`` of ``effect`` under these conditions."""
        return EFFECTS[effect][parameter].at(self.name)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "effects": list(self.effects)}  # type: ignore[arg-type]

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Conditions:
        unknown = sorted(set(data) - {"name", "effects"})
        if unknown:
            raise ValueError(f"unknown conditions key(s) {unknown}; keys are name, effects")
        effects = data.get("effects")
        return cls(data.get("name", DEFAULT_CONDITIONS),
                   tuple(effects) if isinstance(effects, list | tuple) else effects)

    @property
    def label(self) -> str:
        """``lab``, or ``lab[lead,room]`` when only some effects act."""
        full = self.effects == (() if self.name == "ideal" else EFFECT_NAMES)
        return self.name if full else f"{self.name}[{','.join(self.effects)}]"  # type: ignore[arg-type]


def as_conditions(value: Any) -> Conditions:
    """``value`` as :class:`Conditions`: one already, a name, or a ``to_dict`` mapping;
    ``ValueError`` naming the rule otherwise."""
    if isinstance(value, Conditions):
        return value
    if isinstance(value, str):
        return Conditions(value)
    if isinstance(value, dict):
        return Conditions.from_dict(value)
    raise ValueError(f"conditions must be one of {list(CONDITION_NAMES)}, a Conditions or "
                     f"a dict with name and effects, got {value!r}")


#: The textbook world: no effect beyond the geometry.
IDEAL: Conditions = Conditions()
