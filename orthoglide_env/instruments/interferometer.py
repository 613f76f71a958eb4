"""The laser interferometer along one drive, and the names of the instruments a lab owns.

ISO 230-2 measures an axis's positioning directly: the laser head stands at the back end
of the drive, aligned with it, and the retroreflector rides on the carriage.  On the
Orthoglide one actuator moves in joint space, so a reading is the carriage's true position
against its command (lead error, backlash, warm-up, the machine's growth with the room),
with no kinematic model in between, plus the instrument's own errors: a scale error per
lab (the laser's wavelength, the air compensation, the material sensor's error through
the compensated expansion, the beam's cosine error) and a small scatter.  Sizes:
:data:`~orthoglide_env.world.table.INSTRUMENT_ERRORS`; times: the time table
(:data:`~orthoglide_env.lab.operations.TIME`).

A set-up (the lab's ``align`` operation) drives to Zero, aligns the beam with one drive
and zeroes the count there: each set-up is a mounting of its own (``interferometer.x#2``),
whose zero a fit eliminates as it does a gauge's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.model.errors import AXIS_NAMES
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import EFFECTS, INSTRUMENT_ERRORS
from orthoglide_env.world.truth import UM, draw_range

#: The stream jump an interferometer's errors are drawn from (the thermometer's is 1): a
#: lab that owns one draws the same machine, world and noise as one that does not.
_JUMPS: int = 2


@dataclass(frozen=True)
class InterferometerAxis:
    """A laser interferometer's reading along drive ``axis`` (0, 1, 2 for x, y, z): the
    carriage's displacement from where the count was zeroed, less the commanded one
    (mm)."""

    axis: int

    @property
    def slot(self) -> str:
        return f"interferometer/{AXIS_NAMES[self.axis]}"


def mounting_name(axis: int, count: int) -> str:
    """The name of the lab's ``count``-th interferometer set-up, along ``axis``."""
    return f"interferometer.{AXIS_NAMES[axis]}#{count}"


def sigma(conditions: Conditions) -> float:
    """A reading's scatter (mm, a standard deviation) under ``conditions`` (the lab's in
    an ideal world)."""
    row = INSTRUMENT_ERRORS["interferometer"]["noise"]
    return (row.workshop if conditions.name == "workshop" else row.lab)[0] * UM


def scale_second_moment(conditions: Conditions) -> float:
    """E[e^2] of the scale error (dimensionless) a lab's interferometer reads with under
    ``conditions`` (zero in an ideal world): the laser's, the air's and the material
    sensor's through the machine's expansion, uncorrelated; the cosine error (a few
    parts in 1e8) is left out."""
    if not conditions.active:
        return 0.0
    rows = INSTRUMENT_ERRORS["interferometer"]

    def moment(name: str) -> float:
        low, high = rows[name].at(conditions.name)
        return (low * low + low * high + high * high) / 3.0

    alpha = EFFECTS["room"]["expansion"].lab[0]  # um/(m K) = ppm/K
    return (moment("laser") + moment("air") + alpha**2 * moment("material_sensor")) * 1e-12


def draw_errors(conditions: Conditions, stream: np.random.Generator) -> tuple[float, float]:
    """A lab's interferometer: its scale error from the laser, the air compensation and
    the beam's cosine error (dimensionless), and its material sensor's error (K), drawn
    from a jump of ``stream`` (the stream itself does not move).  Zeros in an ideal
    world."""
    if not conditions.active:
        return 0.0, 0.0
    rows, name = INSTRUMENT_ERRORS["interferometer"], conditions.name
    own = np.random.Generator(stream.bit_generator.jumped(_JUMPS))
    laser, air = (float(draw_range(own, rows[k].at(name), (), True, 1e-6))
                  for k in ("laser", "air"))
    angle = float(draw_range(own, rows["alignment"].at(name), (), scale=1e-3))
    sensor = float(draw_range(own, rows["material_sensor"].at(name), (), True))
    return (1 + laser + air) * np.cos(angle) - 1, sensor


def compensation(conditions: Conditions, scale_error: np.ndarray, sensor: np.ndarray,
                 temperature: np.ndarray) -> np.ndarray:
    """The factor the instrument multiplies a raw displacement by: its scale error, and
    the machine's expansion taken off at the material temperature its sensor reads (the
    room's, ``temperature`` K from 20 C, plus the sensor's error)."""
    if "room" not in conditions:
        return 1.0 + np.asarray(scale_error)
    alpha = EFFECTS["room"]["expansion"].lab[0] * 1e-6
    return (1.0 + np.asarray(scale_error)) / (1.0 + alpha * (np.asarray(temperature)
                                                              + sensor))
