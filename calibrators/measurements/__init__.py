"""Gauge readings of one experiment, and their files (CSV or JSON).

A :class:`Measurement` is one reading: which gauge (what it touches, the axis it measures
along, a bar gauge's place ``at`` along the leg), in which mounting of its stand, at which
posture, in which repetition.  :class:`Measurements` holds an experiment's readings;
:meth:`Measurements.read` and :meth:`Measurements.write` choose the format by the file's
extension, ``.csv`` or ``.json``.  The format, column by column, with every rule a file
is checked against, is ``docs/measurements.md``.

=================  ==================================================================
module             its job
=================  ==================================================================
``fields``         the fields' names, limits and checks; the errors
``record``         one reading, from a file's fields and back
``csv_file``       the CSV form
``json_file``      the JSON form
``readings``       the readings of one experiment, read and written by extension
=================  ==================================================================
"""

from __future__ import annotations

from calibrators.measurements.fields import (
    COLUMNS,
    FIELDS,
    JSON_KEYS,
    MAX_EXPERIMENT_TIME_S,
    MAX_FIELD_CHARS,
    MAX_JSON_BYTES,
    MAX_LINE_BYTES,
    MAX_READING_MM,
    MAX_REPETITION,
    MAX_ROOM_C,
    MAX_ROWS,
    MAX_TRACKER_MM,
    MIN_ROOM_C,
    NUMBER_FIELDS,
    PAPER_RHO_TOLERANCE,
    RHO_FIELDS,
    ZERO_RHO,
    FieldError,
    MeasurementFileError,
    paper_rhos,
    rho_label,
)
from calibrators.measurements.readings import Measurements
from calibrators.measurements.record import (
    CARRIAGE_SUFFIX,
    Measurement,
    default_mounting,
    gauge_name,
    part_label,
)

__all__ = [
    "CARRIAGE_SUFFIX", "COLUMNS", "FIELDS", "JSON_KEYS", "MAX_EXPERIMENT_TIME_S",
    "MAX_FIELD_CHARS", "MAX_JSON_BYTES", "MAX_LINE_BYTES", "MAX_READING_MM",
    "MAX_REPETITION", "MAX_ROOM_C", "MAX_ROWS", "MAX_TRACKER_MM", "MIN_ROOM_C",
    "NUMBER_FIELDS", "PAPER_RHO_TOLERANCE", "RHO_FIELDS", "ZERO_RHO", "FieldError",
    "Measurement", "MeasurementFileError", "Measurements", "default_mounting", "gauge_name",
    "paper_rhos", "part_label", "rho_label",
]
