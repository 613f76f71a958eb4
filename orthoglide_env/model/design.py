"""A machine design: the nominal dimensions of an Orthoglide-type machine, as data.

A :class:`MachineDesign` holds what the drawings of a machine say and what its controller
enforces: the leg length ``L``, the parallelogram width ``d``, the tool offset ``r``, the
control limits, the shapes of the links (the gauges' targets), the dial gauges' travel,
the places along a bar where a stand can aim (the slot catalogue's rule) and the range of
geometric errors within which the simulator and the exact model agree.  Units: mm, rad.

The prototype of the paper is the default design; its numbers live in one file shipped
with the package (``prototype.json`` next to this module) and nowhere else.  A design
file (JSON or TOML, ``--design FILE``) gives any of its keys; keys left out take the
prototype's values, except that validity lengths left out scale with ``L``.  Every key
(here the dimensions of ``examples/designs/small.json``, the rest the prototype's)::

    {
      "L": 250.0, "d": 60.0, "r": 25.0,          leg length, width, tool offset (mm)
      "rho_min": -80.0, "rho_max": 50.0,          control limits (mm, 0 at Zero)
      "urdf_margin": 50.0,                        URDF prismatic limits beyond them (mm):
                                                  PyBullet's motors clamp targets to them
      "bar_section": [10.0, 10.0],                bar cross-section (hinge, normal) (mm)
      "bar_clearance": 10.0,                      bar box stops short of each hinge (mm)
      "short_link_size": [20, 20, 100],           parallelogram short links (leg frame, mm)
      "carriage_size": [70, 60, 110],             carriage box (leg frame, mm)
      "carriage_setback": 10.0,                   carriage starts this far behind R1 (mm):
                                                  it and its guideway stay behind R1 at any
                                                  travel, clear of the bars leaving R1
      "platform_size": 55.0,                      platform cube's edge (mm)
      "gauge_travel": 10.0,                       dial gauges' plunger travel (mm)
      "slot_positions": [0.2, 0.35, 0.5, 0.65, 0.8],  bar slots, fraction from the platform
                                                  (the lab's are the prototype's)
      "grid_range": [-80.0, 50.0],                TCP cube of the scoring grid, each axis (mm)
      "validity": {"drho": 10, "dL": 10, "axis_tilt": 0.02, "axis_offset": 5, "attach": 3}
    }                                             (the prototype's: see VALIDITY_UNITS)

Every key's type and range is checked in one place (:data:`RULES`, :data:`VALIDITY_RULE`,
:func:`_relations`); a refusal is one line naming the key and the rule, and from a file the
file and line.
"""

from __future__ import annotations

import itertools
import json
import math
import numbers
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from orthoglide_env.model.userfile import (
    UserFileError,
    load_user_file,
    read_user_file,
    short_repr,
)


class DesignError(UserFileError):
    """A design (file or dict) that does not describe a machine."""


#: The validity range: a machine's errors are within +-limit (unit) of its design, group by
#: group (the machine file's keys), where the simulator and the exact model agree.  Beyond
#: it the PyBullet machine and the exact model part, and more and more of the joint cube
#: cannot be assembled at all.
#:
#: How the prototype's limits were chosen (``benchmarks/validity.py``; 15 random postures across the
#: joint cube and 15 within 8 mm of Zero per machine; gauges compared where both sides
#: call them valid):
#:
#: * one group at a time, 20 machines per size with every error of the group at +-size
#:   (random signs), the first size at which the backends part by more than 1 µm:
#:   drho 50 mm (readings 950 µm apart), dL 30 mm (200 µm), axis_offset 30 mm (47 µm),
#:   attach 20 mm (117 µm); axis_tilt still agrees at 0.1 rad (0.4 µm);
#: * the limits: drho and dL at 5 standard deviations of the ``paper`` and ``realistic``
#:   presets, the extended errors at 10 (so both presets lie well inside), each far
#:   below its group's own breaking size;
#: * every group at its limit at once, 150 machines (4500 postures): TCP within 0.3 µm,
#:   gauge status identical everywhere, readings within 1 µm at every posture near Zero.
#:   Far from Zero, 2 of the 2250 postures had a gauge whose ray grazes a bar's edge on
#:   the way to its face, which PyBullet rounds: 5 and 10 µm there.
#:
#: Outside this guarantee whatever the errors: the corner (60, 60, 60) of the joint cube
#: lies near a singularity, where the simulated machine sags under gravity while the exact
#: model is rigid (0.15 µm on the nominal machine, above 1 µm on 2 and 3 of 200 realistic
#: and paper machines, up to 12 µm at the corners of this range), and beyond which a
#: machine with long encoder offsets or short legs cannot be assembled (the env refuses
#: such targets).
#:
#: Another design's range is its own; left out of its file, its lengths scale with L.
#: The error groups the validity range bounds, with their units.
VALIDITY_UNITS: dict[str, str] = {
    "drho": "mm", "dL": "mm", "axis_tilt": "rad", "axis_offset": "mm", "attach": "mm",
}


@dataclass(frozen=True)
class Rule:
    """What a design key holds: one number (``size`` None), a list of ``size`` numbers, or
    (``size`` 0) a list of one or more; each above ``low`` (at least, when ``closed``) and
    at most ``high``."""

    size: int | None = None
    low: float | None = 0.0
    high: float | None = None
    closed: bool = False
    unit: str = "mm"

    def text(self) -> str:
        """The rule in words, for a refusal."""
        bounds = []
        if self.low is not None:
            bounds.append(f"{'>=' if self.closed else '>'} {self.low:g}")
        if self.high is not None:
            bounds.append(f"{'<=' if self.closed else '<'} {self.high:g}")
        what = ("a number" if self.size is None else
                "a list of one or more numbers" if self.size == 0 else
                f"a list of {self.size} numbers")
        if not bounds:
            return f"{what} ({self.unit})"
        each = "" if self.size is None else "each "
        return f"{what}, {each}{' and '.join(bounds)} ({self.unit})"

    def holds(self, value: float) -> bool:
        if self.low is not None and not (value >= self.low if self.closed else value > self.low):
            return False
        return self.high is None or (value <= self.high if self.closed else value < self.high)


#: Every key of a design and its rule, in file order.
RULES: dict[str, Rule] = {
    "L": Rule(),
    "d": Rule(),
    "r": Rule(closed=True),
    "rho_min": Rule(low=None, high=0.0),
    "rho_max": Rule(),
    "urdf_margin": Rule(),
    "bar_section": Rule(size=2),
    "bar_clearance": Rule(closed=True),
    "short_link_size": Rule(size=3),
    "carriage_size": Rule(size=3),
    "carriage_setback": Rule(closed=True),
    "platform_size": Rule(),
    "gauge_travel": Rule(),
    # The gauge's own rule for a place along a bar (GaugeSpec.at).
    "slot_positions": Rule(size=0, low=0.05, high=0.95, closed=True,
                           unit="fraction of the leg from the platform end"),
    "grid_range": Rule(size=2, low=None),
}
#: The rule of the ``validity`` key, an object of limits by machine key.
VALIDITY_RULE: str = ("an object of the machine keys drho, dL, axis_tilt, axis_offset, attach, "
                      "each a number > 0 (mm; rad for axis_tilt)")
#: Every key of a design, in file order.
KEYS: tuple[str, ...] = (*RULES, "validity")


def _relations(design: MachineDesign) -> list[tuple[tuple[str, ...], bool, str]]:
    """Rules between keys: (the keys, whether it holds, the rule)."""
    positions = design.slot_positions
    return [
        (("rho_max", "L"), design.rho_max < design.L,
         f"rho_max ({design.rho_max:g} mm) must be below L ({design.L:g} mm): the XMax "
         "posture has sin(alpha) = rho_max / L"),
        (("rho_min", "L"), -design.rho_min < design.L,
         f"-rho_min ({-design.rho_min:g} mm) must be below L ({design.L:g} mm): the XMin "
         "posture has sin(alpha) = rho_min / L"),
        (("d", "L"), design.d < 2 * design.L,
         f"d ({design.d:g} mm) must be below 2 L ({2 * design.L:g} mm)"),
        (("bar_clearance", "L"), design.bar_clearance < design.L / 2,
         f"bar_clearance ({design.bar_clearance:g} mm) must be below L / 2 "
         f"({design.L / 2:g} mm)"),
        (("grid_range",), design.grid_range[0] < design.grid_range[1],
         "grid_range must run from a lower to a higher bound"),
        (("slot_positions",), all(a < b for a, b in itertools.pairwise(positions)),
         "slot_positions must be strictly increasing"),
    ]



@dataclass(frozen=True)
class MachineDesign:
    """The nominal design of an Orthoglide-type machine (see the module docstring for the
    keys, their units and rules).  Build one with :meth:`from_dict` or :meth:`from_file`
    (keys left out take the prototype's values) or take :data:`PROTOTYPE`."""

    L: float
    d: float
    r: float
    rho_min: float
    rho_max: float
    urdf_margin: float
    bar_section: tuple[float, float]
    bar_clearance: float
    short_link_size: tuple[float, float, float]
    carriage_size: tuple[float, float, float]
    carriage_setback: float
    platform_size: float
    gauge_travel: float
    slot_positions: tuple[float, ...]
    grid_range: tuple[float, float]
    #: Validity limits in :data:`VALIDITY_UNITS` order.
    validity: tuple[float, float, float, float, float]

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            object.__setattr__(self, f.name, _validity(value) if f.name == "validity"
                               else _numbers(f.name, value, RULES[f.name]))
        for keys, holds, rule in _relations(self):
            if not holds:
                raise DesignError(f"design: {rule}", key=keys[0])

    @property
    def validity_range(self) -> dict[str, tuple[float, str]]:
        """The machines this design's simulator and exact model agree on: every error of a
        group within +-limit (unit), by machine key."""
        return {key: (limit, unit) for (key, unit), limit
                in zip(VALIDITY_UNITS.items(), self.validity, strict=True)}

    # -- (de)serialisation ---------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The design as a JSON-ready dict (every key)."""
        out: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)}
        out.update({key: list(value) for key, value in out.items() if isinstance(value, tuple)},
                   validity=dict(zip(VALIDITY_UNITS, self.validity, strict=True)))
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"

    @classmethod
    def from_dict(cls, data: Any, base: MachineDesign | None = None) -> MachineDesign:
        """A design from a JSON-like dict: keys left out take ``base``'s values (default:
        the prototype; the validity lengths scaled by ``L / base.L``), unknown keys are an
        error."""
        base = PROTOTYPE if base is None else base
        if not isinstance(data, dict):
            raise DesignError("a design must be a JSON object (or a TOML table)")
        unknown = [key for key in data if key not in KEYS]
        if unknown:
            raise DesignError(f"unknown design key(s) {sorted(map(str, unknown))}; allowed: "
                              f"{list(KEYS)}", key=str(unknown[0]))
        for key, value in data.items():
            # Each key checked alone first, so that a refusal names the key at fault.
            if key == "validity":
                _validity_object(value)
            else:
                _numbers(key, value, RULES[key])
        merged = base.to_dict()
        scale = _numbers("L", data.get("L", base.L), RULES["L"]) / base.L
        merged["validity"] = {key: limit * scale if unit == "mm" else limit
                              for key, (limit, unit) in base.validity_range.items()}
        merged.update({key: value for key, value in data.items() if key != "validity"})
        merged["validity"].update(data.get("validity", {}))
        try:
            return cls(**{key: _validity_object(value) if key == "validity" else value
                          for key, value in merged.items()})
        except DesignError as exc:
            # A rule between keys blames the first of its keys that the user gave.
            given = exc.key if exc.key in data else next(
                (k for k in ("L", "d") if k in data), exc.key)
            raise DesignError(str(exc), key=given) from None

    @classmethod
    def from_file(cls, path: str | Path, base: MachineDesign | None = None) -> MachineDesign:
        """Read a design file: TOML when its name ends in ``.toml``, JSON otherwise (a key
        given twice is an error).  Refusals name the file, and the line of the key at
        fault."""
        return load_user_file(path, "design", DesignError, lambda data: cls.from_dict(data, base),
                              toml=Path(path).suffix.lower() == ".toml")


def _number(key: str, value: Any, rule: Rule) -> float:
    """One number under a design key: an int or a float a float can hold (not a boolean,
    not a string), finite and within the rule."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise DesignError(f"design key '{key}' must be {rule.text()}, got {short_repr(value)} "
                          f"({type(value).__name__})", key=key)
    try:
        number = float(value)
    except OverflowError:
        raise DesignError(f"design key '{key}' must be {rule.text()}, got an integer beyond "
                          "the range of a float", key=key) from None
    if not math.isfinite(number) or not rule.holds(number):
        raise DesignError(f"design key '{key}' must be {rule.text()}, got {number:g}", key=key)
    return number


def _numbers(key: str, value: Any, rule: Rule) -> float | tuple[float, ...]:
    """The number, or the tuple of numbers, under a design key, checked against its rule."""
    if rule.size is None:
        return _number(key, value, rule)
    if not isinstance(value, list | tuple) or (
            len(value) != rule.size if rule.size else not value):
        raise DesignError(f"design key '{key}' must be {rule.text()}, got {short_repr(value)}",
                          key=key)
    return tuple(_number(key, element, rule) for element in value)


def _validity_object(value: Any) -> dict[str, float]:
    """A validity object's limits, by machine key (keys left out are left out)."""
    if not isinstance(value, dict):
        raise DesignError(f"design key 'validity' must be {VALIDITY_RULE}, got {short_repr(value)}",
                          key="validity")
    unknown = [key for key in value if key not in VALIDITY_UNITS]
    if unknown:
        raise DesignError(f"design key 'validity' has unknown key(s) {sorted(map(str, unknown))};"
                          f" allowed: {list(VALIDITY_UNITS)}", key="validity")
    limit = Rule(unit="mm; rad for axis_tilt")
    out = {}
    for key, number in value.items():
        try:
            out[key] = _number(key, number, limit)
        except DesignError as exc:
            raise DesignError(str(exc).replace(f"design key '{key}'",
                                               f"design key 'validity.{key}'"),
                              key="validity") from None
    return out


def _validity(value: Any) -> tuple[float, ...]:
    """The validity limits in :data:`VALIDITY_UNITS` order, from a dict or a sequence."""
    if isinstance(value, dict):
        missing = [key for key in VALIDITY_UNITS if key not in value]
        if missing:
            raise DesignError(f"design key 'validity' lacks {missing}", key="validity")
        value = [value[key] for key in VALIDITY_UNITS]
    if not isinstance(value, list | tuple) or len(value) != len(VALIDITY_UNITS):
        raise DesignError(f"design key 'validity' must be {VALIDITY_RULE}",
                          key="validity")
    return tuple(_validity_object(dict(zip(VALIDITY_UNITS, value, strict=True))).values())


def _prototype() -> MachineDesign:
    """The prototype, from the file that ships with the package: every key given."""
    path = Path(__file__).with_name("prototype.json")
    data = json.loads(read_user_file(path, "design file", DesignError))
    missing = [key for key in KEYS if key not in data]
    if missing:
        raise DesignError(f"{path}: the prototype lacks {missing}")
    return MachineDesign(**data)


#: The prototype of the paper, the default design (dimensions: section 2.1 of Pashkevich et
#: al.; control limits: section 2.3).
PROTOTYPE: MachineDesign = _prototype()


def load_design(path: str | Path | None) -> MachineDesign:
    """The design in file ``path``, or the prototype when there is none."""
    return PROTOTYPE if path is None else MachineDesign.from_file(path)
