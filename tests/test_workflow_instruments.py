"""The workflow with the interferometer and the ballbar: `plan` writes their procedures
and sheets, `fit --plan` reads a filled one, `session` asks for their readings."""

from __future__ import annotations

import csv
import json
from contextlib import closing
from pathlib import Path
from typing import Any

import pytest

from calibrators.cli import main
from calibrators.measurements import Measurements
from calibrators.measurements.record import instrument_of
from calibrators.study.episodes import machine_seed, measurements_of, run_episode
from calibrators.study.labs import make_lab
from calibrators.workflow.instruments import LASER_DEVIATION_MM, WORK
from calibrators.workflow.plan import SHEET_FILE, planned_agent
from calibrators.workflow.session import Session
from orthoglide_env.instruments.ballbar import travel_mm
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

LAB = Conditions("lab")
#: The smallest budgets that hold each programme (one ISO 230-2 run per drive; the
#: three planes' circles) and a few gauge readings after it: the tests stay cheap.
CASES = {"iso230-2": (("dial", "interferometer"), 3000.0),
         "ballbar": (("dial", "ballbar"), 1500.0)}
SEED = 3


def _true_lab(agent: Any, instruments: tuple[str, ...], budget: float,
              sigma: float = 0.02, resolution: float = 0.01) -> Any:
    """A lab of a realistic machine under ``lab`` conditions, as calibrate builds it, its
    gauges of repeatability ``sigma`` and ``resolution`` (mm)."""
    return make_lab(agent, backend="exact", errors="realistic", gauge_sigma=sigma,
                    gauge_resolution=resolution, budget_s=budget, conditions=LAB,
                    instruments=instruments)


@pytest.fixture(scope="module", params=sorted(CASES))
def planned(request, tmp_path_factory) -> tuple[str, Path]:
    name = request.param
    instruments, budget = CASES[name]
    out = tmp_path_factory.mktemp(name)
    assert main(["plan", "--agent", name, "--instruments", ",".join(instruments),
                 "--budget", str(budget), "--out", str(out)]) == 0
    return name, out


def test_the_page_shows_each_set_up_and_the_sheet_its_rows(planned) -> None:
    """Each set-up of the instrument is a step with its words and its picture on the page;
    the sheet's rows of the instrument name it (and a ballbar's its set-up), blank."""
    name, out = planned
    work = WORK[CASES[name][0][1]]
    plan = json.loads((out / "plan.json").read_text())
    setups = [s for s in plan["steps"] if s["action"] == work.action]
    # ISO 230-2 sets the laser up on each drive; ISO 230-4's circles share one pivot.
    assert len(setups) == (3 if work.name == "interferometer" else 1)
    page = (out / "procedure.html").read_text()
    for step in setups:
        assert step["setup"]["instrument"] == work.name
        picture = out / f"step-{step['number']}.png"
        assert picture.read_bytes()[:4] == b"\x89PNG"
        assert f'<img src="{picture.name}"' in page
    assert f"<h2>The {work.name}</h2>" in page
    rows = list(csv.DictReader((out / SHEET_FILE).open()))
    own = [r for r in rows if r["instrument"] == work.name]
    assert own and all(r["reading_mm"] == "" for r in rows)
    if work.name == "ballbar":
        assert {r["bar_mm"] for r in own} == {"50.0"}
    else:
        assert {r["axis"] for r in own} == {"x", "y", "z"}


def test_a_sheet_filled_in_a_lab_fits_as_the_labs_own_readings(planned, tmp_path,
                                                                 capsys) -> None:
    """The plan's sheet, filled row by row with what a lab of a realistic machine read
    playing the same procedure (a row its gauge did not read there deleted, as the page
    says), is what that lab wrote down: `fit --plan` reads it back to the same estimate
    as the lab's own readings of those rows (bit for bit: nothing is lost in the sheet's
    columns)."""
    name, out = planned
    instruments, budget = CASES[name]
    agent = planned_agent(name)
    # As the plan was made: its seed (0; the machine it draws is a realistic one) and
    # its gauges' noise (none), from which the planned gauges' part makes its choices.
    with closing(_true_lab(agent, instruments, budget, 0.0, 0.0)) as env:
        episode = run_episode(env, agent, 0)
    lab = measurements_of(episode.records, episode.time_s, design=PROTOTYPE)
    read = {(m.mounting, m.rho, m.time_s): m for m in lab.items}
    rows = []
    for row in csv.DictReader((out / SHEET_FILE).open()):
        key = (row["mounting"], tuple(float(row[f"rho_{a}"]) for a in "xyz"),
               float(row["time_s"]))
        if key in read:
            rows.append({**row, "reading_mm": repr(read.pop(key).reading)})
    # The true machine's plungers leave their travel at a few postures the nominal one
    # reads, and read at a few it does not; the instrument reads every one.
    assert sum(r["instrument"] == instruments[1] for r in rows) == sum(
        instrument_of(m.gauge) == instruments[1] for m in lab.items)
    assert len(rows) > 0.9 * len(lab.items)
    unplanned = set(map(id, read.values()))
    lab = Measurements([m for m in lab.items if id(m) not in unplanned],
                       experiment_time_s=lab.experiment_time_s)
    sheet = tmp_path / "filled.csv"
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    own = tmp_path / "lab.csv"
    lab.write(own)
    estimates = []
    for argv in ([str(sheet), "--plan", str(out / "plan.json")],
                 [str(own), "--conditions", "lab"]):
        assert main(["fit", *argv, "--json"]) == 0
        estimates.append(json.loads(capsys.readouterr().out)["estimate"])
    assert estimates[0] == estimates[1]


class _Technician:
    """Answers a session's questions with what a lab of a realistic machine reads,
    stepped with each action the session announces; ``slips``: the first reading of the
    instrument is first given wrong (a ballbar's past its travel, a laser's count in
    place of its deviation)."""

    def __init__(self, env: Any, slips: bool) -> None:
        self.env, self.slips = env, slips
        self.observation, _ = env.reset(seed=machine_seed(SEED, 0))
        self.again: list[str] = []
        self.asked: list[dict[str, Any]] = []

    def say(self, text: str, action: dict[str, Any] | None = None) -> None:
        if action is not None:
            self.observation, *_ = self.env.step(action)

    def answer(self, question: dict[str, Any]) -> float | None:
        self.asked.append(question)
        if "again" in question:
            self.again.append(question["again"])
        elif self.slips and "instrument" in question and question["rho"] != [0.0] * 3:
            self.slips = False
            if question["instrument"] == "ballbar":
                return 1.5 * travel_mm()
            axis = "xyz".index(question["what"][-1])
            return float(self.observation["interferometer"][0]) + question["rho"][axis]
        if "instrument" in question:
            kind = question["instrument"]
            return (float(self.observation[kind][0])
                    if self.observation[f"{kind}_valid"][0] else None)
        k = question["stand"] - 1
        return float(self.observation["gauges"][k]) if self.observation["valid"][k] else None


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_session_asks_each_instrument_reading_and_re_asks_an_impossible_one(
        name: str, tmp_path: Path) -> None:
    """A session of the reference procedure asks every reading the lab of the true
    machine takes, the instrument's by name; a slip (a ballbar reading past its travel,
    a laser's count in place of its deviation) is asked again with the reason, and the
    readings written are the lab's own; its notebook replays to the same readings."""
    instruments, budget = CASES[name]
    kind = instruments[1]
    session = Session(name, budget, tmp_path / "notebook.jsonl", design=PROTOTYPE,
                      conditions=LAB, seed=machine_seed(SEED, 0), instruments=instruments)
    with closing(_true_lab(session.agent, instruments, budget)) as env:
        technician = _Technician(env, slips=True)
        data = session.run(technician.answer, technician.say)
        truth = measurements_of(env.unwrapped.records, 0.0, design=PROTOTYPE)
    assert len(technician.again) == 1
    assert ("travel" if kind == "ballbar" else "the command's move") in technician.again[0]
    assert any(q.get("instrument") == kind for q in technician.asked)
    assert [(m.mounting, m.rho, m.reading) for m in data.items] == [
        (m.mounting, m.rho, m.reading) for m in truth.items]
    replayed = Session(name, budget, tmp_path / "notebook.jsonl", design=PROTOTYPE,
                       conditions=LAB, seed=machine_seed(SEED, 0), instruments=instruments)
    again = replayed.run(lambda q: pytest.fail(f"asked {q} on a replay"), lambda *a: None)
    assert isinstance(again, Measurements) and again.items == data.items


def test_a_laser_reading_far_from_the_command_is_impossible() -> None:
    """The bound sits above any carriage's deviation a machine's table allows and far
    below a stroke's move: the count typed in place of its deviation is caught, and
    named."""
    from orthoglide_env.instruments.interferometer import InterferometerAxis
    from orthoglide_env.lab.notebook import Record

    record = Record(InterferometerAxis(0), "interferometer.x#1", (-40.0, 0.0, 0.0), 0.012,
                    9, 100.0)
    laser = WORK["interferometer"]
    # The workshop's largest lead, warm-up and lost motion sum to 94 um: twice that.
    assert LASER_DEVIATION_MM == pytest.approx(0.188)
    assert laser.impossible(0.030, record) is None
    assert "command's move" in laser.impossible(-40.0 + 0.012, record)
    assert laser.impossible(0.5, record) is not None
    assert WORK["ballbar"].impossible(-travel_mm() * 1.01, record) is not None
