"""A sequential experiment with a person (or a script) at the machine.

:class:`Session` runs an agent that decides as it reads (``active``) in an exact-model lab
of the design's nominal machine, which gives only the steps' timing and which readings
each step takes.  The readings themselves come from ``answer``, a person typing or a
digital readout.  Before the agent sees a step, that step's readings in the lab's notebook
and observation are replaced by the answers. A reading the gauge could not give
(``-``: out of travel, no contact) is taken out.  Every answer is appended to the session's
notebook file at once, so a crash loses nothing; a session started again on that file
replays it (``resume``) and goes on where it stopped.  The session ends when the agent
stops (at its target predicted error, or when nothing is worth the time) or at the budget.

An impossible answer is asked again (the question then holds ``again``, the reason): one
outside the gauge's travel, or one whose change since its mounting's first answer differs
from the nominal machine's by more than a machine's errors move one reading
(:data:`~calibrators.estimators.faults.NOMINAL_MM`).  Where the nominal machine's gauge
gives no reading (past its travel, off its bar) there is nothing to compare with, and
only the travel is checked.  A stand that reads far from 0 back
at Zero, where its dial was zeroed, may have been knocked: the session says so and asks for
the reading again after a re-zero; an answer near 0 then starts a new mounting of that
stand from that reading on (its own zero for the fit), the same answer again keeps the old
one.

A lab with an instrument beyond the gauges (``--instruments``: the interferometer, the
ballbar, the step gauge) asks for its readings too, after the stands', each question
naming the instrument and what its reading is (:mod:`calibrators.workflow.instruments`);
an answer that cannot be its reading (a ballbar's outside its travel, a laser's far from
the carriage's command, a probe's outside its range or far from where the nominal machine
puts the TCP at its face) is asked again.

The episode is :func:`~calibrators.study.episodes.run_episode`'s, the session watching each
step (:class:`~calibrators.study.episodes.Watcher`) to say it and ask its readings.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from contextlib import closing
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from calibrators.agents import get_agent
from calibrators.agents.base import PlannedAgent
from calibrators.estimators.faults import NOMINAL_MM
from calibrators.measurements import Measurements, gauge_name
from calibrators.study.episodes import run_episode
from calibrators.study.labs import nominal_lab, nominal_options
from calibrators.workflow.instruments import work_of_spec
from calibrators.workflow.plan import SHEET_FILE, LabState, describe_step
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.lab.notebook import Record
from orthoglide_env.lab.operations import Op, slot_catalogue
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.world.conditions import DEFAULT_CONDITIONS, Conditions

#: Back at Zero, a stand reading more than this many of its sigma (plus the dial's
#: resolution) from 0 may have been knocked.
ZERO_K: float = 5.0

#: What an answer is asked for: (step number, what to do, stand (1, 2, ...), gauge name,
#: rho, lab clock (s); an instrument's reading: ``instrument`` and ``what`` in place of
#: the stand); it returns the reading (mm) or None (the gauge gave none).
Answer = Callable[[dict[str, Any]], float | None]


class Session:
    """A sequential experiment of agent ``agent_name`` (see the module docstring); its
    notebook file ``notebook`` (JSON lines: one answer each) is written as it goes and
    replayed when it exists."""

    def __init__(self, agent_name: str, budget_s: float, notebook: str | Path, *,
                 design: MachineDesign, conditions: Conditions | None = None,
                 seed: int = 0, target_mm: float = 0.0, sigma: float = DEFAULT_SIGMA,
                 resolution: float = DEFAULT_RESOLUTION,
                 instruments: tuple[str, ...] = ()) -> None:
        if not budget_s > 0:
            raise ValueError(f"the budget must be a positive number of seconds, got "
                             f"{budget_s:g}")
        if not target_mm >= 0:
            raise ValueError(f"the target must be 0 (none) or a positive mm, got {target_mm:g}")
        self.agent = get_agent(agent_name)
        if isinstance(self.agent, PlannedAgent):
            raise ValueError(f"agent '{agent_name}' decides its whole experiment at the start: "
                             "write it down with orthoglide plan instead")
        if hasattr(self.agent, "target_mm"):
            self.agent.target_mm = target_mm
        elif target_mm:
            raise ValueError(f"agent '{agent_name}' has no target error to stop at")
        self.design, self.seed = design, seed
        self.tolerance = ZERO_K * sigma + resolution
        # mounting: (answer, nominal reading) at its first answer the nominal lab read too.
        self.first: dict[str, tuple[float, float]] = {}
        self.rezeroed: dict[str, str] = {}  # a lab mounting's name: the name it goes by now
        self.notebook = Path(notebook)
        self.replay = _read_notebook(self.notebook)
        self.env = nominal_lab(self.agent, design,
                               Conditions(DEFAULT_CONDITIONS) if conditions is None else conditions,
                               budget_s, sigma=sigma, resolution=resolution,
                               instruments=tuple(instruments))
        self.answered = 0

    def run(self, answer: Answer, say: Callable[..., None] = print) -> Measurements:
        """The experiment to its end; ``answer`` gives each reading asked for (replayed
        answers first), ``say`` is told each step (its words, and the lab action after the
        set-up).  The readings, as a measurement file holds them (:meth:`write` saves
        them)."""
        with closing(self.env):
            episode = run_episode(self.env, self.agent, self.seed,
                                  nominal_options(self.design), watch=_Asker(self, answer, say))
        return episode.measurements

    @staticmethod
    def write(readings: Measurements, folder: str | Path) -> list[Path]:
        """Write the session's ``readings`` as :data:`~calibrators.workflow.plan.SHEET_FILE`
        into ``folder`` (made if missing), for :mod:`calibrators.workflow.fit`; the paths
        written."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        readings.write(folder / SHEET_FILE)
        return [folder / SHEET_FILE]

    def _answer(self, number: int, text: str, observation: dict[str, np.ndarray],
                first: int, held: list[int], answer: Answer,
                moved: tuple[float, ...] | None = None) -> None:
        """Replace the notebook's and the observation's readings from ``first`` on by the
        answers.  Asked are the stands the nominal lab read, and after a move to ``moved``
        (its rho) every stand in service: the real machine may read where the nominal
        one could not.  In stand order, as the lab writes its notebook."""
        lab = self.env.unwrapped
        slots = slot_catalogue(self.design)
        stand_of = {slots[s]: k for k, s in enumerate(held) if s < len(slots)}
        records = lab.records
        nominal = {stand_of[r.spec]: r for r in records[first:] if work_of_spec(r.spec) is None}
        own = [r for r in records[first:] if work_of_spec(r.spec) is not None]
        asked = set(nominal)
        if moved is not None:
            asked |= {k for k, s in enumerate(held)
                      if s < len(slots) and observation["engaged"][k]}
        template = records[first] if len(records) > first else None
        kept = records[:first]
        for stand in sorted(asked):
            predicted = stand in nominal
            record = nominal.get(stand) or Record(
                slots[held[stand]], lab.mountings[stand],
                template.rho if template else moved,
                0.0, template.step if template else number - 1,
                template.time_s if template else float(observation["time"][0]))
            question = {"step": number, "text": text, "stand": stand + 1,
                        "gauge": gauge_name(record.spec), "rho": list(record.rho),
                        "time_s": record.time_s}
            value = self._given(question, {"stand": stand + 1},
                                lambda q, r=record, p=predicted: self._checked(q, r, answer, p))
            observation["valid"][stand] = value is not None
            observation["gauges"][stand] = 0.0 if value is None else value
            if value is not None:
                mounting = self._mounting(record, float(value), predicted)
                kept.append(replace(record, reading=float(value), mounting=mounting))
        for record in own:
            work = work_of_spec(record.spec)
            question = {"step": number, "text": text, "instrument": work.name,
                        "what": work.reading(record, self.design), "gauge": record.mounting,
                        "rho": list(record.rho), "time_s": record.time_s}
            value = self._given(question, {"instrument": work.name}, lambda q, r=record, w=work:
                                _asked_again(q, answer,
                                             lambda v: w.impossible(v, r, self.design)))
            observation[f"{work.key}_valid"][0] = value is not None
            observation[work.key][0] = 0.0 if value is None else value
            if value is not None:
                kept.append(replace(record, reading=float(value)))
        records[:] = kept

    def _given(self, question: dict[str, Any], who: dict[str, Any],
               ask: Callable[[dict[str, Any]], float | None]) -> float | None:
        """The answer to ``question`` of the reader ``who`` (its stand, or its
        instrument): the notebook's next one when it replays, else ``ask``'s, written to
        the notebook at once."""
        if self.answered < len(self.replay):
            given = self.replay[self.answered]
            if given["who"] != who or given["step"] != question["step"]:
                raise ValueError(f"{self.notebook}: answer {self.answered + 1} is for "
                                 f"step {given['step']}, {_who(given['who'])}, but the "
                                 f"session asks step {question['step']}, {_who(who)}: "
                                 "not this session's notebook")
            value = given["reading_mm"]
        else:
            value = ask(question)
            with self.notebook.open("a", encoding="utf-8") as handle:
                handle.write(json.dumps({"step": question["step"], **who,
                                         "gauge": question["gauge"],
                                         "reading_mm": value}) + "\n")
        self.answered += 1
        return value

    def _checked(self, question: dict[str, Any], record: Record, answer: Answer,
                 predicted: bool) -> float | None:
        """The answer to ``question`` (of the nominal lab's ``record``, whose reading is
        the nominal machine's where ``predicted``), asked again with the reason when it is
        impossible or when a stand back at Zero reads far from its zero (a re-zero
        offered: an answer near 0 then starts a new mounting); the second answer stands."""
        value = answer(question)
        reason = None if value is None else self._impossible(record, value, predicted)
        if reason is None:
            return value
        again = answer({**question, "again": reason})
        if (again is not None and "re-zero" in reason and abs(again) <= self.tolerance
                and again != value):
            mounting = self.rezeroed.get(record.mounting, record.mounting)
            self.rezeroed[record.mounting] = f"{mounting}+re-zeroed"
        return again

    def _impossible(self, record: Record, value: float, predicted: bool) -> str | None:
        """Why ``value`` cannot be ``record``'s reading (its nominal one where
        ``predicted``), or why it is suspect; None if it is neither."""
        # A reading at the end of the travel may pass it by its noise and rounding.
        reach = self.env.unwrapped.travel / 2 + self.tolerance
        if abs(value) > reach:
            return (f"{value:+.3f} mm is outside the gauge's travel (+-{reach:g} mm about "
                    "its zero, with its noise): read it again")
        mounting = self.rezeroed.get(record.mounting, record.mounting)
        if mounting not in self.first:
            return None
        # Against the mounting's first answer, not the last: NOMINAL_MM bounds one
        # reading's offset from the nominal machine's, and a change between two readings
        # carries two such offsets.
        before, nominal = self.first[mounting]
        off = (value - before) - (record.reading - nominal) if predicted else 0.0
        if abs(off) > NOMINAL_MM:
            return (f"{value:+.3f} mm is {off:+.3f} mm from what the nominal machine reads "
                    f"there, its stand's first reading {before:+.3f} mm taken as its zero: "
                    "read it again")
        if not any(record.rho) and abs(value) > self.tolerance:
            return (f"back at Zero the stand reads {value:+.3f} mm, where its dial was "
                    "zeroed: it may have been knocked; re-zero its dial and give the "
                    "reading again (the same answer keeps the old zero)")
        return None

    def _mounting(self, record: Record, value: float, predicted: bool) -> str:
        """The mounting ``record``'s answer ``value`` belongs to (a re-zeroed stand's new
        one), which keeps it as its reference when it is its first ``predicted`` one."""
        mounting = self.rezeroed.get(record.mounting, record.mounting)
        if predicted:
            self.first.setdefault(mounting, (value, record.reading))
        return mounting


class _Asker:
    """Watches a session's episode: says each step and puts the answers to its readings
    into the lab's notebook and observation before the agent sees them."""

    def __init__(self, session: Session, answer: Answer, say: Callable[..., None]) -> None:
        self.session, self.answer, self.say = session, answer, say
        self.lab = session.env.unwrapped
        self.slots = slot_catalogue(session.design)
        self.state = LabState()

    def reset(self, i: int, observation: dict[str, np.ndarray]) -> None:
        self.state.reset(observation)
        self.held = self.state.held
        self.say("Step 1: drive to Zero, mount the stands ("
                 + ", ".join(f"stand {k + 1} at {self.slots[s].slot}"
                             for k, s in enumerate(self.held) if s < len(self.slots))
                 + "), set each gauge at mid-travel and zero its dial.")
        self.session._answer(1, "set up", observation, 0, self.held, self.answer)
        self.number, self.clock, self.before = 1, 0.0, len(self.lab.records)

    def step(self, i: int, action: Mapping[str, Any], observation: dict[str, np.ndarray],
             info: Mapping[str, Any]) -> None:
        self.number += 1
        now = float(observation["time"][0])
        step = describe_step(self.number, action, now - self.clock, self.clock,
                             self.lab.records[self.before:], self.before, self.slots,
                             self.session.design, self.held, self.state)
        self.say(f"Step {self.number} ({step.seconds:.0f} s, clock {self.clock / 60:.1f} min): "
                 f"{step.text}", action)
        self.state.step(action, observation)
        self.held = self.state.held
        self.session._answer(self.number, step.text, observation, self.before, self.held,
                             self.answer,
                             moved=tuple(float(v) for v in np.asarray(action["rho"]))
                             if int(action["op"]) == Op.MOVE else None)
        self.clock, self.before = now, len(self.lab.records)


def _read_notebook(path: Path) -> list[dict[str, Any]]:
    """The answers a session's notebook holds (none when it does not exist)."""
    if not path.exists():
        return []
    out = []
    for line_number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            item = json.loads(line)
            value = item["reading_mm"]
            if value is not None and not (isinstance(value, int | float)
                                          and not isinstance(value, bool)
                                          and np.isfinite(value)):
                raise ValueError
            who = ({"instrument": str(item["instrument"])} if "instrument" in item
                   else {"stand": int(item["stand"])})
            out.append({"step": int(item["step"]), "who": who, "reading_mm": value})
        except (ValueError, KeyError, TypeError):
            raise ValueError(f"{path}:{line_number}: not an answer of a session's "
                             "notebook") from None
    return out


def _who(who: dict[str, Any]) -> str:
    """A reader in words: ``stand 3``, or ``the interferometer``."""
    return f"stand {who['stand']}" if "stand" in who else f"the {who['instrument']}"


def _asked_again(question: dict[str, Any], answer: Answer,
                 impossible: Callable[[float], str | None]) -> float | None:
    """The answer to ``question``, asked once more with the reason when ``impossible``
    gives one; the second answer stands."""
    value = answer(question)
    reason = None if value is None else impossible(value)
    return value if reason is None else answer({**question, "again": reason})


def parse_answer(text: str) -> float | None:
    """A typed answer: a reading in mm, ``-`` for none, or a JSON line
    ``{"reading_mm": 0.12}`` (``null`` for none); ``ValueError`` otherwise."""
    text = text.strip()
    if text == "-":
        return None
    if text.startswith("{"):
        try:
            value = json.loads(text)["reading_mm"]
        except (ValueError, KeyError, TypeError):
            raise ValueError("a JSON answer is {\"reading_mm\": number or null}") from None
        if value is None:
            return None
    else:
        value = text
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"not a reading: {text!r} (a number in mm, or - for none)") from None
    if isinstance(value, bool) or not np.isfinite(number) or abs(number) > 100:
        raise ValueError(f"not a reading: {text!r} (a finite number of mm within +-100)")
    return number
