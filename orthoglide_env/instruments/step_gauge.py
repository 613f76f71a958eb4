"""The step gauge laid along a world axis through the workspace, read by a probe on the
platform (a KOBA-type gauge: faces every 20 mm along one line).

A set-up (the lab's ``place`` operation) drives the TCP to a command ``start``, lays the
gauge along world axis ``axis`` with its face 0 there and zeroes the probe on it; face
``k`` lies ``k`` pitches further along the axis.  While the gauge is set up, every move
must bring the nominal machine's TCP onto the gauge's line at a face (else
``ValueError``), and reads it: how far the TCP lies past the face, along the gauge, from
where it lay at face 0 (mm).  So a reading is the TCP's displacement along the axis less
the face's nominal distance from face 0: the machine's positioning error along the axis,
through the kinematics (lead error, backlash and every geometric error move the TCP), plus
the gauge's own errors:

* each face's calibration error (drawn once per gauge: the same at every set-up);
* the gauge's misalignment per set-up: its faces' normal is tilted from the axis, so a
  step reads long by ``1/cos - 1`` of it (cosine error) and a move across the line reads
  its sine;
* the room: the gauge grows from face 0 at its own coefficient, the machine at steel's;
  the lab takes both to 20 C at its thermometer's reading (at 20 C without one);
* the probe's scatter and its resolution.

The gauge's placement along its line is the set-up's zero, which a fit eliminates as it
does a dial gauge's; across the line it does not matter (the faces are flat).  Sizes:
:data:`~orthoglide_env.world.table.INSTRUMENT_ERRORS` (``step-gauge``); times: the time
table (:data:`~orthoglide_env.lab.operations.TIME`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import AXIS_NAMES, MachineParams
from orthoglide_env.model.kinematics import direct
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import (
    EFFECTS,
    INSTRUMENT_ERRORS,
    STEP_GAUGE_FACES,
    STEP_GAUGE_PITCH_MM,
)
from orthoglide_env.world.truth import UM, draw_range

#: The stream jump a step gauge's own draws come from (the thermometer's is 1, the
#: interferometer's 2, the ballbar's 3 and 4): a lab that owns one draws the same
#: machine, world and noise.
_JUMPS: int = 5
#: Misalignments drawn per lab at reset, one per set-up (more set-ups are refused).
MAX_SETUPS: int = 64

_ROWS = INSTRUMENT_ERRORS["step-gauge"]


@dataclass(frozen=True)
class StepGaugeSpec:
    """A step-gauge set-up: laid along world ``axis`` (0, 1, 2 for x, y, z) with face 0 at
    the TCP of command ``start`` (mm, control coordinates)."""

    axis: int
    start: tuple[float, float, float]

    @property
    def slot(self) -> str:
        x, y, z = (f"{v:g}" for v in self.start)
        return f"step-gauge/{AXIS_NAMES[self.axis]}@({x},{y},{z})"


def mounting_name(count: int) -> str:
    """The name of the lab's ``count``-th step-gauge set-up."""
    return f"step-gauge#{count}"


def probe_range_mm() -> float:
    """How far (mm) from a face, either way along the gauge, the probe reads it."""
    return _ROWS["range"].lab[0]


def face_lengths() -> np.ndarray:
    """Each face's nominal distance (mm) from face 0."""
    return STEP_GAUGE_PITCH_MM * np.arange(STEP_GAUGE_FACES)


def faces_of(design: MachineDesign, spec: StepGaugeSpec, rho: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the nominal machine of ``design`` puts the TCP at commands ``rho`` (``(...,
    3)``) against the gauge of ``spec``: the nearest face's index (may lie outside the
    gauge), the distance (mm) along the gauge from that face, and the distance across its
    line."""
    nominal = MachineParams(design=design)
    first = direct(nominal, np.asarray(spec.start, dtype=float))
    offset = direct(nominal, np.asarray(rho, dtype=float)) - first
    along = offset[..., spec.axis]
    face = np.rint(along / STEP_GAUGE_PITCH_MM).astype(int)
    across = np.delete(offset, spec.axis, axis=-1)
    return face, along - face * STEP_GAUGE_PITCH_MM, np.linalg.norm(across, axis=-1)


def off_face(design: MachineDesign, spec: StepGaugeSpec, rho: np.ndarray) -> str:
    """Why the probe cannot read a face of ``spec``'s gauge at command ``rho`` (``(3,)``),
    "" when it can."""
    face, along, across = (float(v) for v in faces_of(design, spec, rho))
    reach, width = probe_range_mm(), _ROWS["across"].lab[0]
    if across > width:
        return (f"the TCP would lie {across:.3f} mm off the gauge's line (a face is read "
                f"within {width:g} mm of it)")
    if not 0 <= face < STEP_GAUGE_FACES:
        return (f"the TCP would lie {face * STEP_GAUGE_PITCH_MM + along:+.3f} mm along the "
                f"gauge from face 0, outside its faces 0 to {STEP_GAUGE_FACES - 1} "
                f"(0 to {face_lengths()[-1]:g} mm)")
    if abs(along) > reach:
        return (f"the TCP would lie {along:+.3f} mm from face {int(face)}, outside the "
                f"probe's range +-{reach:g} mm")
    return ""


def sigma(conditions: Conditions) -> float:
    """A reading's scatter (mm, a standard deviation) under ``conditions`` (the lab's in
    an ideal world): the probe's, and its resolution's rounding."""
    probe = _ROWS["probe"].at("workshop" if conditions.name == "workshop" else "lab")[0]
    step = _ROWS["resolution"].lab[0]
    return float(np.hypot(probe, step / np.sqrt(12))) * UM


def face_sigmas() -> np.ndarray:
    """Each face's calibration error's standard deviation (mm) beyond the gauge's scale
    error: U's constant part over 2 (face 0 is the reference, 0)."""
    out = np.full(STEP_GAUGE_FACES, _ROWS["calibration"].lab[0] / 2 * UM)
    out[0] = 0.0
    return out


def length_sigma() -> float:
    """The standard deviation of the gauge's scale error (dimensionless): U's part that
    grows with the length, over 2."""
    return _ROWS["calibration_length"].lab[0] / 2 * 1e-6


def cosine_rms(conditions: Conditions) -> float:
    """The RMS of a set-up's cosine error (dimensionless: ``1/cos - 1`` of its
    misalignment, uniform within the table's range) under ``conditions``; zero in an
    ideal world."""
    if not conditions.active:
        return 0.0
    low, high = (v * 1e-3 for v in _ROWS["misalignment"].at(conditions.name))
    # E[(a^2 / 2)^2] for a uniform in [low, high].
    return float(np.sqrt((high**5 - low**5) / (5 * (high - low)) / 4)) if high > low else (
        low * low / 2)


def expansion_rms(conditions: Conditions) -> float:
    """The RMS (dimensionless) of the scale error the room leaves on a step once the lab
    has taken the gauge and the machine to 20 C at its thermometer's reading (20 C
    without one): the two coefficients' difference times the room's departure from that
    reading, bounded by its offset's RMS and an hour of its drift (a thermometer's error,
    0.19 K at most, is less); zero without the room effect."""
    if "room" not in conditions:
        return 0.0
    difference = (EFFECTS["room"]["expansion"].lab[0] - _ROWS["expansion"].lab[0]) * 1e-6
    low, high = conditions.size("room", "offset")
    offset = np.sqrt((low * low + low * high + high * high) / 3.0)
    return float(abs(difference) * (offset + conditions.size("room", "drift")[0]))


@dataclass(frozen=True)
class StepGaugeErrors:
    """A lab's step gauge: its faces' calibration errors (mm, ``(STEP_GAUGE_FACES,)``,
    face 0's 0) and its scale error (dimensionless), and each set-up's misalignment in
    turn as the unit normal of its faces (``(MAX_SETUPS, 3)`` in the axis' frame: the
    axis first, then the two across it)."""

    faces: np.ndarray
    scale: float
    normals: np.ndarray


def draw_errors(conditions: Conditions, stream: np.random.Generator) -> StepGaugeErrors:
    """A lab's step-gauge errors drawn from a jump of ``stream`` (the stream itself does
    not move); zeros in an ideal world."""
    if not conditions.active:
        normals = np.zeros((MAX_SETUPS, 3))
        normals[:, 0] = 1.0
        return StepGaugeErrors(np.zeros(STEP_GAUGE_FACES), 0.0, normals)
    own = np.random.Generator(stream.bit_generator.jumped(_JUMPS))
    faces = own.normal(0.0, 1.0, STEP_GAUGE_FACES) * face_sigmas()
    scale = float(own.normal() * length_sigma())
    angle = draw_range(own, _ROWS["misalignment"].at(conditions.name), (MAX_SETUPS,),
                       scale=1e-3)
    turn = own.uniform(0.0, 2 * np.pi, MAX_SETUPS)
    normals = np.stack([np.cos(angle), np.sin(angle) * np.cos(turn),
                        np.sin(angle) * np.sin(turn)], axis=-1)
    return StepGaugeErrors(faces, scale, normals)


def noise_stream(stream: np.random.Generator) -> np.random.Generator:
    """The stream a lab's probe scatter is drawn from: past the errors' jump, so the
    episode's own stream (its gauges' noise) does not move."""
    return np.random.Generator(stream.bit_generator.jumped(_JUMPS + 1))


def world_normal(axis: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Normals (R, 3) given in their axis' frame (axis first, then the two across it, in
    cyclic order) as world vectors, for world axes ``axis`` (R,)."""
    out = np.zeros(normal.shape)
    for k in range(3):
        out[np.arange(len(axis)), (axis + k) % 3] = normal[:, k]
    return out


def readings(moved: np.ndarray, normal: np.ndarray, axis: np.ndarray, face: np.ndarray,
             errors: tuple[np.ndarray, np.ndarray], growth: tuple[np.ndarray, np.ndarray],
             conditions: Conditions, draws: np.ndarray) -> np.ndarray:
    """What probes read (mm, rounded to the resolution) once the TCPs have ``moved``
    (R, 3, mm, the machine grown with the room) from where they touched face 0, on gauges
    whose faces' world ``normal`` (R, 3) is tilted from world ``axis`` (R,), at faces
    ``face`` (R,) with their gauges' ``errors`` (the faces' (R, FACES) mm and the scale
    (R,)), the room's ``growth`` ((R,) K from 20 C: the room's and the thermometer's
    reading), with standard normal ``draws`` (R,).  The distance is the one between the
    two faces' planes along the probe's axis (the world axis)."""
    faces, scale = errors
    temperature, read = growth
    rows = np.arange(len(axis))
    alpha_machine = EFFECTS["room"]["expansion"].lab[0] * 1e-6
    alpha_gauge = _ROWS["expansion"].lab[0] * 1e-6
    length = (face_lengths()[face] * (1.0 + scale) + faces[rows, face]) * (
        1.0 + alpha_gauge * temperature)
    cosine = normal[rows, axis]
    # Taken to 20 C at the thermometer's reading: the TCP's displacement with the steel's
    # coefficient, the faces' distance with the gauge's.
    value = (np.einsum("ri,ri->r", moved, normal) / (1.0 + alpha_machine * read)
             - length / (1.0 + alpha_gauge * read)) / cosine
    probe = _ROWS["probe"].at("workshop" if conditions.name == "workshop" else "lab")[0]
    step = _ROWS["resolution"].lab[0] * UM
    return np.round((value + probe * UM * draws) / step) * step
