"""What a technician does with each instrument beyond the dial gauges: its set-up in
words and in a picture, what its reading on the sheet is, and which answers cannot be
its reading.

:data:`WORK` holds one :class:`InstrumentWork` per instrument that a lab sets up by an
operation of its own (the interferometer's ``align``, the ballbar's ``pivot``, the step
gauge's ``place``); the plan
(:mod:`calibrators.workflow.plan`), its page (:mod:`calibrators.workflow.page`) and the
session (:mod:`calibrators.workflow.session`) find an instrument there by its set-up
operation or by the kind of its readings, so another instrument plugs in by one entry.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from orthoglide_env.instruments import ballbar, interferometer, step_gauge
from orthoglide_env.lab.notebook import Record
from orthoglide_env.lab.operations import TIME, Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import AXIS_NAMES, LEG_NAMES, MachineParams
from orthoglide_env.model.kinematics import carriage_points, direct
from orthoglide_env.world.table import (
    EFFECTS,
    INSTRUMENT_ERRORS,
    STEP_GAUGE_FACES,
    STEP_GAUGE_PITCH_MM,
    STEP_GAUGE_SOURCE,
)


def _words(rho: Any) -> str:
    return ", ".join(f"{float(v):.3f}".rstrip("0").rstrip(".") for v in rho)


class InstrumentWork:
    """An instrument's part of the workflow (subclass one per instrument, and list it in
    :data:`WORK`)."""

    #: The instrument's name (``--instruments``) and the reading file's ``instrument``.
    name: ClassVar[str]
    #: The lab operation that sets it up, and a set-up step's action on the page.
    op: ClassVar[Op]
    action: ClassVar[str]
    #: The kind of its readings' gauge (a reading model's spec).
    spec: ClassVar[type]
    #: The unit an answer is given in, as the session asks for it.
    unit: ClassVar[str] = "mm"
    #: Its keys in the lab's observation: ``key`` (the reading), ``key + "_valid"``, and
    #: ``key + "_in"`` while it is on the machine (where :attr:`off` is given).
    key: ClassVar[str]
    #: What the technician does first at a step that is not a move while it is on the
    #: machine (the lab takes it off then); None: it stays on (the laser).
    off: ClassVar[str | None] = None
    #: The sheet's columns its rows fill beyond the measurement file's (:meth:`cells`).
    columns: ClassVar[tuple[str, ...]] = ()

    def setup(self, act: Mapping[str, Any], design: MachineDesign, first: bool
              ) -> tuple[str, dict[str, Any]]:
        """A set-up step's words for lab action ``act`` (``first``: the lab's first set-up
        of this instrument), and the set-up as the step keeps it (JSON; what
        :meth:`draw` draws)."""
        raise NotImplementedError

    def reading(self, record: Record, design: MachineDesign) -> str:
        """What to write on the sheet for ``record`` (a reading of the nominal machine of
        ``design``), in words."""
        raise NotImplementedError

    def cells(self, record: Any, design: MachineDesign) -> list[str]:
        """A sheet row's cells of :attr:`columns` for ``record`` (a lab's record or a
        measurement: its ``gauge`` or ``spec`` and ``rho``)."""
        return []

    def label(self, record: Any, design: MachineDesign) -> str:
        """Where the printed sheet says a row of ``record`` is read, in a word or two
        (a dial's row names its stand)."""
        return ""

    def before(self, design: MachineDesign) -> list[str]:
        """The page's paragraph on the instrument: what it needs and how it is read."""
        raise NotImplementedError

    def draw(self, design: MachineDesign, setup: Mapping[str, Any], out: Path,
             title: str) -> Path:
        """A picture of the set-up ``setup`` (:meth:`setup`'s) on the nominal machine of
        ``design``, written to ``out``."""
        raise NotImplementedError

    def impossible(self, value: float, record: Record, design: MachineDesign) -> str | None:
        """Why ``value`` (mm) cannot be the reading of ``record`` (the nominal machine's of
        ``design``); None if it can be."""
        raise NotImplementedError


#: What an interferometer's reading on the sheet is.
DEVIATION: str = ("the deviation: the count (compensated for the air and the material "
                  "temperature) less the command's move since the count was zeroed, mm, "
                  "positive when the carriage went further toward rho_max than commanded")


class InterferometerWork(InstrumentWork):
    """The laser interferometer along one drive (ISO 230-2)."""

    name, op, action, key = "interferometer", Op.ALIGN, "set up the laser", "interferometer"
    spec = interferometer.InterferometerAxis

    def setup(self, act: Mapping[str, Any], design: MachineDesign, first: bool
              ) -> tuple[str, dict[str, Any]]:
        axis = AXIS_NAMES[int(act["axis"])]
        leg = LEG_NAMES[int(act["axis"])]
        soak = (f" Put the material sensor on the {leg} drive's frame beside the screw and "
                f"the air sensor near the beam, and let both soak "
                f"{TIME.interferometer_soak_s / 60:.0f} min before you zero (this first "
                "set-up's time holds it); they stay on for every drive after"
                if first else " Move the material sensor to the "
                f"{leg} drive's frame beside the screw")
        text = (f"Drive to Zero. Set the laser interferometer up along the {leg} drive: "
                "the laser head on its tripod behind the drive's outer end, its beam beside "
                f"the drive and along it; the retroreflector on a bracket of the {leg} "
                "carriage, in the beam; the linear "
                "interferometer (beam splitter) fixed to the base between them, as close to "
                "the carriage as it goes (a short dead path). Align the beam: jog the "
                "carriage over its whole stroke and steer the head until the return spot "
                "stays centred (the beam within "
                f"{INSTRUMENT_ERRORS['interferometer']['alignment'].lab[1]:g} mrad of the "
                f"travel).{soak}. At Zero, zero the count and write its reading (0.000) on "
                f"the sheet. Until the next set-up, every move's reading is {DEVIATION}.")
        return text, {"instrument": self.name, "axis": axis}

    def reading(self, record: Record, design: MachineDesign) -> str:
        return f"the laser's deviation along {AXIS_NAMES[record.spec.axis]}"

    def before(self, design: MachineDesign) -> list[str]:
        rows = INSTRUMENT_ERRORS["interferometer"]
        return [
            "A laser interferometer with its air sensor and material sensor (the machine's "
            "expansion compensated at the material temperature it reads, "
            f"{EFFECTS['room']['expansion'].lab[0]:g} um/(m K) for steel); the retroreflector "
            "rides on the carriage of the drive it measures, the beam along that drive. "
            "Only that drive moves during its runs: the reading is the carriage's "
            "true position against its command, with no kinematic model in between.",
            "The compensation's settings: the material's expansion as above, the air "
            f"sensor on, the count in mm. Its reading on the sheet is {DEVIATION} (the "
            "laser software's 'error' column), to 0.1 um. A run approaches every target "
            "from the same side, going up, then every target coming down (the overshoot "
            "postures are read too: write them).",
            f"The sizes the fit assumes: scatter {rows['noise'].lab[0]:g} um in a still room; "
            f"the air compensation within {rows['air'].lab[1]:g} ppm; the material sensor "
            f"within {rows['material_sensor'].lab[1]:g} K. Keep the beam off the "
            "drive's motor and away from draughts.",
        ]

    def draw(self, design: MachineDesign, setup: Mapping[str, Any], out: Path,
             title: str) -> Path:
        axis = AXIS_NAMES.index(setup["axis"])
        machine = MachineParams(design=design)
        rho = np.zeros(3)
        ends = []
        for value in (design.rho_min, design.rho_max):
            rho[axis] = value
            ends.append(carriage_points(machine, rho)[axis])
        inner, outer = sorted(ends, key=np.linalg.norm)
        carriage = carriage_points(machine, np.zeros(3))[axis]
        out_way = (outer - inner) / np.linalg.norm(outer - inner)
        # The beam runs beside the drive, to a retroreflector on a bracket of the carriage.
        side = 45.0 * _side(out_way)
        head = outer + 90.0 * out_way + side
        splitter = carriage + 35.0 * out_way + side
        marks = [(head, "laser head, behind the drive's outer end", "red"),
                 (splitter, "linear interferometer, on the base", "darkorange"),
                 (carriage + side, f"retroreflector on the {LEG_NAMES[axis]} carriage", "red"),
                 ((inner + outer) / 2, "material sensor, on the drive's frame", "navy")]
        lines = [(np.array([head, carriage + side]), "red", 2.5),
                 (np.array([carriage, carriage + side]), "dimgray", 4.0),
                 (np.array(ends), "green", 5.0)]
        return _machine_picture(machine, np.zeros(3), marks, lines, out, title,
                                f"green: the {LEG_NAMES[axis]} carriage's stroke, "
                                f"rho {design.rho_min:g} .. {design.rho_max:g} mm; red: the "
                                "beam, beside the drive")

    def impossible(self, value: float, record: Record, design: MachineDesign) -> str | None:
        # Each set-up zeroes its count at Zero: the command's move is the posture's.
        nominal, moved = record.reading, float(record.rho[record.spec.axis])
        if abs(value - nominal) <= LASER_DEVIATION_MM:
            return None
        count = (f" (it is the command's move, {moved:+.3f} mm, give or take: write the count "
                 "less that move)" if abs(value - moved) <= LASER_DEVIATION_MM else "")
        return (f"{value:+.4f} mm is more than {LASER_DEVIATION_MM:g} mm from the carriage's "
                f"command{count}: read it again")


def _laser_deviation_mm() -> float:
    """The largest deviation (mm) a carriage can show against its command on a machine
    a lab calibrates: twice the workshop's largest lead error (linear, curve and
    periodic), warm-up and lost motion, summed; an answer beyond it is a wrong number."""
    sizes = [EFFECTS["lead"][k].workshop[1] for k in ("scale", "curve", "periodic")]
    sizes += [EFFECTS["warmup"]["amplitude"].workshop[1],
              EFFECTS["backlash"]["lost_motion"].workshop[1]]
    return 2e-3 * float(sum(sizes))


#: A laser reading further than this (mm) from the command is asked again.
LASER_DEVIATION_MM: float = _laser_deviation_mm()


class BallbarWork(InstrumentWork):
    """The telescoping ballbar between the tool cup and a pivot on the base (ISO 230-4)."""

    name, op, action, key = "ballbar", Op.PIVOT, "set up the ballbar", "ballbar"
    spec = ballbar.BallbarSpec
    off = "Take the ballbar off (the tool cup and the pivot stay). "

    def setup(self, act: Mapping[str, Any], design: MachineDesign, first: bool
              ) -> tuple[str, dict[str, Any]]:
        centre = [float(v) for v in np.asarray(act["rho"], dtype=float)]
        length = ballbar.length_of(int(act["bar"]))
        travel = ballbar.travel_mm()
        text = (f"Drive to rho = ({_words(centre)}) mm, the circles' centre. Fix the centre "
                "pivot's magnetic mount on the base under the tool cup and set its ball "
                "into the cup, then lock the mount: the pivot's centre is the TCP here. "
                f"Set the {length:g} mm bar up in its calibrator (the bar's length, as its "
                "software asks) and let it lie on the machine to take its temperature. "
                "Fit the bar between the tool cup and the pivot at the next step's "
                "posture, the first of the run; it stays in for every move after, up to "
                "the next step that is not a move: take it off before that one. Each "
                f"move's reading is the bar's length less {length:g} mm (mm, positive when "
                f"longer; within +-{travel:g} mm, else the move would break the bar: "
                "stop).")
        return text, {"instrument": self.name, "pivot": centre, "bar_mm": length}

    def reading(self, record: Record, design: MachineDesign) -> str:
        return f"the ballbar (its length less {record.spec.length:g} mm)"

    def before(self, design: MachineDesign) -> list[str]:
        rows = INSTRUMENT_ERRORS["ballbar"]
        return [
            "A telescoping ballbar with its centre pivot (a magnetic mount) and the tool "
            f"cup on the platform. Its travel is +-{rows['travel'].lab[0]:g} mm about its "
            f"nominal length; it reads to {rows['resolution'].lab[0]:g} um. Every move "
            "with the bar in is read, the machine at rest at the point (the time table's "
            "settle), each circle run anticlockwise and clockwise from a short "
            "overshoot arc.",
            "Steel like the machine: the room's growth cancels on a reading. Handle the "
            "bar by its grips: a hand warms it.",
        ]

    def draw(self, design: MachineDesign, setup: Mapping[str, Any], out: Path,
             title: str) -> Path:
        machine = MachineParams(design=design)
        centre_rho = np.asarray(setup["pivot"], dtype=float)
        centre = direct(machine, centre_rho)
        radius = float(setup["bar_mm"])
        angles = np.linspace(0, 2 * np.pi, 73)
        lines = []
        for plane, colour in zip(((0, 1), (1, 2), (2, 0)), ("green", "darkorange", "purple"),
                                 strict=True):
            points = np.repeat(centre[None, :], len(angles), axis=0)
            points[:, plane[0]] += radius * np.cos(angles)
            points[:, plane[1]] += radius * np.sin(angles)
            lines.append((points, colour, 1.5))
        start = centre.copy()
        start[0] += radius
        lines.append((np.array([centre, start]), "red", 4.0))
        marks = [(centre, "centre pivot (at the TCP of the centre posture)", "red"),
                 (start, f"the {radius:g} mm bar, the TCP at the circle's first point",
                  "red")]
        return _machine_picture(machine, centre_rho, marks, lines, out, title,
                                "the circles the TCP runs: XY green, YZ orange, ZX purple",
                                focus=centre, zoom=3.0)

    def impossible(self, value: float, record: Record, design: MachineDesign) -> str | None:
        travel = ballbar.travel_mm()
        if abs(value) <= travel:
            return None
        return (f"{value:+.4f} mm is outside the ballbar's travel (+-{travel:g} mm about its "
                "length): read it again (the bar's length less its nominal one)")


#: What a step gauge's reading on the sheet is.
PROBE_READING: str = ("the probe's reading at the face, mm: the TCP's distance past the face "
                      "along the gauge, positive when it lies further toward the gauge's far "
                      "end (the tip pressed in: write what a probe that reads plus when "
                      "pressed shows)")


class StepGaugeWork(InstrumentWork):
    """The step gauge along a world axis through the workspace, its faces read by a probe
    in the tool cup (a KOBA-type gauge)."""

    name, op, action, key = "step-gauge", Op.PLACE, "set up the step gauge", "step_gauge"
    spec = step_gauge.StepGaugeSpec
    off = ("Lift the probe off the gauge and take the gauge off its supports, out of the "
           "machine's way. ")
    columns = ("face",)

    def setup(self, act: Mapping[str, Any], design: MachineDesign, first: bool
              ) -> tuple[str, dict[str, Any]]:
        axis = AXIS_NAMES[int(act["axis"])]
        start = [float(v) for v in np.asarray(act["rho"], dtype=float)]
        rows = INSTRUMENT_ERRORS["step-gauge"]
        last = STEP_GAUGE_FACES - 1
        text = (f"Drive to rho = ({_words(start)}) mm: the TCP is where face 0 goes. "
                f"Lay the step gauge along {axis} through the workspace on its two supports, "
                "each at the support mark its certificate gives (its Airy or Bessel "
                "points: there it sags least; upright along a vertical axis, clamped at "
                "them), face 0 at the tool cup and the faces running "
                f"toward +{axis} (face k lies k x {STEP_GAUGE_PITCH_MM:g} mm further; face "
                f"{last} at {last * STEP_GAUGE_PITCH_MM:g} mm). Align it: square it to "
                f"{axis} against the machine's frame, then jog along +{axis} with an "
                "indicator in the tool cup on the gauge's side and turn the gauge until the "
                f"indicator changes by less than {rows['misalignment'].lab[1]:g} mm per metre "
                f"of travel ({rows['misalignment'].lab[1] * last * STEP_GAUGE_PITCH_MM / 1e3:g}"
                " mm over its length). The gauge lives in the room, soaked to it (one brought "
                "in soaks first, off the clock); handle it by its supports, with gloves. "
                "Fix the length probe in the tool cup, its tip pointing "
                f"+{axis} onto face 0's measuring face, at mid-range, and zero it there; "
                "write its reading (about 0) on the sheet. Until the next step that is not "
                "a move, every move drives to a face: lift the tip clear of the gauge while "
                "the machine drives, let it down on the face once the machine has settled, "
                f"and write {PROBE_READING}.")
        return text, {"instrument": self.name, "axis": axis, "start": start}

    def reading(self, record: Record, design: MachineDesign) -> str:
        return f"the step gauge's probe at face {_face(record.spec, record.rho, design)}"

    def cells(self, record: Any, design: MachineDesign) -> list[str]:
        spec = getattr(record, "gauge", None) or record.spec
        return [str(_face(spec, record.rho, design))]

    def label(self, record: Any, design: MachineDesign) -> str:
        return f"face {self.cells(record, design)[0]}"

    def before(self, design: MachineDesign) -> list[str]:
        rows = INSTRUMENT_ERRORS["step-gauge"]
        machine, gauge = EFFECTS["room"]["expansion"].lab[0], rows["expansion"].lab[0]
        last = STEP_GAUGE_FACES - 1
        reach = last * STEP_GAUGE_PITCH_MM * (machine - gauge) * 1e-3
        return [
            f"A step gauge (KOBA-type) of {STEP_GAUGE_FACES} faces "
            f"{STEP_GAUGE_PITCH_MM:g} mm apart ({STEP_GAUGE_SOURCE}), on two supports, and an "
            "electronic length probe in the tool cup. Its certificate gives each face's "
            f"distance from face 0 within U = {rows['calibration'].lab[0]:g} um + "
            f"{rows['calibration_length'].lab[0]:g} um/m x L (k = 2); the fit takes the "
            "nominal distances and carries U as their error. Laid along a world axis "
            "through the workspace, it reads the machine's positioning along that axis: "
            "the drives' lead error and lost motion, through the kinematics.",
            f"The probe reads within +-{rows['range'].lab[0]:g} mm of face 0's zero, to "
            f"{rows['resolution'].lab[0]:g} um, with a scatter of {rows['probe'].lab[0]:g} um "
            f"in a still room ({rows['probe'].workshop[0]:g} um on a shop floor); it meets "
            f"a face within {rows['across'].lab[0]:g} mm of the gauge's line. Its reading "
            f"on the sheet is {PROBE_READING}. A run goes up the gauge face by face and "
            "back down: the machine reaches each face going up and coming down (the "
            "reversal shows lost motion); write every reading, both ways, as the sheet "
            "lists them.",
            f"The gauge's expansion is {rows['expansion'].lab[0]:g} um/(m K), the machine's "
            f"steel {machine:g}: with a room thermometer, take a reading to 20 C as the fit "
            f"reads it, less {machine - gauge:.1f} um per metre of the face's distance from "
            f"face 0 and per K of the room above 20 C (on face {last}, {reach:.3f} um per K: "
            "well under the probe's resolution near 20 C); without one, write it as read. "
            "It assumes "
            "the gauge "
            f"laid within {rows['misalignment'].lab[1]:g} mrad of its axis in a lab "
            f"({rows['misalignment'].workshop[1]:g} in a workshop): a step then reads long "
            "by 1/cos - 1 of it. The sizes are the world table's step-gauge rows "
            "(orthoglide conditions lists them with their sources).",
        ]

    def draw(self, design: MachineDesign, setup: Mapping[str, Any], out: Path,
             title: str) -> Path:
        axis = AXIS_NAMES.index(setup["axis"])
        machine = MachineParams(design=design)
        start = np.asarray(setup["start"], dtype=float)
        first = direct(machine, start)
        way = np.eye(3)[axis]
        faces = first + np.outer(step_gauge.face_lengths(), way)
        across = 6.0 * _side(way)
        lines = [(faces[[0, -1]], "green", 6.0)]
        lines += [(np.array([f - across, f + across]), "black", 1.5) for f in faces]
        last = STEP_GAUGE_FACES - 1
        marks = [(first, "face 0: the probe in the tool cup, zeroed on it", "red"),
                 (faces[-1], f"face {last}, {last * STEP_GAUGE_PITCH_MM:g} mm along "
                  f"+{setup['axis']}", "green")]
        return _machine_picture(machine, start, marks, lines, out, title,
                                f"green: the step gauge along {setup['axis']}, a face every "
                                f"{STEP_GAUGE_PITCH_MM:g} mm (black); its supports at the "
                                "certificate's marks", focus=faces.mean(axis=0), zoom=2.0)

    def impossible(self, value: float, record: Record, design: MachineDesign) -> str | None:
        spec, rho = record.spec, np.asarray(record.rho, dtype=float)
        face = _face(spec, record.rho, design)
        reach = step_gauge.probe_range_mm()
        if abs(value) > reach:
            distance = face * STEP_GAUGE_PITCH_MM
            hint = (f" (it is face {face}'s distance from face 0, {distance:g} mm, give or "
                    "take: write the probe's reading only)" if abs(value - distance) <= reach
                    else " (in um? write mm)" if abs(value) * 1e-3 <= reach else "")
            return (f"{value:+.4f} mm is outside the probe's range (+-{reach:g} mm about its "
                    f"zero on face 0){hint}: read it again")
        bound = probe_deviation_mm(design, spec, rho)
        if abs(value - record.reading) <= bound:
            return None
        return (f"{value:+.4f} mm puts the TCP {value - record.reading:+.4f} mm from where the "
                f"nominal machine puts it at face {face}, more than a machine's drives and "
                f"geometry move it ({bound:.3f} mm): read it again (the probe on face "
                f"{face})")


def _face(spec: step_gauge.StepGaugeSpec, rho: Any, design: MachineDesign) -> int:
    """The face of ``spec``'s gauge that the nominal machine of ``design`` puts the TCP at,
    at command ``rho``."""
    return int(step_gauge.faces_of(design, spec, np.asarray(rho, dtype=float))[0])


#: How far (mm) a machine's geometry may move a step-gauge reading from the nominal
#: machine's: an assumption, above the 0.157 mm that the geometry of 200 realistic
#: machines (seeds 0-199) moved a reading of the ``step-gauge`` agent's faces by
#: (tests/test_workflow_instruments.py checks 50 of them).
GEOMETRY_ALONG_MM: float = 0.2


def probe_deviation_mm(design: MachineDesign, spec: step_gauge.StepGaugeSpec,
                       rho: np.ndarray) -> float:
    """The largest change (mm) a machine of ``design`` can show in a step-gauge reading of
    ``spec`` at command ``rho`` against the nominal machine's: each drive's deviation
    (:data:`LASER_DEVIATION_MM`, from face 0's set-up to this face) through the nominal
    machine's gain from the drives to the TCP along the gauge (the larger of the two
    postures'; 1 on a world axis through Zero), plus what the geometry moves it by
    (:data:`GEOMETRY_ALONG_MM`)."""
    machine = MachineParams(design=design)
    h = 1e-3  # mm: the model solves to 1e-11 mm, so a central difference is exact to ~1e-8
    gains = []
    for command in (np.asarray(spec.start, dtype=float), rho):
        shifted = command + np.concatenate([np.eye(3), -np.eye(3)]) * h
        tcp = direct(machine, shifted)[:, spec.axis]
        gains.append(float(np.sum(np.abs(tcp[:3] - tcp[3:]) / (2 * h))))
    return LASER_DEVIATION_MM * max(gains) + GEOMETRY_ALONG_MM


#: Every instrument a lab sets up by an operation of its own, by name.
WORK: dict[str, InstrumentWork] = {w.name: w for w in (InterferometerWork(), BallbarWork(),
                                                      StepGaugeWork())}


def work_of_op(op: Op) -> InstrumentWork | None:
    """The instrument set up by lab operation ``op`` (None: a dial gauges' operation)."""
    return next((w for w in WORK.values() if w.op == op), None)


def work_of_spec(spec: Any) -> InstrumentWork | None:
    """The instrument a reading of ``spec`` is of (None: a dial gauge's or the tracker's)."""
    return next((w for w in WORK.values() if isinstance(spec, w.spec)), None)


def work_of_action(action: str) -> InstrumentWork | None:
    """The instrument a step of ``action`` sets up (None: no instrument's set-up)."""
    return next((w for w in WORK.values() if w.action == action), None)


def used_in(actions: list[str]) -> list[InstrumentWork]:
    """The instruments that steps of ``actions`` set up, in :data:`WORK`'s order."""
    return [w for w in WORK.values() if w.action in actions]


def _side(way: np.ndarray) -> np.ndarray:
    """A unit vector square to ``way`` (to set a label off a line)."""
    other = np.cross(way, [0.0, 0.0, 1.0])
    if np.linalg.norm(other) < 1e-9:
        other = np.cross(way, [1.0, 0.0, 0.0])
    return other / np.linalg.norm(other)


def _machine_picture(machine: MachineParams, rho: np.ndarray,
                     marks: list[tuple[np.ndarray, str, str]],
                     lines: list[tuple[np.ndarray, str, float]], out: Path, title: str,
                     legend: str, focus: np.ndarray | None = None, zoom: float = 1.0,
                     width: int = 960, height: int = 720) -> Path:
    """The machine at ``rho`` seen as the stands' pictures see it (aimed at ``focus`` and
    magnified ``zoom`` times, when given), with ``lines`` (world points, colour, width)
    drawn over it and ``marks`` (world point, label, colour) labelled, the world axes in a
    corner, ``title`` on top and ``legend`` below."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from orthoglide_env.sim.pybullet import OrthoglideMachine, square_on_camera
    from orthoglide_env.sim.report import draw_world_axes, project

    eye, target, fov = square_on_camera(width / height, machine.design)
    if focus is not None:
        eye, target = focus + (eye - target), focus
        fov = float(np.degrees(2 * np.arctan(np.tan(np.radians(fov) / 2) / zoom)))
    sim = OrthoglideMachine(machine, [])
    try:
        sim.move(rho)
        frame = sim.render(width, height, eye=eye, target=target, fov=fov)
    finally:
        sim.close()
    figure = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    try:
        axes = figure.add_axes((0, 0, 1, 1))
        axes.imshow(frame)
        axes.set_axis_off()
        for points, colour, lw in lines:
            pixels = project(points, eye, target, fov, width, height)
            axes.plot(pixels[:, 0], pixels[:, 1], color=colour, lw=lw, alpha=0.9)
        # Labels in a column at the right, each with its arrow: none hides another.
        for k, (point, label, colour) in enumerate(marks):
            u, v = project(point[None, :], eye, target, fov, width, height)[0]
            axes.plot(u, v, "o", ms=8, mfc="white", mec=colour, mew=2)
            axes.annotate(label, (u, v), xytext=(0.7 * width, 80 + 45 * k), color=colour,
                          fontsize=10, ha="center",
                          bbox={"boxstyle": "round", "fc": "white", "alpha": 0.85},
                          arrowprops={"arrowstyle": "->", "lw": 1.2, "color": colour})
        draw_world_axes(axes, eye, target, fov, width, height)
        axes.text(10, 24, title, fontsize=13, bbox={"fc": "white", "alpha": 0.85})
        axes.text(150, height - 14, legend, fontsize=10, bbox={"fc": "white", "alpha": 0.85})
        out.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(out, dpi=100)
    finally:
        plt.close(figure)
    return out
