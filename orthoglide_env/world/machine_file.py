"""A machine file's world: the drawn non-geometric truth, kept beside the 27 errors.

A machine file (the schema of :class:`~orthoglide_env.model.errors.MachineParams`) may
hold one more key, ``"world"``: :meth:`World.to_dict` of that machine as a lab drew it
(its conditions, drives, room, each stand's indicator and first mounting).  A truth is so
written (``calibrate --save-truth``), read and replayed: a lab reset with such a machine
takes its world instead of drawing one, so the same commands on the same machine meet
the same screws, room and indicators.  A lab of other conditions refuses it.

An estimate file is a machine file too: the estimated machine's errors, and under
``"calibration"`` the fit that found them (its covariance, readings, gauge stands, the
lab's fitted terms; the calibrators read it, the machine does not).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineFileError, MachineParams
from orthoglide_env.model.userfile import load_user_file
from orthoglide_env.world.truth import World

WORLD_KEY: str = "world"
#: The key of an estimate file's fit (an object the machine passes over).
CALIBRATION_KEY: str = "calibration"


def machine_dict(machine: MachineParams, world: World | None) -> dict[str, Any]:
    """The machine file's object of ``machine`` and (machine 0 of) ``world``."""
    out = machine.to_dict()
    if world is not None:
        out[WORLD_KEY] = world[0].to_dict()
    return out


def read_machine(data: Any, design: MachineDesign | None = None,
                 folder: Path | None = None) -> tuple[MachineParams, World | None]:
    """The machine and its world (None when the object has none) of a machine file's
    object; :class:`MachineFileError` naming the key at fault."""
    if not isinstance(data, dict):
        raise MachineFileError("a machine must be a JSON object")
    if CALIBRATION_KEY in data and not isinstance(data[CALIBRATION_KEY], dict):
        raise MachineFileError("machine key 'calibration' must be an object (a fit's record)",
                               key=CALIBRATION_KEY)
    geometry = {key: value for key, value in data.items()
                if key not in (WORLD_KEY, CALIBRATION_KEY)}
    machine = MachineParams.from_dict(geometry, design, folder)
    if WORLD_KEY not in data:
        return machine, None
    if not isinstance(data[WORLD_KEY], dict):
        raise MachineFileError("machine key 'world' must be an object (a lab's drawn world)",
                               key=WORLD_KEY)
    try:
        return machine, World.from_dict(data[WORLD_KEY])
    except (ValueError, TypeError) as exc:
        raise MachineFileError(f"machine key 'world': {exc}", key=WORLD_KEY) from None


def read_machine_file(path: str | Path, design: MachineDesign | None = None
                      ) -> tuple[MachineParams, World | None]:
    """:func:`read_machine` of the machine file ``path`` (errors name the file and line)."""
    return load_user_file(path, "machine", MachineFileError,
                          lambda data: read_machine(data, design, Path(path).parent))


def write_machine_file(path: str | Path, machine: MachineParams, world: World | None) -> None:
    Path(path).write_text(json.dumps(machine_dict(machine, world), indent=2) + "\n")
