"""``orthoglide plan``: a designed experiment as a technician's procedure, and its sheet
read back by ``fit --plan``."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from contextlib import closing
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import TABLE1, command_here

from calibrators.agents import get_agent
from calibrators.cli import main
from calibrators.measurements import Measurement, Measurements
from calibrators.study.compare import Config
from calibrators.study.episodes import machine_seed, run_episode
from calibrators.study.labs import lab_id
from calibrators.workflow.page import pictures as draw_pictures
from calibrators.workflow.plan import (
    ACTIONS,
    Plan,
    Procedure,
    SheetError,
    Step,
    check_sheet,
    place_words,
    stand_numbers,
    stands_held,
)
from orthoglide_env.instruments.dial import GaugeNoise
from orthoglide_env.instruments.slots import GaugeSpec, layout_from_names
from orthoglide_env.instruments.stands import install
from orthoglide_env.lab.operations import SLOTS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import AXIS_NAMES, MachineParams
from orthoglide_env.world.conditions import Conditions


def run_json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="session")
def paper_plan(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("plan")
    assert main(["plan", "--agent", "paper", "--out", str(out)]) == 0
    return out


def test_the_paper_plan_is_the_lab_experiment(paper_plan, capsys) -> None:
    """The procedure is the experiment the lab runs: the same time on the clock and the
    same readings in the same order as `calibrate --agent paper`."""
    plan = json.loads((paper_plan / "plan.json").read_text())
    cal = run_json(capsys, ["calibrate", "--agent", "paper", "--backend", "exact",
                            "--params", "paper6", "--json"])
    assert plan["total_s"] == pytest.approx(cal["experiment_time_s"]) == 330.0
    rows = list(csv.DictReader((paper_plan / "readings.csv").open()))
    assert len(rows) == len(cal["residuals"]) == 66
    assert all(r["reading_mm"] == "" for r in rows)
    assert [(r["posture"], r["repetition"]) for r in rows] == [
        (r["posture"], str(r["repetition"])) for r in cal["residuals"]]
    steps = {s["number"]: s for s in plan["steps"]}
    # Every row names a step that takes it, and every reading step's rows are its own.
    for k, row in enumerate(rows, start=1):
        assert k in steps[int(row["step"])]["rows"]
    assert sum(len(s["rows"]) for s in plan["steps"]) == 66
    assert [s["number"] for s in plan["steps"]] == list(range(1, len(plan["steps"]) + 1))
    page = (paper_plan / "procedure.html").read_text()
    assert '<img src="setup.png"' in page and (paper_plan / "setup.png").read_bytes()[:4] == \
        b"\x89PNG"
    assert all(s["text"].replace("'", "&#x27;") in page for s in plan["steps"])
    assert Procedure.read(paper_plan / "plan.json").to_dict() == plan


def _filled(paper_plan: Path, tmp_path: Path, capsys) -> Path:
    """The sheet filled by a technician on the Table 1 machine: the textbook world's lab's
    readings of it, row by row (each row checked to be the same gauge and posture)."""
    machine = tmp_path / "m.json"
    machine.write_text(json.dumps(TABLE1))
    readings = tmp_path / "lab.csv"
    assert main(["calibrate", "--agent", "paper", "--machine", str(machine), "--backend",
                 "exact", "--params", "paper6", "--conditions", "ideal", "--save-measurements",
                 str(readings)]) == 0
    capsys.readouterr()
    lab = list(csv.DictReader(readings.open()))
    rows = list(csv.DictReader((paper_plan / "readings.csv").open()))
    for row, read in zip(rows, lab, strict=True):
        assert (row["mounting"], row["posture"], row["rho_x"]) == (
            read["mounting"], read["posture"], read["rho_x"])
        row["reading_mm"] = read["reading_mm"]
    sheet = tmp_path / "readings.csv"
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return sheet


def test_the_filled_sheet_fits_as_it_is(paper_plan, tmp_path, capsys) -> None:
    """`fit --plan` reads the filled sheet and recovers Table 1 exactly (noise-free, the
    paper's six parameters: the issue's 1e-6 mm).  The sheet is filled from the exact
    model, the textbook world's readings, which --conditions names over the plan's."""
    sheet = _filled(paper_plan, tmp_path, capsys)
    out = run_json(capsys, ["fit", str(sheet), "--plan", str(paper_plan / "plan.json"),
                            "--params", "paper6", "--sigma", "0", "--resolution", "0",
                            "--conditions", "ideal", "--json"])
    np.testing.assert_allclose(out["estimate"]["drho"], TABLE1["drho"], atol=1e-6)
    np.testing.assert_allclose(out["estimate"]["dL"], TABLE1["dL"], atol=1e-6)


#: A sheet's row changed (its line's row, column, value) and the words of the refusal.
BAD_SHEET_ROWS = [
    (10, "step", "999", "line 11: step 999 is not in the plan"),
    (10, "step", "2", "line 11: step 2 (lift) takes no reading"),
    (10, "rho_x", "1.0", "line 11: step"),
]


@pytest.mark.parametrize(("row", "column", "value", "fragment"), BAD_SHEET_ROWS)
def test_a_sheet_row_the_plan_does_not_hold_is_refused(paper_plan, tmp_path, capsys, row,
                                                       column, value, fragment) -> None:
    """The first row's refusal as ``fit``'s child process, the others in this process
    (``command_here``)."""
    sheet = _filled(paper_plan, tmp_path, capsys)
    rows = list(csv.DictReader(sheet.open()))
    rows[row - 1][column] = value
    if column == "rho_x":
        rows[row - 1]["posture"] = ""
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    argv = ["fit", str(sheet), "--plan", str(paper_plan / "plan.json")]
    if (row, column, value, fragment) == BAD_SHEET_ROWS[0]:
        proc = subprocess.run([sys.executable, "-m", "calibrators.cli", *argv],
                              capture_output=True, text=True, timeout=120)
    else:
        proc = command_here(argv)
    assert proc.returncode == 2 and fragment in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_a_plan_of_another_design_is_refused(paper_plan, tmp_path, capsys) -> None:
    sheet = _filled(paper_plan, tmp_path, capsys)
    plan = json.loads((paper_plan / "plan.json").read_text())
    plan["design"]["L"] = 250.0
    other = tmp_path / "other.json"
    other.write_text(json.dumps(plan))
    assert main(["fit", str(sheet), "--plan", str(other)]) == 2
    assert "another design" in capsys.readouterr().err


#: ``plan``'s bad options and the words of their refusal.
BAD_PLANS = [
    (["--agent", "active"], "chooses each move from the last readings"),
    (["--agent", "nobody"], "nobody"),
    (["--budget", "0"], "--budget must be a positive"),
]


@pytest.mark.parametrize(("argv", "fragment"), BAD_PLANS)
def test_plan_refuses_bad_input_in_one_line(tmp_path, argv, fragment) -> None:
    """The first refusal as the command's child process (2 CPU-s of imports), the others
    in this process (``command_here``)."""
    argv = ["plan", *argv, "--out", str(tmp_path)]
    if argv[1:-2] == BAD_PLANS[0][0]:
        proc = subprocess.run([sys.executable, "-m", "calibrators.cli", *argv],
                              capture_output=True, text=True, timeout=120)
    else:
        proc = command_here(argv)
    assert proc.returncode == 2 and fragment in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


@pytest.mark.parametrize("spec", SLOTS, ids=[s.slot for s in SLOTS])
def test_the_words_say_where_the_plunger_points(spec: GaugeSpec) -> None:
    """The words follow the installed gauge: its plunger points along the world axis as
    they say, and a reading is positive along that axis (the sheet's rule) whichever way
    the plunger points, so the words say when that is the plunger coming out."""
    gauge = install([spec], MachineParams())[0]
    axis = AXIS_NAMES[spec.axis]
    pointing = "+" if gauge.direction[spec.axis] > 0 else "-"
    words = place_words(spec, PROTOTYPE)
    assert f"plunger pointing {pointing}{axis}" in words
    assert ("plunger comes out" in words) == (pointing == "+")


def test_each_re_mount_has_its_picture(tmp_path) -> None:
    """A re-mount step gets a picture of the stands after it, the moved one highlighted;
    the set-up gets one of all."""
    paper = Plan(PROTOTYPE, agent="paper", budget_s=3600).run()
    moved = Step(len(paper.steps) + 1, "re-mount", "Move stand 1.", 120.0, paper.total_s,
                 stand=1, slot="x-leg/y@0.8")
    procedure = replace(paper, steps=[*paper.steps, moved], sheet=[])
    pictures = draw_pictures(procedure, PROTOTYPE, tmp_path)
    assert pictures == {1: "setup.png", moved.number: f"step-{moved.number}.png"}
    assert all((tmp_path / name).read_bytes()[:4] == b"\x89PNG" for name in pictures.values())


def test_the_sheet_names_each_readings_stand_across_a_re_mount(tmp_path) -> None:
    """Each row of the sheet names the stand it is read on: the stand the set-up put at its
    gauge's place, and after a re-mount the moved stand at its new place (stand 1 leaves
    x-leg/y@0.5 for x-leg/y@0.8: a reading there is stand 1's, none is left at 0.5)."""
    paper = Plan(PROTOTYPE, agent="paper", budget_s=3600).run()
    moved_to = layout_from_names(["x-leg/y@0.8"])[0]
    moved = Step(len(paper.steps) + 1, "re-mount", "Move stand 1.", 120.0, paper.total_s,
                 stand=1, slot="x-leg/y@0.8", rows=[len(paper.sheet) + 1])
    extra = Measurement(moved_to, "Zero", 1, 0.0, (0.0, 0.0, 0.0), "x-leg/y@0.8#2",
                        step=moved.number)
    procedure = replace(paper, steps=[*paper.steps, moved], sheet=[*paper.sheet, extra])
    numbers = stand_numbers(procedure)
    held = {s["stand"]: s["slot"] for s in paper.stands}
    for m, n in zip(paper.sheet, numbers, strict=False):
        assert held[n] == m.gauge.slot
    assert numbers[-1] == 1 and set(numbers) == set(held)


def _sheet_procedure(paper_plan: Path) -> Procedure:
    """The paper plan as read back, with its sheet (plan.json holds the steps only)."""
    return replace(Procedure.read(paper_plan / "plan.json"),
                   sheet=Plan(PROTOTYPE, agent="paper", budget_s=3600).run().sheet)


def _assert_holds_the_procedure(pdf: Path, procedure: Procedure) -> None:
    """The PDF's text holds every step's words (line breaks and hyphenation aside) and,
    row by row, the sheet's row, step, stand, mounting, posture and rho, as the page does."""
    import pypdf

    from calibrators.workflow.plan import rho_words, stand_numbers

    assert pdf.read_bytes()[:5] == b"%PDF-"
    text = "\n".join(page.extract_text() for page in pypdf.PdfReader(pdf).pages)
    flat = "".join(text.split())
    missing = [s.number for s in procedure.steps if "".join(s.text.split()) not in flat]
    assert not missing, f"steps {missing} are not in the PDF's text"
    lines = {" ".join(line.split()) for line in text.splitlines()}
    for k, (m, n) in enumerate(zip(procedure.sheet, stand_numbers(procedure), strict=True),
                               start=1):
        row = f"{k} {m.step} {n} {m.mounting} {m.posture} {rho_words(m.rho)} {m.repetition}"
        assert any(line.startswith(row + " ") for line in lines), row


def test_the_page_draws_d_and_its_drawn_pdf_holds_it(paper_plan, tmp_path) -> None:
    """The page shows the picture of a leg's bars (what "+d/2" refers to) and a stand
    column in its sheet; the PDF drawn with matplotlib (no extra needed) holds the same
    steps and sheet, with a page for each picture."""
    import pypdf

    from calibrators.workflow.page import BARS_FILE, sheet_readers
    from calibrators.workflow.page_pdf import draw_pdf

    html = (paper_plan / "procedure.html").read_text()
    assert f'<img src="{BARS_FILE}"' in html and "<th>stand</th><th>mounting</th>" in html
    assert (paper_plan / BARS_FILE).read_bytes()[:4] == b"\x89PNG"
    procedure = _sheet_procedure(paper_plan)
    out = draw_pdf(procedure, paper_plan, {1: "setup.png"}, BARS_FILE,
                   sheet_readers(procedure), "orthoglide fit", tmp_path / "drawn.pdf")
    _assert_holds_the_procedure(out, procedure)
    # The pages share one table of resources: the pictures are its distinct images.
    images = {i.name for p in pypdf.PdfReader(out).pages for i in p.images}
    assert len(images) == 2  # the bars and the set-up


@pytest.mark.slow
def test_the_typeset_pdf_is_the_page_with_its_pictures(paper_plan, tmp_path) -> None:
    """With the pdf extra the PDF is the HTML page typeset: the same steps and sheet rows,
    the bars' and the set-up's pictures embedded, A4 pages."""
    import pypdf

    from calibrators.workflow.page import PDF_FILE, write_page
    from calibrators.workflow.page_pdf import typeset_problem

    problem = typeset_problem()
    if problem:
        pytest.skip(f"the typeset PDF needs the pdf extra: {problem}")
    procedure = _sheet_procedure(paper_plan)
    write_page(procedure, tmp_path, pdf=True)
    _assert_holds_the_procedure(tmp_path / PDF_FILE, procedure)
    pages = pypdf.PdfReader(tmp_path / PDF_FILE).pages
    assert len({i.name for p in pages for i in p.images}) == 2  # bars.png and setup.png
    # A4 is 595.3 x 841.9 points; WeasyPrint rounds to a hundredth of a point.
    assert all(abs(float(p.mediabox.width) - 595.28) < 0.1 and
               abs(float(p.mediabox.height) - 841.89) < 0.1 for p in pages)


@pytest.mark.slow
def test_plan_pdf_without_the_extra_says_so_in_one_line(tmp_path, monkeypatch,
                                                        capsys) -> None:
    """Without WeasyPrint `plan --pdf` still writes the PDF, drawn with matplotlib, and one
    line says so and how to get the typeset page."""
    monkeypatch.setitem(sys.modules, "weasyprint", None)  # import fails: not installed
    assert main(["plan", "--agent", "paper", "--out", str(tmp_path), "--pdf"]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines() if "matplotlib" in line]
    assert len(notes) == 1 and "pip install -e '.[pdf]'" in notes[0], notes
    assert "libpango" in notes[0]
    _assert_holds_the_procedure(tmp_path / "procedure.pdf", _sheet_procedure(tmp_path))


def test_the_sheet_names_the_stands_and_fit_reads_them_back(paper_plan, tmp_path,
                                                            capsys) -> None:
    """The sheet's stand column is each row's stand (the page's); a filled sheet without
    the column (an older sheet) fits to the very same estimate, bit for bit."""

    rows = list(csv.DictReader((paper_plan / "readings.csv").open()))
    numbers = stand_numbers(_sheet_procedure(paper_plan))
    assert [r["stand"] for r in rows] == [str(n) for n in numbers]
    sheet = _filled(paper_plan, tmp_path, capsys)
    argv = ["--plan", str(paper_plan / "plan.json"), "--conditions", "ideal", "--json"]
    with_stands = run_json(capsys, ["fit", str(sheet), *argv])
    filled = list(csv.DictReader(sheet.open()))
    old = tmp_path / "old.csv"
    with old.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=[k for k in filled[0] if k != "stand"],
                                extrasaction="ignore")
        writer.writeheader()
        writer.writerows(filled)
    without = run_json(capsys, ["fit", str(old), *argv])
    assert with_stands["estimate"] == without["estimate"]


def _fit_with_stand(paper_plan: Path, tmp_path: Path, capsys, mounting: str, rows: list[int],
                    stand: str) -> subprocess.CompletedProcess:
    """``fit --plan`` of the paper plan's sheet with ``rows`` (of ``mounting``) written on
    ``stand``, run in this process (``command_here``: the sheet's refusals keep a child of
    their own above)."""
    sheet = _filled(paper_plan, tmp_path, capsys)
    filled = list(csv.DictReader(sheet.open()))
    for k in rows:
        assert filled[k - 1]["mounting"] == mounting
        filled[k - 1]["stand"] = stand
    with sheet.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(filled[0]))
        writer.writeheader()
        writer.writerows(filled)
    argv = ["fit", str(sheet), "--plan", str(paper_plan / "plan.json")]
    return command_here(argv)


def test_a_stand_other_than_the_plans_is_refused(paper_plan, tmp_path, capsys) -> None:
    """Every reading of a mounting written as stand 5 where the plan mounts stand 2: fit
    --plan names the first line and both stands, in one line."""
    rows = [k for k, r in enumerate(csv.DictReader((paper_plan / "readings.csv").open()),
                                    start=1) if r["mounting"] == "x-leg/z@0.5"]
    proc = _fit_with_stand(paper_plan, tmp_path, capsys, "x-leg/z@0.5", rows, "5")
    assert proc.returncode == 2, proc.stderr
    assert (f"line {rows[0] + 1}: step 1 reads x-leg/z@0.5 on stand 2, not on stand 5"
            in proc.stderr), proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_a_mounting_on_two_stands_is_refused(paper_plan, tmp_path, capsys) -> None:
    """One row of a mounting written as another stand than its other rows: the file itself
    is refused (a mounting is one stand's), naming both lines."""
    proc = _fit_with_stand(paper_plan, tmp_path, capsys, "x-leg/z@0.5", [10], "5")
    assert proc.returncode == 2, proc.stderr
    assert "readings.csv:11: column 14 (stand): mounting 'x-leg/z@0.5' is on stand 2 (line 3)" in \
        proc.stderr, proc.stderr


#: The budget of the ``optimal`` plan below (s).
OPTIMAL_BUDGET_S = 1200.0


@pytest.fixture(scope="session")
def optimal_plan() -> Procedure:
    """`plan --agent optimal --conditions lab` for 20 minutes, with the dial gauges: a plan
    that still re-mounts a stand twice (a quarter hour's re-mounts once), which the tests
    below read, at a fraction of the hour's planning."""
    return Plan(PROTOTYPE, agent="optimal", conditions=Conditions("lab"),
                budget_s=OPTIMAL_BUDGET_S).run()


class _Actions:
    """The lab actions of an episode, as a plan's steps name them: (action, rho of a move,
    stand of a lift, engage or re-mount as the technician numbers it)."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, tuple[float, ...] | None, int | None]] = []

    def reset(self, i, observation) -> None:
        self.seen.clear()

    def step(self, i, action, observation, info) -> None:
        op = Op(int(action["op"]))
        self.seen.append((ACTIONS[op],
                          tuple(float(v) for v in action["rho"]) if op == Op.MOVE else None,
                          int(action["stand"]) + 1 if op in (Op.LIFT, Op.ENGAGE, Op.REMOUNT)
                          else None))


@pytest.mark.slow
def test_the_optimal_plan_is_the_one_compare_plays(optimal_plan) -> None:
    """The procedure `plan` writes for `optimal` is, step for step, the experiment
    `compare`'s `optimal` plays on the nominal machine with compare's defaults (its lab's
    arguments, the first machine's seed: the dial gauges' sigma and resolution), to the
    same clock.  `optimal` designs its experiment for the noise the lab shows it, so a
    plan made for other gauges than the lab's is another plan (noise-free: 137 steps and
    1198.2 s, against compare's 166 and 1196.1 s)."""
    config = Config(agents=("optimal",), estimators=("full",), budget_s=OPTIMAL_BUDGET_S,
                    errors="nominal", conditions=Conditions("lab"))
    assert optimal_plan.gauges == GaugeNoise(config.sigma, config.resolution)
    agent = get_agent("optimal")
    kwargs = config.lab_kwargs(agent)
    played = _Actions()
    with closing(gym.make(lab_id(kwargs), **kwargs)) as env:
        episode = run_episode(env, agent, machine_seed(config.seed, 0), watch=played)
    assert optimal_plan.total_s == episode.time_s
    assert [(s.action, None if s.action != "drive and read" else tuple(s.rho), s.stand)
            for s in optimal_plan.steps[1:]] == played.seen
    assert any(s.action == "re-mount" for s in optimal_plan.steps)


def test_a_plans_own_sheet_passes_its_check(optimal_plan) -> None:
    """Every reading the plan lists is one its steps hold, a re-mount's included: the
    re-mount reads every stand at Zero, the moved one at its new place."""
    remounts = [s for s in optimal_plan.steps if s.action == "re-mount"]
    assert any(len(s.rows) > 1 for s in remounts)
    check_sheet(Measurements(optimal_plan.sheet), optimal_plan)
    # The moved stand's reading written at the place it left is refused.
    moved = remounts[0]
    left = next(slot for slot, stand in stands_held(optimal_plan)[moved.number - 1].items()
                if stand == moved.stand)
    stale = Measurement(layout_from_names([left])[0], "Zero", 1, 0.0, (0.0, 0.0, 0.0), left,
                        step=moved.number)
    with pytest.raises(SheetError, match=f"step {moved.number} has no stand at {left} "
                       f"\\(stand {moved.stand} is moved to {moved.slot} there\\)"):
        check_sheet(Measurements([stale]), optimal_plan)
