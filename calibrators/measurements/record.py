"""One reading (:class:`Measurement`): which gauge in which mounting, at which posture,
in which repetition; built from a file's fields and written back to them."""

from __future__ import annotations

import functools
import numbers
import sys
from collections.abc import Mapping
from dataclasses import KW_ONLY, InitVar, dataclass, field
from typing import Any

import numpy as np

from calibrators.measurements import fields
from calibrators.measurements.fields import (
    _READING_RULE,
    _TRACKER_RULE,
    BALLBAR_FIELDS,
    FACE_FIELD,
    INSTRUMENT_KINDS,
    MAX_BAR_MM,
    MAX_EXPERIMENT_TIME_S,
    MAX_READING_MM,
    MAX_ROOM_C,
    MAX_TRACKER_MM,
    MIN_ROOM_C,
    RHO_FIELDS,
    STEP_GAUGE_FIELDS,
    ZERO_RHO,
    FieldError,
    _fields_problem,
    _given,
    _label,
    _posture,
    _real,
    _repetition,
    _required,
    _show,
    rho_label,
)
from orthoglide_env.instruments.ballbar import BallbarSpec, travel_mm
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.instruments.slots import NO_LEG, GaugeSpec, Part, layout_from_names, on_platform
from orthoglide_env.instruments.step_gauge import (
    StepGaugeSpec,
    face_lengths,
    faces_of,
    off_face,
    probe_range_mm,
)
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import AXIS_NAMES, LEG_NAMES
from orthoglide_env.reading_model import TrackerAxis

#: A ballbar reading's limit: its travel about the bar's length.
_BALLBAR_RULE = "mm (a ballbar reads within its travel about its length)"
#: A step-gauge reading's limit: its probe's range about face 0's.
_PROBE_RULE = "mm (a step gauge's probe reads within its range)"
#: What a reading reads, as the files name it.
Gauge = GaugeSpec | TrackerAxis | InterferometerAxis | BallbarSpec | StepGaugeSpec


@functools.lru_cache(maxsize=4096)
def default_mounting(gauge: GaugeSpec | TrackerAxis) -> str:
    """A reading's mounting when none is named: a gauge's slot (``x-leg/y@0.5``), or the
    coordinate of the one tracker station (``tracker.x``)."""
    if isinstance(gauge, TrackerAxis):
        return f"tracker.{AXIS_NAMES[gauge.component]}"
    if isinstance(gauge, InterferometerAxis):
        return f"interferometer.{AXIS_NAMES[gauge.axis]}"
    return gauge_name(gauge)  # (a ballbar's: its set-up, ``ballbar/50@(...)``)


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

    gauge: Gauge
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
    #: The number of the stand it was read on, as the technician numbers the stands
    #: (``orthoglide plan``'s sheet), if given.
    stand: int | None = field(default=None, compare=False)
    design: InitVar[MachineDesign] = PROTOTYPE

    def __post_init__(self, design: MachineDesign) -> None:
        posture, rho = _posture(self.posture, self.rho, design)
        mounting = default_mounting(self.gauge) if self.mounting == "" else _label(
            self.mounting, "mounting")
        for name, value in (("posture", posture), ("rho", rho), ("mounting", mounting)):
            object.__setattr__(self, name, value)
        self._own(self.reading, self.repetition, self.time_s, self.line, self.step,
                  self.temperature_c, self.stand)

    def _own(self, reading: object, repetition: object, time_s: object,
             line: int | None, step: object = None, temperature_c: object = None,
             stand: object = None) -> None:
        """Check and set what is this reading's own: its value, repetition, time,
        procedure step, room temperature and stand."""
        limit, rule = ((MAX_TRACKER_MM, _TRACKER_RULE) if isinstance(self.gauge, TrackerAxis)
                       else (travel_mm(), _BALLBAR_RULE) if isinstance(self.gauge, BallbarSpec)
                       else (probe_range_mm(), _PROBE_RULE)
                       if isinstance(self.gauge, StepGaugeSpec)
                       else (MAX_READING_MM, _READING_RULE))
        reading = _real(reading, "reading_mm", -limit, limit, rule)
        time_s = None if time_s is None else _real(
            time_s, "time_s", 0.0, MAX_EXPERIMENT_TIME_S, "s (the lab clock)")
        step = None if step is None else _repetition(step, "step")
        stand = None if stand is None else _repetition(stand, "stand")
        temperature_c = None if temperature_c is None else _real(
            temperature_c, "temperature_c", MIN_ROOM_C, MAX_ROOM_C, "C (a room's)")
        for name, value in (("repetition", _repetition(repetition)), ("reading", reading),
                            ("time_s", time_s), ("line", line), ("step", step),
                            ("temperature_c", temperature_c), ("stand", stand)):
            object.__setattr__(self, name, value)

    def again(self, reading: object, repetition: object = 1, time_s: object = None,
              line: int | None = None, step: object = None,
              temperature_c: object = None, stand: object = None) -> Measurement:
        """Another reading of this gauge and mounting at this posture, its own fields
        checked as a new reading's are (what a file repeats is checked once)."""
        out = object.__new__(type(self))
        for name in ("gauge", "posture", "rho", "mounting"):
            object.__setattr__(out, name, getattr(self, name))
        out._own(reading, repetition, time_s, line, step, temperature_c, stand)
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
        # Each slot's own setter, called directly and not in a loop: half the cost of
        # ``object.__setattr__`` by name (a sweep records tens of thousands of readings).
        (set_gauge, set_posture, set_repetition, set_reading, set_rho, set_mounting,
         set_line, set_time, set_temperature, set_step, set_stand) = _RECORDED_SETTERS
        set_gauge(out, gauge)
        set_posture(out, posture or rho_label(rho))
        set_repetition(out, repetition)
        set_reading(out, reading)
        set_rho(out, rho)
        set_mounting(out, mounting)
        set_line(out, None)
        set_time(out, time_s)
        set_temperature(out, temperature_c)
        set_step(out, None)
        set_stand(out, None)
        return out

    @property
    def is_zero(self) -> bool:
        return self.rho == ZERO_RHO

    def to_dict(self) -> dict[str, Any]:
        """The reading as a JSON object of the file format."""
        out = {"mounting": self.mounting, "gauge": gauge_name(self.gauge),
               "posture": self.posture, "rho": list(self.rho), "repetition": self.repetition,
               "reading_mm": self.reading}
        if isinstance(self.gauge, BallbarSpec):
            del out["gauge"]  # its set-up's fields say it
            out.update(instrument="ballbar", **dict(zip(BALLBAR_FIELDS, ballbar_cells(
                self.gauge), strict=True)))
        if isinstance(self.gauge, StepGaugeSpec):
            del out["gauge"]  # its set-up's fields say it
            out.update(instrument="step-gauge", axis=AXIS_NAMES[self.gauge.axis],
                       **dict(zip(STEP_GAUGE_FIELDS, self.gauge.start, strict=True)))
        if self.time_s is not None:
            out["time_s"] = self.time_s
        if self.temperature_c is not None:
            out["temperature_c"] = self.temperature_c
        if self.step is not None:
            out["step"] = self.step
        if self.stand is not None:
            out["stand"] = self.stand
        if isinstance(self.gauge, InterferometerAxis):
            out["instrument"] = "interferometer"
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
        elif isinstance(self.gauge, InterferometerAxis | StepGaugeSpec):
            leg, axis, at = "", AXIS_NAMES[self.gauge.axis], ""
        elif isinstance(self.gauge, BallbarSpec):
            leg, axis, at = "", "", ""
        else:
            leg, axis = part_label(self.gauge), AXIS_NAMES[self.gauge.axis]
            at = repr(float(self.gauge.at)) if self.gauge.part == Part.BAR else ""
        return [self.mounting, leg, axis, at, self.posture, *(repr(v) for v in self.rho),
                str(self.repetition), repr(self.reading),
                *("" if v is None else repr(v) for v in (self.time_s, self.temperature_c))]


def instrument_of(gauge: Gauge) -> str:
    """The ``instrument`` column of a reading of ``gauge``."""
    if isinstance(gauge, InterferometerAxis):
        return "interferometer"
    if isinstance(gauge, BallbarSpec):
        return "ballbar"
    if isinstance(gauge, StepGaugeSpec):
        return "step-gauge"
    return "tracker" if isinstance(gauge, TrackerAxis) else "dial"


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
def _named_gauge(name: str) -> GaugeSpec | TrackerAxis | InterferometerAxis:
    if name.startswith("tracker/") and name[len("tracker/"):] in AXIS_NAMES:
        return TrackerAxis(AXIS_NAMES.index(name[len("tracker/"):]))
    if name.startswith("interferometer/") and name[len("interferometer/"):] in AXIS_NAMES:
        return InterferometerAxis(AXIS_NAMES.index(name[len("interferometer/"):]))
    try:
        return layout_from_names([name])[0]
    except ValueError as exc:
        raise FieldError("gauge", f"must name a gauge like 'x-leg/y', 'x/y@0.3', "
                                  f"'x-carriage/y', 'platform/x' or 'reference/x' ({exc}), "
                                  f"got {_show(name)}") from None


def _gauge(fields: Mapping[str, object], design: MachineDesign) -> Gauge:
    # Empty or absent: the reading's gauge says which (a file from before the column).
    instrument = _given(fields, "instrument")
    if instrument is not None and instrument not in INSTRUMENT_KINDS:
        raise FieldError("instrument", f"must be one of {', '.join(INSTRUMENT_KINDS)} "
                                       f"(empty: dial), got {_show(instrument)}")
    if instrument == "ballbar":
        return _ballbar_gauge(fields, design)
    if instrument == "step-gauge":
        return _step_gauge(fields, design)
    stray = [name for name in (*STEP_GAUGE_FIELDS, FACE_FIELD) if _given(fields, name) is not None]
    if stray:
        raise FieldError(stray[0], "only a step-gauge reading has its set-up and face: leave "
                                   f"it empty (instrument {_show(instrument or 'dial')})")
    stray = [name for name in BALLBAR_FIELDS if _given(fields, name) is not None]
    if stray:
        raise FieldError(stray[0], "only a ballbar reading has its set-up: leave it empty "
                                   f"(instrument {_show(instrument or 'dial')})")
    gauge = _instrument_gauge(fields) if instrument == "interferometer" else _plain_gauge(
        fields)
    if instrument is not None and instrument != instrument_of(gauge):
        raise FieldError("instrument", f"{instrument} for a reading of "
                                       f"{gauge_name(gauge)}, which is a "
                                       f"{instrument_of(gauge)}'s")
    return gauge


def _ballbar_gauge(fields: Mapping[str, object], design: MachineDesign) -> BallbarSpec:
    """A ballbar reading's set-up: its pivot's centring command (``pivot_x``, ``_y``,
    ``_z``, within ``design``'s control limits) and its bar's length (``bar_mm``); no leg,
    axis, place or gauge name."""
    for name in ("gauge", "leg", "axis", "at"):
        if _given(fields, name) is not None:
            raise FieldError(name, f"a ballbar reading has no {name}: its set-up is "
                                   f"{', '.join(BALLBAR_FIELDS)}; got {_show(fields[name])}")
    missing = [name for name in BALLBAR_FIELDS if _given(fields, name) is None]
    if missing:
        raise FieldError(missing[0], "empty: a ballbar reading needs its set-up: the command "
                                     "its pivot was centred at (pivot_x, pivot_y, pivot_z, "
                                     "mm) and the bar's length (bar_mm)")
    centre = tuple(_real(fields[name], name, design.rho_min, design.rho_max,
                         "mm (the control limits)") for name in BALLBAR_FIELDS[:3])
    length = _real(fields["bar_mm"], "bar_mm", 0.0, MAX_BAR_MM, "mm (a ballbar's length)")
    if length == 0.0:
        raise FieldError("bar_mm", "must be a length > 0 mm, got 0")
    return BallbarSpec(centre, length)  # type: ignore[arg-type]


def _step_gauge(fields: Mapping[str, object], design: MachineDesign) -> StepGaugeSpec:
    """A step-gauge reading's set-up: the world axis it lies along (``axis``) and the
    command at which its probe touched face 0 (``start_x``, ``_y``, ``_z``, within
    ``design``'s control limits); no leg, place or gauge name."""
    for name in ("gauge", "leg", "at", *BALLBAR_FIELDS):
        if _given(fields, name) is not None:
            raise FieldError(name, f"a step-gauge reading has no {name}: its set-up is axis, "
                                   f"{', '.join(STEP_GAUGE_FIELDS)}; got {_show(fields[name])}")
    missing = [name for name in ("axis", *STEP_GAUGE_FIELDS) if _given(fields, name) is None]
    if missing:
        raise FieldError(missing[0], "empty: a step-gauge reading needs its set-up: the world "
                                     "axis it lies along (axis) and the command at which the "
                                     "probe touched face 0 (start_x, start_y, start_z, mm)")
    axis = fields["axis"]
    if axis not in AXIS_NAMES:
        raise FieldError("axis", f"a step gauge lies along a world axis: one of "
                                 f"{', '.join(AXIS_NAMES)}, got {_show(axis)}")
    start = tuple(_real(fields[name], name, design.rho_min, design.rho_max,
                        "mm (the control limits)") for name in STEP_GAUGE_FIELDS)
    return StepGaugeSpec(AXIS_NAMES.index(axis), start)  # type: ignore[arg-type, arg-type]


def _check_face(m: Measurement, given: object, design: MachineDesign) -> None:
    """A step-gauge reading's rho must put the nominal machine's TCP at one of its gauge's
    faces, and at the ``face`` field's when one is given (:class:`FieldError`)."""
    problem = off_face(design, m.gauge, np.asarray(m.rho))  # type: ignore[arg-type]
    if problem:
        raise FieldError("rho", f"a step-gauge reading is read at a face: {problem}")
    if given is None:
        return
    count = len(face_lengths())
    if isinstance(given, bool) or not isinstance(given, numbers.Integral) or not (
            0 <= given < count):
        raise FieldError(FACE_FIELD, f"must be a face of the gauge, an integer 0..{count - 1}, "
                                     f"got {_show(given)}")
    face = int(faces_of(design, m.gauge, np.asarray(m.rho))[0])  # type: ignore[arg-type]
    if face != given:
        raise FieldError(FACE_FIELD, f"the reading's rho puts the TCP at face {face}, not "
                                     f"{given}")


def ballbar_cells(gauge: BallbarSpec) -> tuple[float, ...]:
    """A ballbar reading's :data:`~calibrators.measurements.fields.BALLBAR_FIELDS`."""
    return (*gauge.centre, gauge.length)


def _instrument_gauge(fields: Mapping[str, object]) -> InterferometerAxis:
    """An interferometer reading's drive: its ``axis`` (or ``gauge`` ``interferometer/x``),
    and no leg or place."""
    if "gauge" in fields:
        return _plain_gauge(fields)  # type: ignore[return-value]
    axis = _given(fields, "axis")
    if axis is None:
        raise FieldError("axis", "empty: an interferometer reading needs the drive it reads "
                                 f"({', '.join(AXIS_NAMES)})")
    if axis not in AXIS_NAMES:
        raise FieldError("axis", f"an interferometer reads a drive: one of "
                                 f"{', '.join(AXIS_NAMES)}, got {_show(axis)}")
    for name in ("leg", "at"):
        if _given(fields, name) is not None:
            raise FieldError(name, f"an interferometer reading has no {name}: leave it "
                                   f"empty, got {_show(fields[name])}")
    return InterferometerAxis(AXIS_NAMES.index(axis))


def _plain_gauge(fields: Mapping[str, object]) -> GaugeSpec | TrackerAxis | InterferometerAxis:
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
    gauge = _gauge(fields, design)
    rho = [_given(fields, name) for name in RHO_FIELDS]
    if None in rho:
        if any(v is not None for v in rho):
            raise FieldError(RHO_FIELDS[rho.index(None)],
                             "empty: give all of rho_x, rho_y, rho_z or none")
        rho = None
    posture = _given(fields, "posture")
    if posture is None and rho is None:
        raise FieldError("posture", "empty: give a paper posture, or the rho")
    out = Measurement(gauge, "" if posture is None else posture,
                      _given(fields, "repetition", 1), reading, rho,
                      _given(fields, "mounting", ""), line, design=design,
                      time_s=_given(fields, "time_s"), step=_given(fields, "step"),
                      temperature_c=_given(fields, "temperature_c"),
                      stand=_given(fields, "stand"))
    if isinstance(gauge, StepGaugeSpec):
        _check_face(out, _given(fields, FACE_FIELD), design)
    return out


class _Readings:
    """Readings as they are read or written, with the rules that span readings."""

    def __init__(self) -> None:
        self.items: list[Measurement] = []
        self._mounting: dict[str, tuple[GaugeSpec, str]] = {}
        self._stand: dict[str, tuple[int, str]] = {}

    def add(self, m: Measurement, where: str) -> None:
        if len(self.items) >= fields.MAX_ROWS:
            raise FieldError(None, f"more than {fields.MAX_ROWS} readings")
        gauge, first = self._mounting.setdefault(m.mounting, (m.gauge, where))
        if gauge != m.gauge:
            raise FieldError("mounting", f"mounting {_show(m.mounting)} holds gauge "
                                         f"{gauge_name(gauge)} ({first}), not "
                                         f"{gauge_name(m.gauge)}: one stand, one gauge")
        if m.stand is not None:
            stand, first = self._stand.setdefault(m.mounting, (m.stand, where))
            if stand != m.stand:
                raise FieldError("stand", f"mounting {_show(m.mounting)} is on stand {stand} "
                                          f"({first}), not stand {m.stand}: a mounting is one "
                                          "stand's")
        self.items.append(m)


#: The setters of the slots :meth:`Measurement.recorded` fills, in its order.
_RECORDED_SETTERS = tuple(getattr(Measurement, name).__set__ for name in (
    "gauge", "posture", "repetition", "reading", "rho", "mounting", "line", "time_s",
    "temperature_c", "step", "stand"))
