"""The workflow with the interferometer, the ballbar and the step gauge: `plan` writes
their procedures and sheets (for the prototype and for a custom design), `fit --plan`
reads a filled one, `session` asks for their readings."""

from __future__ import annotations

import csv
import json
from contextlib import closing
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from calibrators.cli import main
from calibrators.measurements import Measurements
from calibrators.measurements.record import instrument_of
from calibrators.study.episodes import machine_seed, measurements_of, run_episode
from calibrators.study.labs import make_lab
from calibrators.workflow.instruments import (
    GEOMETRY_ALONG_MM,
    LASER_DEVIATION_MM,
    PROBE_READING,
    WORK,
    probe_deviation_mm,
)
from calibrators.workflow.plan import SHEET_FILE, planned_agent
from calibrators.workflow.session import Session
from orthoglide_env.instruments.ballbar import travel_mm
from orthoglide_env.instruments.step_gauge import StepGaugeSpec, probe_range_mm
from orthoglide_env.model.design import PROTOTYPE, MachineDesign, load_design
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import STEP_GAUGE_FACES, STEP_GAUGE_PITCH_MM

LAB = Conditions("lab")
#: The smallest budgets that hold each programme (one ISO 230-2 run per drive; the
#: three planes' circles; one step-gauge run per axis) and a few gauge readings after
#: it: the tests stay cheap.
CASES = {"iso230-2": (("dial", "interferometer"), 3000.0),
         "ballbar": (("dial", "ballbar"), 1500.0),
         "step-gauge": (("dial", "step-gauge"), 1500.0)}
SEED = 3
#: A custom design (a shorter stroke than the step gauge's 160 mm, a smaller machine).
SMALL = Path(__file__).resolve().parents[1] / "examples" / "designs" / "small.json"
#: Each instrument's procedure on the prototype, and on the custom design.
PLANS = [(name, design) for design in (None, SMALL) for name in sorted(CASES)]


def _true_lab(agent: Any, instruments: tuple[str, ...], budget: float,
              sigma: float = 0.02, resolution: float = 0.01,
              design: MachineDesign = PROTOTYPE) -> Any:
    """A lab of a realistic machine of ``design`` under ``lab`` conditions, as calibrate
    builds it, its gauges of repeatability ``sigma`` and ``resolution`` (mm)."""
    return make_lab(agent, backend="exact", errors="realistic", gauge_sigma=sigma,
                    gauge_resolution=resolution, budget_s=budget, conditions=LAB,
                    instruments=instruments, design=design)


@pytest.fixture(scope="module", params=PLANS,
                ids=[f"{n}-{'small' if d else 'prototype'}" for n, d in PLANS])
def planned(request, tmp_path_factory) -> tuple[str, Path, MachineDesign]:
    name, design = request.param
    instruments, budget = CASES[name]
    out = tmp_path_factory.mktemp(name)
    chosen = [] if design is None else ["--design", str(design)]
    assert main(["plan", "--agent", name, "--instruments", ",".join(instruments),
                 "--budget", str(budget), "--out", str(out), *chosen]) == 0
    return name, out, PROTOTYPE if design is None else load_design(design)


def test_the_page_shows_each_set_up_and_the_sheet_its_rows(planned) -> None:
    """Each set-up of the instrument is a step with its words and its picture on the page;
    the sheet's rows of the instrument name it (and a ballbar's and a step gauge's its
    set-up, a step gauge's its face, within the design's reach), blank."""
    name, out, design = planned
    work = WORK[CASES[name][0][1]]
    plan = json.loads((out / "plan.json").read_text())
    setups = [s for s in plan["steps"] if s["action"] == work.action]
    # ISO 230-2 sets the laser up on each drive, the step gauge is laid along each axis;
    # ISO 230-4's circles share one pivot.
    assert len(setups) == (1 if work.name == "ballbar" else 3)
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
    if work.name == "step-gauge":
        # Face 0 at the stroke's back end; as many faces as the stroke holds (all 9 on
        # the prototype's 160 mm, 7 on the small design's 130 mm); each step names its face.
        stroke = design.rho_max - design.rho_min
        count = min(STEP_GAUGE_FACES, int(stroke // STEP_GAUGE_PITCH_MM) + 1)
        assert {int(r["face"]) for r in own} == set(range(count))
        assert all(float(r[f"start_{a}"]) == design.rho_min for r in own
                   for a in "xyz" if a == r["axis"])
        steps = {s["number"]: s["text"] for s in plan["steps"]}
        assert all(f"face {r['face']}" in steps[int(r["step"])] for r in own
                   if r["step"] not in {str(s["number"]) for s in setups})
        assert PROBE_READING in setups[0]["text"]


def test_a_written_procedure_ends_within_its_budget_as_planned(planned) -> None:
    """The gauges' part after the instrument's programme is planned on the lab's clock
    (the laser the ISO 230-2 programme leaves set up charges each move its dwell): no
    step would end past the budget, so the procedure is not cut short, and its steps
    follow one another on the sheet's clock."""
    name, out, _ = planned
    plan = json.loads((out / "plan.json").read_text())
    assert not [n for n in plan["notes"] if "past the budget" in n]
    ends = [s["start_s"] + s["seconds"] for s in plan["steps"]]
    assert ends[-1] <= CASES[name][1]
    assert all(s["start_s"] == pytest.approx(end, abs=1e-9)
               for s, end in zip(plan["steps"][1:], ends, strict=False))


def test_a_sheet_filled_in_a_lab_fits_as_the_labs_own_readings(planned, tmp_path,
                                                                 capsys) -> None:
    """The plan's sheet, filled row by row with what a lab of a realistic machine read
    playing the same procedure (a row its gauge did not read there deleted, as the page
    says), is what that lab wrote down: `fit --plan` reads it back to the same estimate
    as the lab's own readings of those rows (bit for bit: nothing is lost in the sheet's
    columns)."""
    name, out, design = planned
    instruments, budget = CASES[name]
    agent = planned_agent(name)
    # As the plan was made: its seed (0; the machine it draws is a realistic one) and
    # its gauges (the dial gauges'), for whose noise the planned gauges' part chooses.
    with closing(_true_lab(agent, instruments, budget, design=design)) as env:
        episode = run_episode(env, agent, 0)
    lab = measurements_of(episode.records, episode.time_s, design=design)
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
    lab = replace(lab, items=[m for m in lab.items if id(m) not in unplanned])
    sheet = tmp_path / "filled.csv"
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    own = tmp_path / "lab.csv"
    lab.write(own)
    # A CSV file carries no design: the lab's own file is fitted with the design's file,
    # the sheet with its plan's design.
    chosen = tmp_path / "design.json"
    chosen.write_text(json.dumps(design.to_dict()))
    estimates = []
    for argv in ([str(sheet), "--plan", str(out / "plan.json")],
                 [str(own), "--conditions", "lab", "--design", str(chosen)]):
        assert main(["fit", *argv, "--json"]) == 0
        estimates.append(json.loads(capsys.readouterr().out)["estimate"])
    assert estimates[0] == estimates[1]


class _Technician:
    """Answers a session's questions with what a lab of a realistic machine reads,
    stepped with each action the session announces; ``slips``: the first reading of the
    instrument where a slip shows is first given wrong (a ballbar's past its travel, a
    laser's count in place of its deviation, a probe's face distance added to its
    reading)."""

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
            kind = question["instrument"]
            key = WORK[kind].key
            if kind == "ballbar":
                self.slips = False
                return 1.5 * travel_mm()
            if kind == "interferometer":
                self.slips = False
                axis = "xyz".index(question["what"][-1])
                return float(self.observation[key][0]) + question["rho"][axis]
            face = int(question["what"].split()[-1])
            if face > 0:  # face 0's distance is 0: no slip shows there
                self.slips = False
                return float(self.observation[key][0]) + face * STEP_GAUGE_PITCH_MM
        if "instrument" in question:
            key = WORK[question["instrument"]].key
            return (float(self.observation[key][0])
                    if self.observation[f"{key}_valid"][0] else None)
        k = question["stand"] - 1
        return float(self.observation["gauges"][k]) if self.observation["valid"][k] else None


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_a_session_asks_each_instrument_reading_and_re_asks_an_impossible_one(
        name: str, tmp_path: Path) -> None:
    """A session of the reference procedure asks every reading the lab of the true
    machine takes, the instrument's by name; a slip (a ballbar reading past its travel,
    a laser's count in place of its deviation, a face's distance in place of the probe's
    reading) is asked again with the reason, and no true reading is (the bounds hold
    this realistic machine's), so the readings written are the lab's own; its notebook
    replays to the same readings."""
    instruments, budget = CASES[name]
    kind = instruments[1]
    session = Session(name, budget, tmp_path / "notebook.jsonl", design=PROTOTYPE,
                      conditions=LAB, seed=machine_seed(SEED, 0), instruments=instruments)
    with closing(_true_lab(session.agent, instruments, budget)) as env:
        technician = _Technician(env, slips=True)
        data = session.run(technician.answer, technician.say)
        truth = measurements_of(env.unwrapped.records, 0.0, design=PROTOTYPE)
    assert len(technician.again) == 1
    assert {"ballbar": "travel", "interferometer": "the command's move",
            "step-gauge": "distance from face 0"}[kind] in technician.again[0]
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
    assert laser.impossible(0.030, record, PROTOTYPE) is None
    assert "command's move" in laser.impossible(-40.0 + 0.012, record, PROTOTYPE)
    assert laser.impossible(0.5, record, PROTOTYPE) is not None
    assert WORK["ballbar"].impossible(-travel_mm() * 1.01, record, PROTOTYPE) is not None


def test_a_probe_reading_outside_its_range_or_far_from_the_face_is_impossible() -> None:
    """A probe reading is asked again when the probe cannot show it (past its range, the
    face's distance from face 0 or um named as the likely slip) or when it puts the TCP
    further from where the nominal machine puts it at that face than the drives can (the
    laser's bound through the drives' gain to the TCP along the gauge)."""
    from calibrators.agents.step_gauge import face_command
    from orthoglide_env.lab.notebook import Record

    spec = StepGaugeSpec(0, tuple(face_command(PROTOTYPE, 0, 0)))
    rho = tuple(face_command(PROTOTYPE, 0, 3))
    record = Record(spec, "step-gauge#1", rho, 0.004, 9, 100.0)
    probe = WORK["step-gauge"]
    bound = probe_deviation_mm(PROTOTYPE, spec, np.asarray(rho))
    # On the x axis through Zero the x drive carries the TCP one to one (the y and z
    # drives' moves leave x alone): the laser's bound and the geometry's, inside the
    # probe's range (so the check catches a slip the range lets through).
    assert bound == pytest.approx(LASER_DEVIATION_MM + GEOMETRY_ALONG_MM, rel=1e-6)
    assert bound < probe_range_mm()
    assert probe.impossible(0.004 + 0.9 * bound, record, PROTOTYPE) is None
    far = probe.impossible(0.004 + 1.1 * bound, record, PROTOTYPE)
    assert "face 3" in far and "nominal machine" in far
    assert "distance from face 0" in probe.impossible(60.012, record, PROTOTYPE)
    assert "in um?" in probe.impossible(41.0, record, PROTOTYPE)
    assert "range" in probe.impossible(-probe_range_mm() * 1.01, record, PROTOTYPE)


def test_the_geometry_moves_a_step_reading_by_less_than_its_allowance() -> None:
    """On 50 realistic machines (27 geometric errors each, noise-free) the geometry moves
    every face's reading of the step-gauge agent's set-ups, against the nominal machine's,
    by less than GEOMETRY_ALONG_MM (measured over 200: 0.157 mm at most, 0.06 mm at the
    95th percentile)."""
    from calibrators.agents.step_gauge import face_command, faces_in_reach
    from orthoglide_env.model.errors import MachineParams, random_machine
    from orthoglide_env.model.kinematics import direct

    nominal = MachineParams(design=PROTOTYPE)
    rho = np.array([[face_command(PROTOTYPE, axis, f) for f in range(faces_in_reach(
        PROTOTYPE))] for axis in range(3)])  # (axis, face, 3)
    along = np.arange(3)[:, None]
    expected = np.take_along_axis(direct(nominal, rho), along[..., None], -1)[..., 0]
    worst = 0.0
    for seed in range(50):
        true = np.take_along_axis(direct(random_machine(seed, "realistic",
                                                        design=PROTOTYPE), rho),
                                  along[..., None], -1)[..., 0]
        moved = (true - true[:, :1]) - (expected - expected[:, :1])
        worst = max(worst, float(np.abs(moved).max()))
    assert 0.0 < worst < GEOMETRY_ALONG_MM
