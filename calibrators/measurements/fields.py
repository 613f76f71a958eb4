"""The fields of a reading file: their names, limits and checks, and the errors a file
that breaks a rule raises."""

from __future__ import annotations

import functools
import math
import numbers
import sys
from collections.abc import Collection, Iterable, Mapping, Sequence
from typing import Any

from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.kinematics import PAPER_POSTURES, paper_posture

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
#: The column written after :data:`COLUMNS` when a reading is an interferometer's (a file
#: without one reads and writes as before).
INSTRUMENT_COLUMN: str = "instrument"
#: The ``instrument`` column's values: a dial gauge's (the default where it is empty or
#: absent), a tracker's (also told by ``leg`` ``tracker``), an interferometer's, a
#: ballbar's and a step gauge's.
INSTRUMENT_KINDS: tuple[str, ...] = ("dial", "tracker", "interferometer", "ballbar",
                                     "step-gauge")
RHO_FIELDS: tuple[str, str, str] = ("rho_x", "rho_y", "rho_z")
#: A ballbar reading's set-up, written after the ``instrument`` column when a reading is a
#: ballbar's: the command its pivot was centred at (mm, control coordinates) and the bar's
#: nominal length (mm).
BALLBAR_FIELDS: tuple[str, ...] = ("pivot_x", "pivot_y", "pivot_z", "bar_mm")
#: A ballbar's bar is at most this long (mm): a longer one is a wrong unit or column.
MAX_BAR_MM: float = 1000.0
#: A step-gauge reading's set-up, written after the ``instrument`` column (and the
#: ballbar's) when a reading is a step gauge's: the command at which its probe touched
#: face 0 (mm, control coordinates); the gauge's axis is the ``axis`` column.
STEP_GAUGE_FIELDS: tuple[str, ...] = ("start_x", "start_y", "start_z")
#: A step-gauge reading's face (0 to the gauge's last), written after its set-up: a check
#: that the reading's rho puts the TCP at it.
FACE_FIELD: str = "face"
#: Every name a CSV column or a JSON reading's key may have.
FIELDS: tuple[str, ...] = (*COLUMNS, "gauge", "step", "stand", INSTRUMENT_COLUMN,
                           *BALLBAR_FIELDS, *STEP_GAUGE_FIELDS, FACE_FIELD)
NUMBER_FIELDS: frozenset[str] = frozenset({"at", *RHO_FIELDS, "repetition", "reading_mm",
                                          "time_s", "temperature_c", "step", "stand",
                                          *BALLBAR_FIELDS, *STEP_GAUGE_FIELDS, FACE_FIELD})
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
                                    f"({', '.join(_compact(v) for v in paper)}) on the design "
                                    f"the readings are read with, not at "
                                    f"({', '.join(_compact(v) for v in values)}): readings of "
                                    f"another design are read with that design (--design), "
                                    f"and a posture of your own needs a name of your own")
    return label, paper


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
    if "gauge" not in names and not ({"leg", "axis"} <= set(names)
                                     or {"instrument", "axis"} <= set(names)
                                     or {"instrument", *BALLBAR_FIELDS} <= set(names)):
        return ("the gauge is missing: give 'gauge', or 'leg' and 'axis' (an "
                "interferometer's: 'instrument' and 'axis'; a ballbar's: 'instrument', "
                f"{', '.join(BALLBAR_FIELDS)})")
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


