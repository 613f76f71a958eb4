"""The JSON form of a reading file: read with its duplicated keys remembered (to refuse
them), within a size limit."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any, BinaryIO

from calibrators.measurements.fields import MAX_JSON_BYTES, MeasurementFileError
from calibrators.measurements.record import Measurement
from orthoglide_env.model.design import PROTOTYPE, MachineDesign


class _JsonObject(dict):
    """A JSON object that remembers which of its keys appeared more than once."""

    duplicates: tuple[str, ...] = ()

    @classmethod
    def of(cls, pairs: list[tuple[str, Any]]) -> _JsonObject:
        obj = cls(pairs)
        if len(obj) < len(pairs):
            obj.duplicates = tuple(k for k, n in Counter(k for k, _ in pairs).items() if n > 1)
        return obj


def load_json(handle: BinaryIO, path: Path) -> object:
    """The JSON document of the file open as ``handle`` (``path`` names it in errors), its
    objects remembering keys given twice."""
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




def write_json(items: list[Measurement], experiment_time_s: float, design: MachineDesign,
               path: Path) -> None:
    """Write the JSON form, one reading per line; the design only when it is not the
    prototype's."""
    body = ",\n".join(json.dumps(m.to_dict()) for m in items)
    named = "" if design == PROTOTYPE else f' "design": {json.dumps(design.to_dict())},'
    path.write_text(f'{{"experiment_time_s": {json.dumps(experiment_time_s)},'
                    f'{named} "readings": [\n{body}\n]}}\n', encoding="utf-8")
