"""A designed experiment as a procedure a technician follows, and its readings sheet.

:class:`Plan` (configured with the design, the agent, the conditions and the budget) plays
a planned agent's experiment (decided at reset, from what the lab shows before the first
move: :class:`~calibrators.agents.base.PlannedAgent`) on the nominal machine of the design,
in an exact-model lab of the given conditions and budget, and writes down what a
technician does: a :class:`Procedure` of numbered steps (mount, drive, lift, engage,
re-mount, read), each with the seconds the lab's time table gives it, and every reading to
take, in step order, as rows of a measurement file whose ``reading_mm`` is left blank
(:func:`write_sheet`).  :func:`place_words` says where a stand goes in a technician's
words.  The filled sheet is read by :mod:`calibrators.workflow.fit`; with the plan its rows
are checked against the steps (:func:`check_sheet`).  The printable page and its pictures
are :mod:`calibrators.workflow.page`'s.

An agent that chooses each move from the last reading (``active``) has no procedure to
write ahead: it is refused by name.  A reference procedure with an instrument
(``iso230-2``, ``ballbar``: :class:`~calibrators.agents.instrument_first.InstrumentFirst`)
plays its fixed programme, and the gauges' part is :data:`PLANNED_GAUGES`'s, decided at the
start of that part (its own ``active`` decides as it reads: ``orthoglide session`` runs
it).  An instrument's set-up and readings are written as
:mod:`calibrators.workflow.instruments` says.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping
from contextlib import closing
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibrators.agents import available, get_agent
from calibrators.agents.base import Agent, PlannedAgent
from calibrators.agents.instrument_first import GAUGES, InstrumentFirst
from calibrators.measurements import COLUMNS, Measurement, Measurements, gauge_name
from calibrators.measurements.csv_file import instrument_cells, instrument_columns
from calibrators.study.episodes import measurements_of, run_episode
from calibrators.study.labs import nominal_lab, nominal_options
from calibrators.workflow.instruments import WORK, work_of_action, work_of_op, work_of_spec
from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    GaugeNoise,
    check_noise,
)
from orthoglide_env.instruments.slots import PLATFORM_AIM, GaugeSpec, Part
from orthoglide_env.lab.engine import TIME_UP
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S, Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import AXIS_NAMES, LEG_NAMES
from orthoglide_env.world.conditions import DEFAULT_CONDITIONS, Conditions
from orthoglide_env.world.table import REFERENCE_LENGTH_MM

#: The sheet's columns: the measurement file's, the step each reading belongs to and the
#: stand it is read on (the technician checks it; ``fit --plan`` checks it against the plan).
SHEET_COLUMNS: tuple[str, ...] = (*COLUMNS, "step", "stand")
#: The files :meth:`Procedure.write` writes: the steps, and the readings sheet.
PLAN_FILE, SHEET_FILE = "plan.json", "readings.csv"
#: What each lab operation is called in a step (an instrument's set-up: its own words,
#: :mod:`calibrators.workflow.instruments`).
ACTIONS: dict[Op, str] = {Op.MOVE: "drive and read", Op.LIFT: "lift", Op.ENGAGE: "engage",
                          Op.REMOUNT: "re-mount", Op.STOP: "stop"}
#: The agent that plays a reference procedure's gauges' part in a written plan.
PLANNED_GAUGES: str = "optimal"


@dataclass(frozen=True)
class Step:
    """One step of a procedure: what to do, how long the lab's time table gives it, and
    which readings (rows of the sheet, from 1) are taken at it."""

    number: int
    action: str
    text: str
    seconds: float
    start_s: float  # the lab clock when it begins
    stand: int | None = None  # 1, 2, ... as the technician numbers the stands
    slot: str | None = None
    rho: list[float] | None = None
    rows: list[int] = field(default_factory=list)
    #: An instrument's set-up (:meth:`~calibrators.workflow.instruments.InstrumentWork.
    #: setup`'s), at a step that sets one up.
    setup: dict[str, Any] | None = None


@dataclass(frozen=True)
class Procedure:
    """A planned agent's experiment as steps, with the stands' places and its sheet, for
    ``gauges`` of the noise it was designed for (None: a plan written before plans named
    their gauges)."""

    agent: str
    budget_s: float
    conditions: dict[str, Any]
    design: dict[str, Any]
    stands: list[dict[str, Any]]  # {"stand", "slot", "place"} as mounted at set-up
    steps: list[Step]
    gauges: GaugeNoise | None
    sheet: list[Measurement] = field(default_factory=list, compare=False)
    #: What the technician should know beyond the steps (e.g. steps left out).
    notes: list[str] = field(default_factory=list)

    @property
    def total_s(self) -> float:
        return float(sum(s.seconds for s in self.steps))

    def summary(self) -> str:
        """The procedure in one line: its agent, steps, readings and time."""
        return (f"agent {self.agent}: {len(self.steps)} steps, {len(self.sheet)} readings, "
                f"{self.total_s / 60:.1f} min on the lab's clock (budget "
                f"{self.budget_s / 60:.0f} min)")

    def gauges_words(self) -> str:
        """The gauges the procedure was designed for, as its page names them."""
        if self.gauges is None:
            return "gauges it does not name"
        return (f"gauges of repeatability {self.gauges.sigma:g} mm read to "
                f"{self.gauges.resolution:g} mm")

    def to_dict(self) -> dict[str, Any]:
        """The procedure as JSON (the sheet is its own file, :func:`write_sheet`)."""
        out = asdict(self)
        out.pop("sheet")
        out["total_s"] = self.total_s
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Procedure:
        """The procedure :meth:`to_dict` wrote (``ValueError`` if it is not one)."""
        try:
            gauges = data.get("gauges")
            return cls(data["agent"], float(data["budget_s"]), dict(data["conditions"]),
                       dict(data["design"]), list(data["stands"]),
                       [Step(**s) for s in data["steps"]],
                       None if gauges is None else check_noise(
                           gauges["sigma"], gauges["resolution"],
                           names=("gauges sigma", "gauges resolution")),
                       notes=[str(n) for n in data.get("notes", [])])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a procedure written by orthoglide plan: {exc}") from None

    def write(self, folder: str | Path) -> list[Path]:
        """Write ``plan.json`` (:meth:`to_dict`) and the readings sheet ``readings.csv``
        (:func:`write_sheet`) into ``folder`` (made if missing); the paths written."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        plan = folder / PLAN_FILE
        plan.write_text(json.dumps(self.to_dict(), indent=1) + "\n", encoding="utf-8")
        return [plan, write_sheet(self, folder / SHEET_FILE)]

    @classmethod
    def read(cls, path: str | Path) -> Procedure:
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path}: cannot read the plan: {exc}") from None
        if not isinstance(data, dict):
            raise ValueError(f"{path}: not a procedure written by orthoglide plan")
        return cls.from_dict(data)


def rho_words(rho: list[float] | tuple[float, ...]) -> str:
    """A command as a controller takes it: mm to the micron."""
    return ", ".join(f"{v:.3f}".rstrip("0").rstrip(".") for v in rho)


def planned_agents() -> list[str]:
    """The registered agents whose experiment can be written down at the start: those that
    decide it then, and the reference procedures with an instrument."""
    return [name for name in available()
            if isinstance(get_agent(name), PlannedAgent | InstrumentFirst)]


def place_words(spec: GaugeSpec, design: MachineDesign) -> str:
    """Where a stand goes and how its dial is read, in a technician's words: the part and
    face, the distance from a named hinge, the measuring direction and which way a
    reading is positive on the sheet (along the world axis, as every reading is)."""
    axis = AXIS_NAMES[spec.axis]
    toward = "+" if spec.approach > 0 else "-"
    side = "-" if spec.approach > 0 else "+"
    pushed = ("away from the stand: the plunger comes out, so a dial that reads plus when "
              "pressed shows minus: write minus what it shows" if spec.approach > 0
              else "toward the stand: the plunger is pushed in, so a dial that reads plus "
              "when pressed shows it: write what it shows")
    if spec.part == Part.BAR:
        leg = LEG_NAMES[spec.leg]
        where = (f"on the {leg} leg's parallelogram, on its bar at "
                 f"{'+' if spec.bar > 0 else '-'}d/2 (the picture of a leg's two bars names "
                 f"each; d = {design.d:g} mm the distance between the bars), "
                 f"{spec.at * design.L:.0f} mm along the bar from "
                 f"the centre of its platform-end hinge ({spec.at:g} of L = {design.L:g} mm), "
                 "on the bar's flat face")
    elif spec.part == Part.CARRIAGE:
        where = (f"on the {LEG_NAMES[spec.leg]} carriage, its face normal to {axis}, at the "
                 "middle of the face with the machine at Zero")
    else:
        others = " and ".join(f"-{AXIS_NAMES[a]}" for a in range(3) if a != spec.axis)
        where = (f"on the platform's -{axis} face, {PLATFORM_AIM:g} mm off its centre toward "
                 f"{others}")
        if spec.part == Part.REFERENCE:
            where += (f", through the {REFERENCE_LENGTH_MM:g} mm gauge block: with the "
                      "machine at Zero hold the block square to that face, set the plunger "
                      "on the block's far face at mid-travel, zero the dial and read it "
                      "there, then take the block away (the stand stays); the dial then "
                      f"reads the bare face once the platform has come {REFERENCE_LENGTH_MM:g} "
                      "mm toward it. Handle the block with gloves: a hand warms it")
    return (f"{where}; the stand on the {side}{axis} side, its plunger pointing {toward}{axis}, "
            f"square to the face. Write a reading positive when the face moves toward +{axis} "
            f"({pushed})")


class Plan:
    """The plan of an experiment, configured: agent ``agent``'s experiment within
    ``budget_s`` seconds on a machine of ``design`` under ``conditions`` (default
    :data:`~orthoglide_env.world.conditions.DEFAULT_CONDITIONS`, the real lab), read
    with gauges of repeatability ``sigma`` and display ``resolution`` (mm; the dial
    gauges' by default, as ``compare`` and :class:`~calibrators.workflow.session.Session`
    read them), a random agent's choices drawn from ``seed``.  ``ValueError`` at
    construction for a budget that is not positive, bad noise, or an agent that decides
    as it reads; :meth:`run` makes the :class:`Procedure`."""

    def __init__(self, design: MachineDesign, *, agent: str = "paper",
                 conditions: Conditions | None = None, budget_s: float = DEFAULT_BUDGET_S,
                 seed: int = 0, instruments: tuple[str, ...] = (),
                 sigma: float = DEFAULT_SIGMA, resolution: float = DEFAULT_RESOLUTION
                 ) -> None:
        if not isinstance(design, MachineDesign):
            raise TypeError(f"design must be a MachineDesign, got {type(design).__name__}")
        if not budget_s > 0:
            raise ValueError(f"budget_s must be a positive number of seconds, got "
                             f"{budget_s:g}")
        self.gauges = check_noise(sigma, resolution, names=("sigma", "resolution"))
        planned_agent(agent)
        self.design, self.agent, self.budget_s, self.seed = design, agent, float(budget_s), seed
        self.conditions = Conditions(DEFAULT_CONDITIONS) if conditions is None else conditions
        self.instruments = tuple(instruments)

    def run(self) -> Procedure:
        """The procedure: the experiment played on the design's nominal machine in the
        exact-model lab; a planned agent's steps do not depend on the machine, so they
        are the real machine's."""
        return make_procedure(self.agent, self.budget_s, self.design, self.conditions,
                              self.seed, self.instruments, sigma=self.gauges.sigma,
                              resolution=self.gauges.resolution)


def planned_agent(agent_name: str) -> Agent:
    """The agent ``agent_name``, a reference procedure's with :data:`PLANNED_GAUGES` for
    its gauges' part; ``ValueError`` for one that decides as it reads."""
    agent = get_agent(agent_name)
    if isinstance(agent, InstrumentFirst):
        agent.gauges = PLANNED_GAUGES
        return agent
    if not isinstance(agent, PlannedAgent):
        raise ValueError(f"agent '{agent_name}' chooses each move from the last readings: its "
                         "experiment cannot be written down ahead; plan one that decides it "
                         f"at the start ({', '.join(planned_agents())})")
    return agent


def make_procedure(agent_name: str, budget_s: float, design: MachineDesign,
                   conditions: Conditions | None = None, seed: int = 0,
                   instruments: tuple[str, ...] = (), *, sigma: float, resolution: float
                   ) -> Procedure:
    """The procedure of agent ``agent_name``'s experiment within ``budget_s`` seconds on a
    machine of ``design`` under ``conditions`` (default
    :data:`~orthoglide_env.world.conditions.DEFAULT_CONDITIONS`, the real lab), in a lab
    owning ``instruments`` (empty: the dial gauges) whose gauges read with repeatability
    ``sigma`` and display ``resolution`` (mm): :meth:`Plan.run`.  ``ValueError`` for an
    agent that decides as it reads, or that needs an instrument the lab does not own."""
    conditions = Conditions(DEFAULT_CONDITIONS) if conditions is None else conditions
    agent = planned_agent(agent_name)
    notes = ([f"after its {'/'.join(agent.needs_instruments)} programme, the gauges' part "
              f"is {PLANNED_GAUGES}'s plan for the time left (the agent's own {GAUGES} "
              "decides as it reads: orthoglide session runs it)"]
             if isinstance(agent, InstrumentFirst) else [])
    # The agent designs its experiment for the gauges' noise the lab shows it: the
    # gauges the real lab reads, or the plan is not the one played there.
    with closing(nominal_lab(agent, design, conditions, budget_s, sigma=sigma,
                             resolution=resolution, instruments=tuple(instruments))) as env:
        writer = _StepWriter(env.unwrapped, agent_name, design)
        episode = run_episode(env, agent, seed, nominal_options(design), watch=writer)
    data = measurements_of(episode.records, episode.time_s, design=design)
    sheet = [m.again(m.reading, m.repetition, m.time_s, None, step, m.temperature_c)
             for m, step in zip(data.items, writer.taken, strict=True)]
    return Procedure(agent_name, float(budget_s), conditions.to_dict(), design.to_dict(),
                     writer.stands, writer.steps, GaugeNoise(sigma, resolution), sheet,
                     notes + ([writer.cut] if writer.cut else []))


class _StepWriter:
    """Writes down each step of a planned agent's episode in ``lab`` as the technician's
    :class:`Step`, and the step each reading of the notebook belongs to."""

    def __init__(self, lab: Any, agent_name: str, design: MachineDesign) -> None:
        self.lab, self.agent_name, self.design = lab, agent_name, design
        self.state = LabState()
        self.steps: list[Step] = []
        self.stands: list[dict[str, Any]] = []
        self.taken: list[int] = []
        #: Why the procedure stops before its plan's end ("": it does not).
        self.cut = ""

    def reset(self, i: int, observation: dict[str, np.ndarray]) -> None:
        slots = self.lab.slots
        self.state.reset(observation)
        self.held = self.state.held
        self.stands = [{"stand": k + 1, "slot": slots[s].slot,
                        "place": place_words(slots[s], self.design)}
                       for k, s in enumerate(self.held) if s < len(slots)]
        engaged = [bool(e) for e in observation["engaged"]]
        read = len(self.lab.records)
        self.steps = [Step(1, "set up", _setup_text(self.stands, engaged), 0.0, 0.0,
                           rows=list(range(1, read + 1)))]
        self.taken = [1] * read
        self.clock = 0.0

    def step(self, i: int, action: Mapping[str, Any], observation: dict[str, np.ndarray],
             info: Mapping[str, Any]) -> None:
        number = len(self.steps) + 1
        if str(info.get("refused", "")).endswith(TIME_UP):
            # The planner's clock ran behind the lab's: the procedure ends at the budget.
            self.cut = f"step {number} would end past the budget: the procedure stops before it"
            return
        if info.get("refused"):
            raise RuntimeError(f"the lab refused step {number} of agent '{self.agent_name}' "
                               f"on the nominal machine: {info['refused']}")
        now = float(observation["time"][0])
        before = len(self.taken)
        read = self.lab.records[before:]
        self.steps.append(describe_step(number, action, now - self.clock, self.clock, read,
                                        before, self.lab.slots, self.design, self.held,
                                        self.state))
        self.taken += [number] * len(read)
        self.state.step(action, observation)
        self.held = self.state.held
        self.clock = now


class LabState:
    """What a step's words depend on beyond its action, followed step by step: the stands'
    slots (``held``, indices into the lab's slots), the instruments on the machine (``on``,
    names of :data:`~calibrators.workflow.instruments.WORK` that are taken off before a
    step that is not a move: the ballbar, the step gauge's probe), and the operations
    that set an instrument up before."""

    def reset(self, observation: Mapping[str, np.ndarray]) -> None:
        self.held = [int(s) for s in observation["slot"]]
        self.on: list[str] = []
        self.set_up: set[Op] = set()

    def step(self, action: Mapping[str, Any], observation: Mapping[str, np.ndarray]) -> None:
        """Follow lab action ``action``, which led to ``observation``."""
        self.held = [int(s) for s in observation["slot"]]
        self.on = [w.name for w in WORK.values() if w.off is not None
                   and np.asarray(observation.get(f"{w.key}_in", [0]))[0]]
        self.set_up.add(Op(int(action["op"])))


def _setup_text(stands: list[dict[str, Any]], engaged: list[bool]) -> str:
    lifted = [s["stand"] for s in stands if not engaged[s["stand"] - 1]]
    return ("Switch the drives on and drive to Zero (rho 0, 0, 0). Mount "
            + ", ".join(f"stand {s['stand']} at {s['slot']}" for s in stands)
            + ", each where the stands' list says. Set each gauge at mid-travel, zero its "
            "dial and write each reading (0.000 unless it moved) on the sheet. The lab "
            "clock (the sheet's time_s) starts at 0 when this step ends"
            + (f"; then lift the plungers of stands {', '.join(map(str, lifted))}"
               if lifted else "") + ".")


def describe_step(number: int, act: Mapping[str, Any], seconds: float, start: float,
                  read: list, first_row: int, slots: tuple[GaugeSpec, ...],
                  design: MachineDesign, held: list[int], state: LabState | None = None
                  ) -> Step:
    """Step ``number``: lab action ``act``, its ``seconds`` from the clock at ``start``, the
    records it ``read`` (rows from ``first_row + 1`` on the sheet), in words for the
    technician, with the stands at the slots ``held`` (indices into ``slots``) and the
    instruments as ``state`` found them before the step (None: none set up)."""
    op = Op(int(act["op"]))
    # Any operation but a move takes the ballbar or the probe off: the technician does it
    # first.
    off = ("".join(WORK[name].off or "" for name in state.on)
           if state is not None and op != Op.MOVE else "")
    work = work_of_op(op)
    if work is not None:
        text, setup = work.setup(act, design, state is None or op not in state.set_up)
        return Step(number, work.action, off + text, seconds, start,
                    rho=[0.0, 0.0, 0.0] if op == Op.ALIGN else
                    [float(v) for v in np.asarray(act["rho"], dtype=float)],
                    rows=list(range(first_row + 1, first_row + len(read) + 1)), setup=setup)
    stand = int(act["stand"]) + 1
    rows = list(range(first_row + 1, first_row + len(read) + 1))
    # Stands by the number the technician gave them, with where they are.
    number_of = {slots[s].slot: k + 1 for k, s in enumerate(held) if s < len(slots)}
    if op == Op.REMOUNT:
        number_of[slots[int(act["slot"])].slot] = stand
    names = [f"stand {number_of[n]} ({n})" if n in number_of else n
             for n in dict.fromkeys(gauge_name(r.spec) for r in read
                                    if work_of_spec(r.spec) is None)]
    names += list(dict.fromkeys(w.reading(r, design) for r in read
                                if (w := work_of_spec(r.spec)) is not None))
    if op == Op.MOVE:
        rho = [float(v) for v in np.asarray(act["rho"], dtype=float)]
        reading = (f"read {', '.join(names)} onto the sheet" if names
                   else "no reading (every gauge is lifted)")
        return Step(number, ACTIONS[op], f"Drive to rho = ({rho_words(rho)}) "
                    f"mm, wait until it settles, {reading}.", seconds, start, rho=rho,
                    rows=rows)
    if op == Op.LIFT:
        return Step(number, ACTIONS[op], f"{off}Lift the plunger of stand {stand} with its "
                    "lever.",
                    seconds, start, stand, rows=rows)
    if op == Op.ENGAGE:
        return Step(number, ACTIONS[op], f"{off}Let the plunger of stand {stand} down on its face "
                    "again (its zero is kept).", seconds, start, stand, rows=rows)
    if op == Op.REMOUNT:
        slot = slots[int(act["slot"])]
        return Step(number, ACTIONS[op], f"{off}Drive to Zero. Move stand {stand} to {slot.slot}: "
                    f"{place_words(slot, design)}. Set the gauge at mid-travel and zero its "
                    f"dial. Then, at Zero, read {', '.join(names)} onto the sheet.", seconds,
                    start, stand, slot.slot, rows=rows)
    return Step(number, ACTIONS[op], f"{off}The experiment is over: lift every plunger and switch "
                "the drives off.", seconds, start, rows=rows)


def write_sheet(procedure: Procedure, path: str | Path) -> Path:
    """The readings sheet: one row per reading to take, in step order, the measurement
    file's columns, ``step`` and ``stand`` (then an instrument's columns, for a lab with
    one: :func:`~calibrators.measurements.csv_file.instrument_columns`, and those that
    guide its reader, :attr:`~calibrators.workflow.instruments.InstrumentWork.columns`:
    a step gauge's ``face``, which ``fit`` checks), ``reading_mm`` blank (``time_s`` the
    planned time: write the clock's when it differs)."""
    path = Path(path)
    extra = instrument_columns(procedure.sheet)
    design = MachineDesign.from_dict(procedure.design)
    guides = [w for w in WORK.values()
              if w.columns and any(isinstance(m.gauge, w.spec) for m in procedure.sheet)]
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([*SHEET_COLUMNS, *extra, *(c for w in guides for c in w.columns)])
        reading = COLUMNS.index("reading_mm")
        for m, stand in zip(procedure.sheet, stand_numbers(procedure), strict=True):
            row = m.csv_row()
            row[reading] = ""
            writer.writerow([*row, str(m.step), "" if stand is None else str(stand),
                             *instrument_cells(m, extra),
                             *(c for w in guides for c in (
                                 w.cells(m, design) if isinstance(m.gauge, w.spec)
                                 else [""] * len(w.columns)))])
    return path


def sheet_readers(procedure: Procedure) -> list[str]:
    """Where the printed sheet says each row is read: its stand's number (a dial's), or
    its instrument's word for it (a step gauge's face), else blank."""
    design = MachineDesign.from_dict(procedure.design)
    return [str(stand) if stand is not None
            else w.label(m, design) if (w := work_of_spec(m.gauge)) is not None else ""
            for m, stand in zip(procedure.sheet, stand_numbers(procedure), strict=True)]


def stands_held(procedure: Procedure) -> dict[int, dict[str, int]]:
    """The stand on each slot during each step, by step number: the set-up's stands, as
    each re-mount moves one."""
    held = {s["slot"]: s["stand"] for s in procedure.stands}
    out = {}
    for step in procedure.steps:
        if step.action == "re-mount":
            held = {slot: k for slot, k in held.items() if k != step.stand}
            held[step.slot] = step.stand
        out[step.number] = held
    return out


def stand_numbers(procedure: Procedure) -> list[int | None]:
    """The number of the stand each row of the sheet is read on (None: on no stand, the
    tracker's), by the stands the set-up mounts and each re-mount's move."""
    held = stands_held(procedure)
    out: list[int | None] = [None] * len(procedure.sheet)
    for step in procedure.steps:
        for row in step.rows:
            out[row - 1] = held[step.number].get(gauge_name(procedure.sheet[row - 1].gauge))
    return out


class SheetError(ValueError):
    """Readings that are not a filled sheet of the plan they are checked against."""


def check_sheet(data: Measurements, procedure: Procedure) -> None:
    """:class:`SheetError` naming the line of the first reading of ``data`` that the plan does
    not hold: a step it does not have, or a dial at a place no stand holds at that step, a
    posture or a stand other than that step's (a reading without a stand is not checked
    for one: sheets before the stand column)."""
    steps = {s.number: s for s in procedure.steps}
    held = stands_held(procedure)
    for m in data.items:
        where = f"line {m.line}" if m.line is not None else "a reading"
        if m.step is None:
            raise SheetError(f"{where}: no step: a sheet of the plan numbers every reading")
        step = steps.get(m.step)
        if step is None:
            raise SheetError(f"{where}: step {m.step} is not in the plan (steps 1 .. "
                             f"{len(procedure.steps)})")
        if (step.action not in ("set up", "drive and read", "re-mount")
                and work_of_action(step.action) is None):
            raise SheetError(f"{where}: step {m.step} ({step.action}) takes no reading")
        # A re-mount reads every stand at Zero, the moved one at its new place: a dial
        # reads where a stand is held at its step.
        if isinstance(m.gauge, GaugeSpec) and gauge_name(m.gauge) not in held[m.step]:
            moved = (f" (stand {step.stand} is moved to {step.slot} there)"
                     if step.slot is not None else "")
            raise SheetError(f"{where}: step {m.step} has no stand at {m.gauge.slot}{moved}; "
                             f"its stands are at {', '.join(held[m.step])}")
        if step.rho is not None and tuple(step.rho) != m.rho:
            raise SheetError(f"{where}: step {m.step} is at rho {tuple(step.rho)}, not "
                             f"{m.rho}")
        stand = held[m.step].get(gauge_name(m.gauge))
        if m.stand is not None and m.stand != stand:
            planned = "on no stand" if stand is None else f"on stand {stand}"
            raise SheetError(f"{where}: step {m.step} reads {gauge_name(m.gauge)} {planned}, "
                             f"not on stand {m.stand}: read the stand the sheet names, or "
                             "plan again for the stands as mounted")
