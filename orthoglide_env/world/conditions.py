"""Conditions: which of the real lab's effects act, and at which size.

``ideal`` has none (the textbook machine); ``lab`` and ``workshop`` have every effect of
:data:`~orthoglide_env.world.table.EFFECTS` at their sizes.  ``lab`` is the default of
every command and env (:data:`DEFAULT_CONDITIONS`): the textbook world flatters every
strategy, so it is asked for by name.  Any effect can be switched off on its own
(``effects``), so each can be studied alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from orthoglide_env.world.table import EFFECTS, SCALES

CONDITION_NAMES: tuple[str, ...] = ("ideal", "lab", "workshop")
#: What a fit may be told in place of a name: estimate the world from the readings
#: (:mod:`calibrators.estimators.world_sizes`); a lab's world always has a name.
AUTO: str = "auto"
#: The gauges' indicators: mechanical dials (ISO 463) or digital ones.
INDICATORS: tuple[str, ...] = ("dial", "digital")
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
#: The drives: semi-closed loop on ball screws (encoders on the motors) or closed loop on
#: linear scales (:data:`~orthoglide_env.world.table.SCALES`).
DRIVES: tuple[str, ...] = ("screw", "scales")
#: What linear scales take away from the drives' rows of the table (their range is 0);
#: the lead error's linear part becomes the scale's grade.
_SCALED_OFF: frozenset[tuple[str, str]] = frozenset({
    ("lead", "curve"), ("lead", "periodic"), ("backlash", "lost_motion"),
    ("warmup", "amplitude")})
#: The world of every command and env that is not told one: the real lab, since the
#: textbook world (``ideal``) flatters every gauge strategy 1.5-3x and the tracker 3-4x
#: (docs/benchmarks.md); ``ideal`` is asked for by name.
DEFAULT_CONDITIONS: str = "lab"


@dataclass(frozen=True)
class Conditions:
    """The world a lab's machines live in: ``name`` (:data:`CONDITION_NAMES`), the
    ``effects`` that act (all of the name's when None; none under ``ideal``) and the
    gauges' ``indicator`` (:data:`INDICATORS`: its error curve is the ``dial`` effect's
    ``digital_*`` rows for a digital one) and the ``drives`` (:data:`DRIVES`: with
    ``scales`` the lead error's rows are the scale's grade, and its curve, periodic error,
    warm-up and the nut's lost motion are 0)."""

    name: str
    effects: tuple[str, ...] | None = None
    indicator: str = "dial"
    drives: str = "screw"

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
        if not isinstance(self.indicator, str) or self.indicator not in INDICATORS:
            raise ValueError(f"unknown indicator {self.indicator!r}; choose from "
                             f"{list(INDICATORS)}")
        if not isinstance(self.drives, str) or self.drives not in DRIVES:
            raise ValueError(f"unknown drives {self.drives!r}; choose from {list(DRIVES)}")
        if self.drives != "screw" and self.name == "ideal":
            raise ValueError("the ideal conditions' drives are exact: name 'lab' or "
                             "'workshop' for linear scales' errors")
        if self.indicator != "dial" and "dial" not in on:
            raise ValueError(f"a {self.indicator} indicator's errors are the dial effect's: "
                             f"name 'lab' or 'workshop' with the dial effect on")
        object.__setattr__(self, "effects", on)

    def __contains__(self, effect: str) -> bool:
        return effect in self.effects  # type: ignore[operator]

    @property
    def active(self) -> bool:
        """Whether any effect acts (else the lab draws nothing for the world)."""
        return bool(self.effects)

    def size(self, effect: str, parameter: str) -> tuple[float, float]:
        """The range (table units) of ``parameter`` of ``effect`` under these conditions
        (with linear scales, the drives' rows they change)."""
        if self.drives == "scales":
            if (effect, parameter) in _SCALED_OFF:
                return (0.0, 0.0)
            if (effect, parameter) == ("lead", "scale"):
                return SCALES["grade"].at(self.name)
        return EFFECTS[effect][parameter].at(self.name)

    def to_dict(self) -> dict[str, Any]:
        out = {"name": self.name, "effects": list(self.effects),  # type: ignore[arg-type]
               "indicator": self.indicator}
        if self.drives != "screw":  # (files of screw drives read as they always did)
            out["drives"] = self.drives
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Conditions:
        unknown = sorted(set(data) - {"name", "effects", "indicator", "drives"})
        if unknown:
            raise ValueError(f"unknown conditions key(s) {unknown}; keys are name, effects, "
                             "indicator, drives")
        effects = data.get("effects")
        return cls(data.get("name", DEFAULT_CONDITIONS),
                   tuple(effects) if isinstance(effects, list | tuple) else effects,
                   data.get("indicator", "dial"), data.get("drives", "screw"))

    @property
    def label(self) -> str:
        """``lab``, or ``lab[lead,room]`` when only some effects act; ``+digital`` with
        digital indicators, ``+scales`` with closed-loop drives."""
        full = self.effects == (() if self.name == "ideal" else EFFECT_NAMES)
        label = self.name if full else f"{self.name}[{','.join(self.effects)}]"  # type: ignore[arg-type]
        label = label if self.indicator == "dial" else f"{label}+{self.indicator}"
        return label if self.drives == "screw" else f"{label}+{self.drives}"


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
                     f"a dict with name, effects and indicator, got {value!r}")


#: The textbook world: no effect beyond the geometry.
IDEAL: Conditions = Conditions("ideal")
