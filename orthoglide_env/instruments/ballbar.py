"""The telescoping ballbar between the platform and a pivot on the base (ISO 230-4).

A set-up (the lab's ``pivot`` operation) drives the TCP to a centre posture, fixes the
centre pivot's magnetic mount under the tool cup there and fits a bar of one of
:data:`~orthoglide_env.world.table.BALLBAR_LENGTHS_MM`.  While the bar is in, every move
reads it: the TCP's distance from the pivot less the bar's nominal length (mm), so the
bar sees the geometry through the kinematics (lead error, backlash and every geometric
error move the TCP it reads), plus its own errors: a scale error per lab, a reading's
scatter and its resolution.  The pivot sits where the TCP truly was, off by the
centring error; a fit takes the centre as three unknowns of the set-up, as ISO 230-4's
analysis removes the centring, and the bar's calibrated length as the set-up's zero.
The bar is steel like the machine (an assumption): the room's uniform growth cancels.

Sizes: :data:`~orthoglide_env.world.table.INSTRUMENT_ERRORS` (``ballbar``); times: the
time table (:data:`~orthoglide_env.lab.operations.TIME`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import direct
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM, INSTRUMENT_ERRORS
from orthoglide_env.world.truth import UM, draw_range

#: The stream jump a ballbar's own draws come from (the thermometer's is 1, the
#: interferometer's 2): a lab that owns one draws the same machine, world and noise.
_JUMPS: int = 3
#: Centring errors drawn per lab at reset, one row per set-up (a lab sets up at most this
#: many times in an episode: more is refused).
MAX_SETUPS: int = 64


@dataclass(frozen=True)
class BallbarSpec:
    """A ballbar set-up: its pivot centred at the TCP of command ``centre`` (mm, control
    coordinates) and its bar's nominal ``length`` (mm).  A reading is the TCP's distance
    from the pivot less ``length`` (mm)."""

    centre: tuple[float, float, float]
    length: float

    @property
    def slot(self) -> str:
        x, y, z = (f"{v:g}" for v in self.centre)
        return f"ballbar/{self.length:g}@({x},{y},{z})"


def mounting_name(count: int) -> str:
    """The name of the lab's ``count``-th ballbar set-up."""
    return f"ballbar#{count}"


def travel_mm() -> float:
    """How far (mm) a reading may lie from the bar's nominal length, either way."""
    return INSTRUMENT_ERRORS["ballbar"]["travel"].lab[0]


def sigma(conditions: Conditions) -> float:
    """A reading's scatter (mm, a standard deviation): half the bar's constant accuracy,
    and its resolution's rounding (the same in every world: it is the instrument's)."""
    rows = INSTRUMENT_ERRORS["ballbar"]
    half = rows["accuracy"].at(conditions.name)[1] / 2
    step = rows["resolution"].at(conditions.name)[0]
    return float(np.hypot(half, step / np.sqrt(12))) * UM


def scale_rms() -> float:
    """The RMS of a lab's scale error (dimensionless; uniform within the table's range,
    either sign): a fit considers it on every ballbar reading."""
    low, high = INSTRUMENT_ERRORS["ballbar"]["scale"].lab
    return float(np.sqrt((low * low + low * high + high * high) / 3.0)) * 1e-2


def centring_sigma() -> float:
    """The RMS (mm) of a pivot's centring error per coordinate, the widest the table
    allows (the workshop's): a fit's prior on a set-up's centre, whatever the world."""
    low, high = INSTRUMENT_ERRORS["ballbar"]["centring"].workshop
    return float(np.sqrt((low * low + low * high + high * high) / 3.0)) * UM


def nominal_readings(design: MachineDesign, spec: BallbarSpec, rho: np.ndarray) -> np.ndarray:
    """What the nominal machine of ``design`` puts on the bar of ``spec`` at commands
    ``rho`` (``(..., 3)``): its distance less the nominal length (mm)."""
    nominal = MachineParams(design=design)
    centre = direct(nominal, np.asarray(spec.centre, dtype=float))
    return np.linalg.norm(direct(nominal, np.asarray(rho, dtype=float)) - centre,
                          axis=-1) - spec.length


def length_of(index: int) -> float:
    """The bar length (mm) of an action's ``bar`` index, or ``ValueError``."""
    if not 0 <= index < len(BALLBAR_LENGTHS_MM):
        raise ValueError(f"bar must be an index of the lengths {list(BALLBAR_LENGTHS_MM)} "
                         f"mm, got {index}")
    return BALLBAR_LENGTHS_MM[index]


@dataclass(frozen=True)
class BallbarErrors:
    """A lab's ballbar: its scale error (dimensionless) and the centring error (mm) of
    each of its set-ups in turn (``(MAX_SETUPS, 3)``)."""

    scale: float
    centring: np.ndarray


def draw_errors(conditions: Conditions, stream: np.random.Generator) -> BallbarErrors:
    """A lab's ballbar errors drawn from a jump of ``stream`` (the stream itself does not
    move); zeros in an ideal world."""
    if not conditions.active:
        return BallbarErrors(0.0, np.zeros((MAX_SETUPS, 3)))
    rows, name = INSTRUMENT_ERRORS["ballbar"], conditions.name
    own = np.random.Generator(stream.bit_generator.jumped(_JUMPS))
    scale = float(draw_range(own, rows["scale"].at(name), (), True, 1e-2))
    centring = draw_range(own, rows["centring"].at(name), (MAX_SETUPS, 3), True, UM)
    return BallbarErrors(scale, centring)


def noise_stream(stream: np.random.Generator) -> np.random.Generator:
    """The stream a lab's ballbar scatter is drawn from: past the errors' jump, so the
    episode's own stream (its gauges' noise) does not move."""
    return np.random.Generator(stream.bit_generator.jumped(_JUMPS + 1))


def readings(distance: np.ndarray, length: np.ndarray, scale: np.ndarray,
             conditions: Conditions, draws: np.ndarray) -> np.ndarray:
    """What bars of nominal ``length`` read at a TCP-pivot ``distance`` (mm) with their
    ``scale`` error and standard normal ``draws``: rounded to the resolution (mm)."""
    step = INSTRUMENT_ERRORS["ballbar"]["resolution"].lab[0] * UM
    half = INSTRUMENT_ERRORS["ballbar"]["accuracy"].at(conditions.name)[1] / 2 * UM
    value = (distance - length) * (1.0 + scale) + half * draws
    return np.round(value / step) * step
