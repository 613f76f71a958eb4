"""Gauge readings of one experiment, and their files (CSV or JSON).

A :class:`Measurement` is one dial reading: which gauge (what it touches, the axis it
measures along, a bar gauge's place ``at`` along the leg), in which mounting of its stand,
at which posture, in which repetition.
:class:`Measurements` holds an experiment's readings; :meth:`Measurements.read` and
:meth:`Measurements.write` choose the format by the file's extension, ``.csv`` or
``.json``.

CSV
---
UTF-8 text (a byte-order mark is accepted): a header line naming the columns, then one
reading per line.  Columns come in any order, their names are case-sensitive, cells are
stripped of surrounding blanks, blank lines are skipped, an empty cell is a value not
given.  The paper's five columns ``leg,axis,posture,repetition,reading_mm`` are one
case of this format.

============================  ========  ================================================
column                        required  meaning
============================  ========  ================================================
``reading_mm``                yes       the dial reading (mm), positive along the axis
``gauge``                     (a)       a gauge name: ``x-leg/y``, ``x/y@0.3`` (a bar),
                                        ``x-carriage/y`` (a carriage), ``platform/x``,
                                        ``reference/x`` (c)
``leg``, ``axis``             (a)       what the gauge touches: a leg's bar (``x``,
                                        ``y``, ``z``), a carriage (``x-carriage``, ...),
                                        ``platform`` or ``reference``; and the world
                                        axis measured
                                        along (for a bar or a carriage one of the two
                                        normal to its leg)
``at``                        no        with a bar's ``leg``, ``axis``: the gauge's place
                                        along the leg, 0.05 .. 0.95 from the platform
                                        end (default 0.5, the middle, as in the paper);
                                        empty for a carriage or the platform
``posture``                   (b)       a paper posture (Zero, XMax, XMin, YMax, YMin,
                                        ZMax, ZMin), or any label when rho is given
``rho_x``, ``rho_y``,         (b)       the commanded posture, control coordinates (mm);
``rho_z``                               without a label one is made: ``rho(5,-5,0)``
``repetition``                no        an integer grouping a Zero reading with the
                                        readings that follow it (default 1)
``mounting``                  no        one installation of a stand: a gauge re-mounted
                                        at the same place is a new mounting with its
                                        own zero (default: the gauge's name,
                                        ``x-leg/y@0.5``)
``time_s``                    no        when it was read (s on the lab clock, from the
                                        drives' switch-on): what a fit under lab or
                                        workshop conditions sizes drift with
``temperature_c``             no        the room's temperature then (C, a thermometer's
                                        reading, :data:`MIN_ROOM_C` .. :data:`MAX_ROOM_C`):
                                        the stands' growth is fitted against it
``step``                      no        the step of a written procedure
                                        (``orthoglide plan``) the reading was taken at,
                                        1 .. :data:`MAX_REPETITION`; ``fit --plan``
                                        checks it against the plan
============================  ========  ================================================

(a) the gauge either as ``gauge`` or as ``leg`` and ``axis`` (and ``at``), not both.  A
laser tracker's reading is three rows, one per coordinate of the reflector in the
tracker's frame: ``gauge`` ``tracker/x`` (or ``leg`` ``tracker``, ``axis`` ``x``), within
+-:data:`MAX_TRACKER_MM`; its default mounting is ``tracker.x`` (station ``tracker``).
(b) ``posture`` and/or the three ``rho_*`` columns; a row whose rho cells are empty
names a paper posture, and a paper posture's rho, when given, is its own.
(c) a platform gauge zeroed against the gauge block
(:data:`~orthoglide_env.world.table.REFERENCE_LENGTH_MM` long) held to the face at
Zero: its readings at Zero are through the block, its others on the bare face.

JSON
----
``{"readings": [{...}, ...], "experiment_time_s": 12.5}`` (the time optional, 0 .. 1e9):
each reading an object whose keys are the CSV's column names, numbers as JSON numbers
(not strings or booleans), rho as ``"rho": [x, y, z]`` or as ``rho_x``, ``rho_y``,
``rho_z``; a missing key, ``null`` or ``""`` is a value not given.  Keys appear once.

Rules of both formats (a file that breaks one is refused with one line naming the file,
the line and column of a CSV, or the index, from 0, of a JSON reading, and the rule):
numbers are finite; a reading lies within +-:data:`MAX_READING_MM` (a dial gauge's
travel is about 10 mm); rho lies within the control limits of the experiment's design (a
JSON file's ``design``, else the one the reader is given, else the prototype's), and a
paper posture is that design's; a
repetition is an integer 1 .. :data:`MAX_REPETITION`; a posture label or mounting is 1 ..
:data:`MAX_FIELD_CHARS` printable characters without surrounding blanks; a mounting
holds one gauge; a file holds 1 .. :data:`MAX_ROWS` readings (so at most that many
distinct repetitions).  A CSV cell holds at most :data:`MAX_FIELD_CHARS`
characters, a line at most :data:`MAX_LINE_BYTES` bytes, and a reading one line: a
quoted line break is refused.  A JSON file holds at most :data:`MAX_JSON_BYTES` bytes.
The CSV has no place for the experiment time; the JSON file keeps it.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import numbers
import re
import sys
from collections import Counter
from collections.abc import Collection, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import KW_ONLY, InitVar, dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from orthoglide_env.instruments.slots import NO_LEG, GaugeSpec, Part, layout_from_names, on_platform
from orthoglide_env.model.design import PROTOTYPE, DesignError, MachineDesign
from orthoglide_env.model.errors import AXIS_NAMES, LEG_NAMES
from orthoglide_env.model.kinematics import PAPER_POSTURES, paper_posture
from orthoglide_env.reading_model import TrackerAxis

#: A dial gauge's travel is about 10 mm: a reading ten times that is a wrong unit or column.
MAX_READING_MM: float = 100.0
#: A laser tracker coordinate (mm): its range, about 40 m.
MAX_TRACKER_MM: float = 40_000.0
MAX_REPETITION: int = 1_000_000
MAX_ROWS: int = 1_000_000
#: Labels are names, not documents; the bound also keeps integer parsing cheap (CPython's
#: int() is quadratic in the digits).
MAX_FIELD_CHARS: int = 1024
#: Bounds the memory one line can take before the csv module sees it.
MAX_LINE_BYTES: int = 65_536
MAX_JSON_BYTES: int = 256 * 1024 * 1024
#: A paper posture given with its rho: the rho may be rounded this much (mm); the reading
#: then takes the paper posture's exact rho, so that readings at it group together.
PAPER_RHO_TOLERANCE: float = 1e-6
#: An experiment time beyond ~30 years is a wrong unit.
MAX_EXPERIMENT_TIME_S: float = 1e9
#: A room's temperature (C) where a machine is calibrated lies well within these: a value
#: in kelvin (about 293) or Fahrenheit (about 68) is a wrong unit.
MIN_ROOM_C: float = 0.0
MAX_ROOM_C: float = 50.0

#: The columns :meth:`Measurements.to_csv` writes, in order.
COLUMNS: tuple[str, ...] = ("mounting", "leg", "axis", "at", "posture", "rho_x", "rho_y",
                            "rho_z", "repetition", "reading_mm", "time_s", "temperature_c")
RHO_FIELDS: tuple[str, str, str] = ("rho_x", "rho_y", "rho_z")
#: Every name a CSV column or a JSON reading's key may have.
FIELDS: tuple[str, ...] = (*COLUMNS, "gauge", "step")
NUMBER_FIELDS: frozenset[str] = frozenset({"at", *RHO_FIELDS, "repetition", "reading_mm",
                                          "time_s", "temperature_c", "step"})
JSON_KEYS: tuple[str, ...] = ("readings", "experiment_time_s", "design")

ZERO_RHO: tuple[float, float, float] = (0.0, 0.0, 0.0)


@functools.lru_cache(maxsize=64)
def paper_rhos(design: MachineDesign) -> dict[str, tuple[float, ...]]:
    """Each paper posture's rho on ``design`` (they depend on L and the control limits)."""
    return {name: tuple(float(v) for v in paper_posture(name, design))
            for name in PAPER_POSTURES}


_PAPER_RHO: dict[str, tuple[float, ...]] = paper_rhos(PROTOTYPE)
_READING_RULE = "mm (a dial gauge's travel is about 10 mm)"
_TRACKER_RULE = "mm (a laser tracker's range)"
_RHO_RULE = "mm (the control limits)"


class MeasurementFileError(ValueError):
    """A measurement file that cannot be read; the one-line message names the file, the
    place (line and column, or reading index) and the rule broken."""


class FieldError(ValueError):
    """A value that breaks a rule; ``field`` is its name in the files (None: the reading
    as a whole), so a reader can point at the column or key."""

    def __init__(self, field: str | None, rule: str) -> None:
        super().__init__(f"{field}: {rule}" if field else rule)
        self.field = field
        self.rule = rule


def _show(value: object) -> str:
    """A value for a one-line message: quoted, escaped, cut to a readable length."""
    if isinstance(value, int) and value.bit_length() > 3000:  # str() refuses > 4300 digits
        return "a huge integer"
    text = value if isinstance(value, str) else repr(value)
    return repr(text if len(text) <= 40 else text[:37] + "...")


def _real(value: object, name: str, low: float, high: float, unit: str) -> float:
    """``value`` as a float: a number (not a bool or a string), finite, in [low, high]."""
    if type(value) is float and low <= value <= high:  # the common case, without ABC checks
        return value
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise FieldError(name, f"must be a number, got {_show(value)}")
    if not isinstance(value, numbers.Integral) and not math.isfinite(value):
        raise FieldError(name, f"must be finite, got {_show(value)}")
    # Compared before any conversion: exact for integers of any size, which float() is not.
    if not low <= value <= high:
        raise FieldError(name, f"must lie in [{low:g}, {high:g}] {unit}, got {_show(value)}")
    return float(value)


def _repetition(value: object, name: str = "repetition") -> int:
    if type(value) is int and 1 <= value <= MAX_REPETITION:  # the common case, fast
        return value
    if (isinstance(value, bool) or not isinstance(value, numbers.Integral)
            or not 1 <= value <= MAX_REPETITION):
        raise FieldError(name, f"must be an integer 1..{MAX_REPETITION}, "
                               f"got {_show(value)}")
    return int(value)


def _label(value: object, name: str) -> str:
    """A posture label or mounting name; interned, since a file repeats a few of them."""
    if (not isinstance(value, str) or not value or len(value) > MAX_FIELD_CHARS
            or value != value.strip() or not value.isprintable()):
        raise FieldError(name, f"must be 1 to {MAX_FIELD_CHARS} printable characters without "
                               f"surrounding blanks, got {_show(value)}")
    return sys.intern(value)


def _compact(value: float) -> str:
    text = repr(value)
    return text[:-2] if text.endswith(".0") else text


def rho_label(rho: Sequence[float]) -> str:
    """The label of a posture given by its rho alone, e.g. ``rho(5,-5,0)``."""
    return "rho(" + ",".join(_compact(v) for v in rho) + ")"


def _posture(label: object, rho: Iterable[object] | None, design: MachineDesign
             ) -> tuple[str, tuple[float, ...]]:
    """A reading's posture label and rho on ``design``: a paper posture's rho (``design``'s)
    is filled in (and checked when given); a label of one's own needs its rho, within
    ``design``'s control limits; no label with a rho gets one made."""
    papers = _PAPER_RHO if design is PROTOTYPE else paper_rhos(design)
    if rho is None:
        if type(label) is str and label in papers:  # the common case, fast
            return label, papers[label]
        label = _label(label, "posture")
        if label not in papers:
            raise FieldError("posture", f"must be a paper posture ({', '.join(PAPER_POSTURES)})"
                                        f" unless rho is given, got {_show(label)}")
        return label, papers[label]
    try:
        components = [] if isinstance(rho, (str, bytes, Mapping)) else list(rho)
    except TypeError:  # not a sequence at all
        components = []
    if len(components) != 3:
        raise FieldError("rho", f"must have 3 components, got {_show(rho)}")
    values = tuple(_real(v, name, design.rho_min, design.rho_max, _RHO_RULE)
                   for v, name in zip(components, RHO_FIELDS, strict=True))
    if label == "":
        return rho_label(values), values
    label = _label(label, "posture")
    paper = papers.get(label)
    if paper is None:
        return label, values
    if max(abs(a - b) for a, b in zip(values, paper, strict=True)) > PAPER_RHO_TOLERANCE:
        raise FieldError("posture", f"{label} is the paper posture at rho "
                                    f"({', '.join(_compact(v) for v in paper)}): label a "
                                    f"posture of your own with a name of your own")
    return label, paper


@functools.lru_cache(maxsize=4096)
def default_mounting(gauge: GaugeSpec | TrackerAxis) -> str:
    """A reading's mounting when none is named: a gauge's slot (``x-leg/y@0.5``), or the
    coordinate of the one tracker station (``tracker.x``)."""
    if isinstance(gauge, TrackerAxis):
        return f"tracker.{AXIS_NAMES[gauge.component]}"
    return gauge_name(gauge)


def gauge_name(gauge: GaugeSpec | TrackerAxis) -> str:
    """A gauge's full name, place included, e.g. ``x-leg/y@0.5``: the default mounting."""
    return sys.intern(gauge.slot)


@dataclass(frozen=True, slots=True)
class Measurement:
    """One gauge reading: which gauge, in which mounting, at which posture and repetition.

    ``rho`` is the commanded posture (control coordinates, mm, within the control limits
    of ``design``, the machine's design: default the prototype); ``posture`` its label, a
    paper posture name (whose rho on ``design`` is filled in when not given) or any other
    label for a posture given by its ``rho`` ("" makes one from the rho).  ``mounting`` names one
    installation of the gauge's stand ("": the gauge's name): each has its own zero, and
    differences are taken against its readings at ``rho = (0, 0, 0)``.  ``line`` is where
    the reading came from in a file (not part of the reading: equality ignores it).  The
    module docstring's rules of one reading are checked here; a broken one raises
    :class:`FieldError` (a ValueError) naming the field.
    """

    gauge: GaugeSpec | TrackerAxis
    posture: str
    repetition: int
    reading: float
    rho: tuple[float, float, float] | None = None
    mounting: str = ""
    line: int | None = field(default=None, compare=False)
    _: KW_ONLY
    time_s: float | None = None
    #: The room's temperature (C) a thermometer read with it, if any.
    temperature_c: float | None = None
    #: The step of a written procedure it was taken at (``orthoglide plan``), if any.
    step: int | None = field(default=None, compare=False)
    design: InitVar[MachineDesign] = PROTOTYPE

    def __post_init__(self, design: MachineDesign) -> None:
        posture, rho = _posture(self.posture, self.rho, design)
        mounting = default_mounting(self.gauge) if self.mounting == "" else _label(
            self.mounting, "mounting")
        for name, value in (("posture", posture), ("rho", rho), ("mounting", mounting)):
            object.__setattr__(self, name, value)
        self._own(self.reading, self.repetition, self.time_s, self.line, self.step,
                  self.temperature_c)

    def _own(self, reading: object, repetition: object, time_s: object,
             line: int | None, step: object = None, temperature_c: object = None) -> None:
        """Check and set what is this reading's own: its value, repetition, time,
        procedure step and room temperature."""
        limit, rule = ((MAX_TRACKER_MM, _TRACKER_RULE) if isinstance(self.gauge, TrackerAxis)
                       else (MAX_READING_MM, _READING_RULE))
        reading = _real(reading, "reading_mm", -limit, limit, rule)
        time_s = None if time_s is None else _real(
            time_s, "time_s", 0.0, MAX_EXPERIMENT_TIME_S, "s (the lab clock)")
        step = None if step is None else _repetition(step, "step")
        temperature_c = None if temperature_c is None else _real(
            temperature_c, "temperature_c", MIN_ROOM_C, MAX_ROOM_C, "C (a room's)")
        for name, value in (("repetition", _repetition(repetition)), ("reading", reading),
                            ("time_s", time_s), ("line", line), ("step", step),
                            ("temperature_c", temperature_c)):
            object.__setattr__(self, name, value)

    def again(self, reading: object, repetition: object = 1, time_s: object = None,
              line: int | None = None, step: object = None,
              temperature_c: object = None) -> Measurement:
        """Another reading of this gauge and mounting at this posture, its own fields
        checked as a new reading's are (what a file repeats is checked once)."""
        out = object.__new__(type(self))
        for name in ("gauge", "posture", "rho", "mounting"):
            object.__setattr__(out, name, getattr(self, name))
        out._own(reading, repetition, time_s, line, step, temperature_c)
        return out

    @classmethod
    def recorded(cls, gauge: GaugeSpec | TrackerAxis, posture: str, reading: float,
                 rho: tuple[float, float, float], mounting: str, repetition: int,
                 time_s: float | None = None, temperature_c: float | None = None
                 ) -> Measurement:
        """A reading the lab wrote in its notebook, taken as it is: the lab only records
        finite readings of its own gauges at postures it reached, so the checks a reading
        from a file needs (a tenth of a millisecond each on a large sweep's notebooks)
        would find nothing."""
        out = object.__new__(cls)
        for name, value in (("gauge", gauge), ("posture", posture or rho_label(rho)),
                            ("repetition", repetition), ("reading", reading), ("rho", rho),
                            ("mounting", mounting), ("line", None), ("time_s", time_s),
                            ("temperature_c", temperature_c), ("step", None)):
            object.__setattr__(out, name, value)
        return out

    @property
    def is_zero(self) -> bool:
        return self.rho == ZERO_RHO

    def to_dict(self) -> dict[str, Any]:
        """The reading as a JSON object of the file format."""
        out = {"mounting": self.mounting, "gauge": gauge_name(self.gauge),
               "posture": self.posture, "rho": list(self.rho), "repetition": self.repetition,
               "reading_mm": self.reading}
        if self.time_s is not None:
            out["time_s"] = self.time_s
        if self.temperature_c is not None:
            out["temperature_c"] = self.temperature_c
        if self.step is not None:
            out["step"] = self.step
        return out

    @classmethod
    def from_dict(cls, data: object, design: MachineDesign = PROTOTYPE) -> Measurement:
        """A reading on a machine of ``design`` from a JSON object of the file format
        (:class:`FieldError` if bad)."""
        if not isinstance(data, dict):
            raise FieldError(None, f"must be a JSON object, got {_show(data)}")
        if getattr(data, "duplicates", ()):
            raise FieldError(data.duplicates[0], "the key appears more than once")
        fields = dict(data)
        if "rho" in fields:
            rho = fields.pop("rho")
            if any(name in fields for name in RHO_FIELDS):
                raise FieldError("rho", "give rho as a list or as rho_x, rho_y, rho_z, not both")
            if not isinstance(rho, list) or len(rho) != 3:
                raise FieldError("rho", f"must be a list of 3 numbers, got {_show(rho)}")
            fields.update(zip(RHO_FIELDS, rho, strict=True))
        problem = _fields_problem(fields, "key")
        if problem:
            raise FieldError(None, problem)
        return _measurement(fields, None, design)

    def csv_row(self) -> list[str]:
        """The reading as a row of :data:`COLUMNS`; numbers as their shortest round-trip
        ``repr``, so reading the file back gives the identical floats."""
        if isinstance(self.gauge, TrackerAxis):
            leg, axis, at = "tracker", AXIS_NAMES[self.gauge.component], ""
        else:
            leg, axis = part_label(self.gauge), AXIS_NAMES[self.gauge.axis]
            at = repr(float(self.gauge.at)) if self.gauge.part == Part.BAR else ""
        return [self.mounting, leg, axis, at, self.posture, *(repr(v) for v in self.rho),
                str(self.repetition), repr(self.reading),
                *("" if v is None else repr(v) for v in (self.time_s, self.temperature_c))]


def _fields_problem(names: Collection[str], kind: str) -> str | None:
    """What is wrong with the set of fields a CSV header or a JSON reading gives, if any."""
    unknown = [name for name in names if name not in FIELDS]
    if unknown:
        shown = ", ".join(_show(name) for name in unknown[:5])
        return f"unknown {kind} {shown}; the {kind}s are {', '.join(FIELDS)}"
    if "reading_mm" not in names:
        return f"the {kind} 'reading_mm' is required"
    if "gauge" in names and {"leg", "axis", "at"} & set(names):
        return "give the gauge as 'gauge' or as 'leg', 'axis' (and 'at'), not both"
    if "gauge" not in names and not {"leg", "axis"} <= set(names):
        return "the gauge is missing: give 'gauge', or 'leg' and 'axis'"
    rho = [name for name in RHO_FIELDS if name in names]
    if 0 < len(rho) < 3:
        return "rho needs all of rho_x, rho_y and rho_z"
    if not rho and "posture" not in names:
        return "the posture is missing: give 'posture' and/or rho_x, rho_y, rho_z"
    return None


def _given(fields: Mapping[str, object], name: str, default: Any = None) -> Any:
    """A field's value, or ``default`` when it is absent, null or empty."""
    value = fields.get(name)
    return default if value is None or value == "" else value


def _required(fields: Mapping[str, object], name: str) -> Any:
    value = _given(fields, name)
    if value is None:
        raise FieldError(name, "empty: every reading needs it")
    return value


#: The ``leg`` column of a carriage gauge: its leg's name with this suffix.
CARRIAGE_SUFFIX: str = "-carriage"


def part_label(gauge: GaugeSpec) -> str:
    """The ``leg`` column of a gauge: its bar's leg (``x``), its carriage (``x-carriage``),
    ``platform`` or ``reference``."""
    if on_platform(gauge.part):
        return gauge.part.name.lower()
    return LEG_NAMES[gauge.leg] + (CARRIAGE_SUFFIX if gauge.part == Part.CARRIAGE else "")


#: A file names a few gauges many times.
_spec = functools.lru_cache(maxsize=4096)(GaugeSpec)


@functools.lru_cache(maxsize=4096)
def _named_gauge(name: str) -> GaugeSpec | TrackerAxis:
    if name.startswith("tracker/") and name[len("tracker/"):] in AXIS_NAMES:
        return TrackerAxis(AXIS_NAMES.index(name[len("tracker/"):]))
    try:
        return layout_from_names([name])[0]
    except ValueError as exc:
        raise FieldError("gauge", f"must name a gauge like 'x-leg/y', 'x/y@0.3', "
                                  f"'x-carriage/y', 'platform/x' or 'reference/x' ({exc}), "
                                  f"got {_show(name)}") from None


def _gauge(fields: Mapping[str, object]) -> GaugeSpec | TrackerAxis:
    if "gauge" in fields:
        name = _required(fields, "gauge")
        if not isinstance(name, str):
            raise FieldError("gauge", f"must be a gauge name, got {_show(name)}")
        return _named_gauge(name)
    leg, axis = _required(fields, "leg"), _required(fields, "axis")
    at = _given(fields, "at")
    if leg == "tracker" and axis in AXIS_NAMES and at is None:
        return TrackerAxis(AXIS_NAMES.index(axis))
    if leg in ("platform", "reference"):
        if not isinstance(axis, str) or axis not in AXIS_NAMES:
            raise FieldError("axis", f"must be one of {', '.join(AXIS_NAMES)}, got "
                                     f"{_show(axis)}")
        if at is not None:
            raise FieldError("at", f"a {leg} gauge has one place per face: leave 'at' "
                                   "empty")
        return _spec(NO_LEG, AXIS_NAMES.index(axis), part=Part[leg.upper()])
    carriage = isinstance(leg, str) and leg.endswith(CARRIAGE_SUFFIX)
    name = leg.removesuffix(CARRIAGE_SUFFIX) if carriage else leg
    if not isinstance(leg, str) or name not in LEG_NAMES:
        raise FieldError("leg", f"must be one of {', '.join(LEG_NAMES)} (a bar), "
                                f"{', '.join(n + CARRIAGE_SUFFIX for n in LEG_NAMES)}, platform, "
                                f"reference or tracker, got {_show(leg)}")
    if not isinstance(axis, str) or axis not in AXIS_NAMES or axis == name:
        raise FieldError("axis", f"must be one of the two axes normal to the {name} leg, "
                                 f"got {_show(axis)}")
    if carriage:
        if at is not None:
            raise FieldError("at", "a carriage gauge has one place: leave 'at' empty")
        return _spec(LEG_NAMES.index(name), AXIS_NAMES.index(axis), part=Part.CARRIAGE)
    at = 0.5 if at is None else _real(at, "at", 0.0, 1.0, "(a fraction of the leg)")
    try:
        return _spec(LEG_NAMES.index(leg), AXIS_NAMES.index(axis), at)
    except ValueError as exc:
        raise FieldError("at", str(exc)) from None


def _measurement(fields: Mapping[str, object], line: int | None, design: MachineDesign
                 ) -> Measurement:
    """One reading from its fields: a CSV row's cells (numbers parsed) or a JSON object."""
    reading = _required(fields, "reading_mm")
    gauge = _gauge(fields)
    rho = [_given(fields, name) for name in RHO_FIELDS]
    if None in rho:
        if any(v is not None for v in rho):
            raise FieldError(RHO_FIELDS[rho.index(None)],
                             "empty: give all of rho_x, rho_y, rho_z or none")
        rho = None
    posture = _given(fields, "posture")
    if posture is None and rho is None:
        raise FieldError("posture", "empty: give a paper posture, or the rho")
    return Measurement(gauge, "" if posture is None else posture,
                       _given(fields, "repetition", 1), reading, rho,
                       _given(fields, "mounting", ""), line, design=design,
                       time_s=_given(fields, "time_s"), step=_given(fields, "step"),
                       temperature_c=_given(fields, "temperature_c"))


class _Readings:
    """Readings as they are read or written, with the rules that span readings."""

    def __init__(self) -> None:
        self.items: list[Measurement] = []
        self._mounting: dict[str, tuple[GaugeSpec, str]] = {}

    def add(self, m: Measurement, where: str) -> None:
        if len(self.items) >= MAX_ROWS:
            raise FieldError(None, f"more than {MAX_ROWS} readings")
        gauge, first = self._mounting.setdefault(m.mounting, (m.gauge, where))
        if gauge != m.gauge:
            raise FieldError("mounting", f"mounting {_show(m.mounting)} holds gauge "
                                         f"{gauge_name(gauge)} ({first}), not "
                                         f"{gauge_name(m.gauge)}: one stand, one gauge")
        self.items.append(m)


_INTEGER = re.compile(r"[+-]?[0-9]+")
#: The columns that hold what is a reading's own; the rest a file repeats.
_OWN_FIELDS: tuple[str, ...] = ("reading_mm", "repetition", "time_s", "step",
                                "temperature_c")
#: At most this many distinct (gauge, mounting, posture) rows are kept parsed (a few MB).
MAX_SEEN: int = 100_000


def _cell_value(name: str, text: str) -> object:
    """A CSV cell as its field's value: a number for the number fields."""
    if len(text) > MAX_FIELD_CHARS:
        raise FieldError(name, f"longer than {MAX_FIELD_CHARS} characters")
    if name not in NUMBER_FIELDS or not text:
        return text
    if _INTEGER.fullmatch(text):
        return int(text)
    if text.isascii() and "_" not in text:
        try:
            return float(text)
        except ValueError:
            pass
    raise FieldError(name, f"must be a number, got {_show(text)}")


def _lines(handle: BinaryIO, path: Path) -> Iterator[str]:
    """The file's lines as text, decoded one by one so that a fault names its line."""
    for number, raw in enumerate(iter(functools.partial(handle.readline, MAX_LINE_BYTES + 1),
                                      b""), start=1):
        if len(raw) > MAX_LINE_BYTES:
            raise MeasurementFileError(f"{path}:{number}: longer than {MAX_LINE_BYTES} bytes")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise MeasurementFileError(f"{path}:{number}: not UTF-8 text (byte {exc.start + 1} "
                                       f"of the line)") from None
        yield text.removeprefix("\ufeff") if number == 1 else text


def _records(handle: BinaryIO, path: Path) -> Iterator[tuple[int, list[str]]]:
    """(line, stripped cells) of every record that is not blank; a record is one line."""
    reader = csv.reader(_lines(handle, path))
    while True:
        start = reader.line_num + 1
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:  # e.g. its field_size_limit, NUL bytes
            raise MeasurementFileError(f"{path}:{start}: not CSV: {exc}") from None
        if reader.line_num > start:
            raise MeasurementFileError(f"{path}:{start}: a quoted field runs on to line "
                                       f"{reader.line_num}: a reading takes one line")
        cells = [cell.strip() for cell in row]
        if any(cells):
            yield start, cells


def _read_csv(handle: BinaryIO, path: Path, design: MachineDesign) -> list[Measurement]:
    records = _records(handle, path)
    first = next(records, None)
    if first is None:
        raise MeasurementFileError(f"{path}: empty: the header line naming the columns is "
                                   "missing")
    line, header = first
    repeated = [name for name, count in Counter(header).items() if count > 1]
    problem = (f"column {_show(repeated[0])} appears more than once" if repeated
               else _fields_problem(header, "column"))
    if problem:
        raise MeasurementFileError(f"{path}:{line}: header: {problem}")
    readings = _Readings()
    own = [(name, header.index(name)) for name in _OWN_FIELDS if name in header]
    shared = [k for k in range(len(header)) if k not in {k for _, k in own}]
    # A long experiment repeats a few gauges, mountings and postures: each distinct set of
    # those cells is parsed and checked once, which keeps a million rows to seconds.
    seen: dict[tuple[str, ...], Measurement] = {}
    for line, cells in records:
        if len(cells) != len(header):
            raise MeasurementFileError(f"{path}:{line}: expected {len(header)} columns as in "
                                       f"the header, got {len(cells)}")
        try:
            key = tuple(cells[k] for k in shared)
            first = seen.get(key)
            if first is None:
                fields = {name: _cell_value(name, text)
                          for name, text in zip(header, cells, strict=True)}
                m = _measurement(fields, line, design)
                if len(seen) < MAX_SEEN:
                    seen[key] = m
            else:
                fields = {name: _cell_value(name, cells[k]) for name, k in own}
                m = first.again(_required(fields, "reading_mm"),
                                _given(fields, "repetition", 1), _given(fields, "time_s"),
                                line, _given(fields, "step"), _given(fields, "temperature_c"))
            readings.add(m, f"line {line}")
        except FieldError as exc:
            place = (f"column {header.index(exc.field) + 1} ({exc.field}): "
                     if exc.field in header else "")
            raise MeasurementFileError(f"{path}:{line}: {place}{exc.rule}") from None
    if not readings.items:
        raise MeasurementFileError(f"{path}: no readings after the header")
    return readings.items


class _JsonObject(dict):
    """A JSON object that remembers which of its keys appeared more than once."""

    duplicates: tuple[str, ...] = ()

    @classmethod
    def of(cls, pairs: list[tuple[str, Any]]) -> _JsonObject:
        obj = cls(pairs)
        if len(obj) < len(pairs):
            obj.duplicates = tuple(k for k, n in Counter(k for k, _ in pairs).items() if n > 1)
        return obj


def _load_json(handle: BinaryIO, path: Path) -> object:
    raw = handle.read(MAX_JSON_BYTES + 1)
    if len(raw) > MAX_JSON_BYTES:
        raise MeasurementFileError(f"{path}: larger than {MAX_JSON_BYTES} bytes")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise MeasurementFileError(f"{path}:{line}: not UTF-8 text") from None
    try:
        return json.loads(text, object_pairs_hook=_JsonObject.of)
    except json.JSONDecodeError as exc:
        raise MeasurementFileError(f"{path}:{exc.lineno}:{exc.colno}: not valid JSON: "
                                   f"{exc.msg}") from None
    except (ValueError, RecursionError) as exc:  # e.g. an integer of > 4300 digits
        raise MeasurementFileError(f"{path}: not valid JSON: {exc}") from None


@contextmanager
def _opened(path: Path) -> Iterator[BinaryIO]:
    try:
        handle = path.open("rb")
    except FileNotFoundError:
        raise MeasurementFileError(f"measurement file not found: {path}") from None
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise MeasurementFileError(f"cannot read measurement file {path}: {reason}") from None
    with handle:
        yield handle


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise MeasurementFileError(f"{path}: a measurement file ends in .csv or .json")
    return suffix


@dataclass
class Measurements:
    """The readings of one experiment, plus the experiment time it cost (s), on a machine
    of ``design`` (a JSON file's optional ``design`` key: an object of design keys; left
    out, the prototype)."""

    items: list[Measurement] = field(default_factory=list)
    experiment_time_s: float = 0.0
    design: MachineDesign = PROTOTYPE

    def __len__(self) -> int:
        return len(self.items)

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of the file format."""
        out: dict[str, Any] = {"experiment_time_s": self.experiment_time_s,
                               "readings": [m.to_dict() for m in self.items]}
        if self.design != PROTOTYPE:
            out["design"] = self.design.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: object, source: str = "readings",
                  design: MachineDesign | None = None) -> Measurements:
        """Readings from the JSON document; ``source`` names it in error messages.  The
        readings are checked on the document's design, else ``design`` (None: the
        prototype); a document naming another design than ``design`` is refused."""
        if not isinstance(data, dict):
            raise MeasurementFileError(f"{source}: must be a JSON object with 'readings'")
        if getattr(data, "duplicates", ()):
            raise MeasurementFileError(f"{source}: the key {_show(data.duplicates[0])} "
                                       "appears more than once")
        unknown = [key for key in data if key not in JSON_KEYS]
        if unknown:
            raise MeasurementFileError(f"{source}: unknown key {_show(unknown[0])}; the keys "
                                       f"are {', '.join(JSON_KEYS)}")
        items = data.get("readings")
        if not isinstance(items, list):
            raise MeasurementFileError(f"{source}: 'readings' must be a list")
        if len(items) > MAX_ROWS:
            raise MeasurementFileError(f"{source}: more than {MAX_ROWS} readings")
        try:
            seconds = _real(data.get("experiment_time_s", 0.0), "experiment_time_s", 0.0,
                            MAX_EXPERIMENT_TIME_S, "s")
            named = MachineDesign.from_dict(data["design"]) if "design" in data else None
        except (FieldError, DesignError) as exc:
            raise MeasurementFileError(f"{source}: {exc}") from None
        if named is not None and design is not None and named != design:
            keys = [k for k, v in named.to_dict().items() if design.to_dict()[k] != v]
            raise MeasurementFileError(f"{source}: the file's design differs from the one "
                                       f"given (in {', '.join(keys)})")
        design = named or design or PROTOTYPE
        readings = _Readings()
        for index, item in enumerate(items):
            try:
                readings.add(Measurement.from_dict(item, design), f"reading {index}")
            except FieldError as exc:
                raise MeasurementFileError(f"{source}: reading {index}: {exc}") from None
        return cls(readings.items, seconds, design)

    def check(self) -> None:
        """Refuse (ValueError naming the reading's index) what a file could not hold, so
        that whatever is written reads back: on :attr:`design`, each rho within its
        control limits and each paper posture at its rho."""
        readings = _Readings()
        for index, m in enumerate(self.items):
            try:
                _posture(m.posture, m.rho, self.design)
                readings.add(m, f"reading {index}")
            except FieldError as exc:
                raise ValueError(f"reading {index}: {exc}") from None

    def to_json(self, path: str | Path) -> None:
        """Write the JSON format, one reading per line."""
        self.check()
        body = ",\n".join(json.dumps(m.to_dict()) for m in self.items)
        design = ("" if self.design == PROTOTYPE
                  else f' "design": {json.dumps(self.design.to_dict())},')
        Path(path).write_text(f'{{"experiment_time_s": {json.dumps(self.experiment_time_s)},'
                              f'{design} "readings": [\n{body}\n]}}\n', encoding="utf-8")

    @classmethod
    def from_json(cls, path: str | Path, design: MachineDesign | None = None) -> Measurements:
        """Read a JSON file (``design`` as in :meth:`from_dict`)."""
        path = Path(path)
        with _opened(path) as handle:
            data = _load_json(handle, path)
        result = cls.from_dict(data, str(path), design)
        if not result.items:
            raise MeasurementFileError(f"{path}: no readings")
        return result

    def to_csv(self, path: str | Path) -> None:
        """Write the CSV format: the header :data:`COLUMNS`, then one reading per row
        (without the ``time_s`` or ``temperature_c`` column when no reading has one)."""
        self.check()
        keep = [k for k, name in enumerate(COLUMNS)
                if name not in ("time_s", "temperature_c")
                or any(getattr(m, name) is not None for m in self.items)]
        with Path(path).open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow([COLUMNS[k] for k in keep])
            writer.writerows([row[k] for k in keep] for row in (m.csv_row() for m in self.items))

    @classmethod
    def from_csv(cls, path: str | Path, design: MachineDesign | None = None) -> Measurements:
        """Read a CSV file of readings on a machine of ``design`` (None: the prototype):
        a CSV has no place to name its design."""
        path = Path(path)
        design = PROTOTYPE if design is None else design
        with _opened(path) as handle:
            return cls(_read_csv(handle, path, design), design=design)

    def write(self, path: str | Path) -> None:
        """Write ``path`` in the format its extension names (.csv or .json)."""
        path = Path(path)
        (self.to_json if _suffix(path) == ".json" else self.to_csv)(path)

    @classmethod
    def read(cls, path: str | Path, design: MachineDesign | None = None) -> Measurements:
        """Read ``path`` in the format its extension names (.csv or .json), its readings
        checked on the file's design, else ``design``, else the prototype (a JSON file
        naming another design than ``design`` is refused)."""
        path = Path(path)
        return (cls.from_json if _suffix(path) == ".json" else cls.from_csv)(path, design)
