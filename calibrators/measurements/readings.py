"""The readings of one experiment (:class:`Measurements`) and their files, the format
chosen by the extension."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from calibrators.measurements import fields
from calibrators.measurements.csv_file import read_csv, write_csv
from calibrators.measurements.fields import (
    JSON_KEYS,
    MAX_EXPERIMENT_TIME_S,
    FieldError,
    MeasurementFileError,
    _posture,
    _real,
    _show,
)
from calibrators.measurements.json_file import load_json, write_json
from calibrators.measurements.record import Measurement, _Readings
from orthoglide_env.model.design import PROTOTYPE, DesignError, MachineDesign


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
        if len(items) > fields.MAX_ROWS:
            raise MeasurementFileError(f"{source}: more than {fields.MAX_ROWS} readings")
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
        write_json(self.items, self.experiment_time_s, self.design, Path(path))

    @classmethod
    def from_json(cls, path: str | Path, design: MachineDesign | None = None) -> Measurements:
        """Read a JSON file (``design`` as in :meth:`from_dict`)."""
        path = Path(path)
        with _opened(path) as handle:
            data = load_json(handle, path)
        result = cls.from_dict(data, str(path), design)
        if not result.items:
            raise MeasurementFileError(f"{path}: no readings")
        return result

    def to_csv(self, path: str | Path) -> None:
        """Write the CSV format: the header :data:`COLUMNS`, then one reading per row
        (without the ``time_s`` or ``temperature_c`` column when no reading has one)."""
        self.check()
        write_csv(self.items, Path(path))

    @classmethod
    def from_csv(cls, path: str | Path, design: MachineDesign | None = None) -> Measurements:
        """Read a CSV file of readings on a machine of ``design`` (None: the prototype):
        a CSV has no place to name its design.  Nor its experiment time: it is taken as
        the last reading's ``time_s`` (0 without the column), the least the experiment
        took."""
        path = Path(path)
        design = PROTOTYPE if design is None else design
        with _opened(path) as handle:
            items = read_csv(handle, path, design)
        seconds = max((m.time_s for m in items if m.time_s is not None), default=0.0)
        return cls(items, seconds, design=design)

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
