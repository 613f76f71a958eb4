"""The CSV form of a reading file: read line by line, each distinct row parsed once;
written with a header of its columns."""

from __future__ import annotations

import csv
import functools
import re
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from calibrators.measurements.fields import (
    BALLBAR_FIELDS,
    COLUMNS,
    INSTRUMENT_COLUMN,
    MAX_FIELD_CHARS,
    MAX_LINE_BYTES,
    NUMBER_FIELDS,
    STEP_GAUGE_FIELDS,
    FieldError,
    MeasurementFileError,
    _fields_problem,
    _given,
    _required,
    _show,
)
from calibrators.measurements.record import (
    Measurement,
    _measurement,
    _Readings,
    ballbar_cells,
    instrument_of,
)
from orthoglide_env.instruments.ballbar import BallbarSpec
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.instruments.step_gauge import StepGaugeSpec
from orthoglide_env.model.design import MachineDesign

_INTEGER = re.compile(r"[+-]?[0-9]+")
#: The columns that hold what is a reading's own; the rest a file repeats.
_OWN_FIELDS: tuple[str, ...] = ("reading_mm", "repetition", "time_s", "step",
                                "temperature_c", "stand")
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


def read_csv(handle: BinaryIO, path: Path, design: MachineDesign) -> list[Measurement]:
    """The readings of the CSV file open as ``handle`` (``path`` names it in errors),
    checked on ``design``."""
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
                                line, _given(fields, "step"), _given(fields, "temperature_c"),
                                _given(fields, "stand"))
            readings.add(m, f"line {line}")
        except FieldError as exc:
            place = (f"column {header.index(exc.field) + 1} ({exc.field}): "
                     if exc.field in header else "")
            raise MeasurementFileError(f"{path}:{line}: {place}{exc.rule}") from None
    if not readings.items:
        raise MeasurementFileError(f"{path}: no readings after the header")
    return readings.items




def write_csv(items: list[Measurement], path: Path) -> None:
    """Write ``items`` as CSV: the header :data:`COLUMNS`, then one reading per row (without
    the ``time_s`` or ``temperature_c`` column when no reading has one, nor the
    ``instrument`` column when no reading is an interferometer's)."""
    keep = [k for k, name in enumerate(COLUMNS)
            if name not in ("time_s", "temperature_c")
            or any(getattr(m, name) is not None for m in items)]
    extra = instrument_columns(items)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([COLUMNS[k] for k in keep] + extra)
        writer.writerows([row[k] for k in keep] + instrument_cells(m, extra)
                         for m, row in ((m, m.csv_row()) for m in items))


def instrument_columns(items: list[Measurement]) -> list[str]:
    """The columns a file of ``items`` carries after :data:`COLUMNS`: the ``instrument``
    column when a reading is an interferometer's, a ballbar's or a step gauge's, then the
    ballbar's set-up when one is a ballbar's and the step gauge's when one is a step
    gauge's (none for dial gauges and the tracker: files as before)."""
    bars = any(isinstance(m.gauge, BallbarSpec) for m in items)
    probes = any(isinstance(m.gauge, StepGaugeSpec) for m in items)
    kinds = bars or probes or any(isinstance(m.gauge, InterferometerAxis) for m in items)
    return (([INSTRUMENT_COLUMN] if kinds else []) + (list(BALLBAR_FIELDS) if bars else [])
            + (list(STEP_GAUGE_FIELDS) if probes else []))


def instrument_cells(m: Measurement, columns: list[str]) -> list[str]:
    """Reading ``m``'s cells of :func:`instrument_columns`'s ``columns``."""
    if not columns:
        return []
    return ([instrument_of(m.gauge)]
            + (_setup_cells(m) if BALLBAR_FIELDS[0] in columns else [])
            + (_start_cells(m) if STEP_GAUGE_FIELDS[0] in columns else []))


def _start_cells(m: Measurement) -> list[str]:
    """A reading's step-gauge set-up cells (empty for another instrument's)."""
    if not isinstance(m.gauge, StepGaugeSpec):
        return [""] * len(STEP_GAUGE_FIELDS)
    return [repr(float(v)) for v in m.gauge.start]


def _setup_cells(m: Measurement) -> list[str]:
    """A reading's ballbar set-up cells (empty for another instrument's)."""
    if not isinstance(m.gauge, BallbarSpec):
        return [""] * len(BALLBAR_FIELDS)
    return [repr(float(v)) for v in ballbar_cells(m.gauge)]
