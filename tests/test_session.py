"""``orthoglide session``: the active agent with the readings typed in, through a pipe."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import command_here

import orthoglide_env
from calibrators.cli import main
from calibrators.measurements import Measurements
from calibrators.study.episodes import machine_seed
from calibrators.workflow.session import parse_answer
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import DEFAULT_CONDITIONS

#: The piped session's machine and lab time: five minutes hold 99 readings (the session
#: is stopped after 40 and resumed), and each of its three runs of ``active`` costs a
#: CPU-second less than ten minutes' 197.
SEED, BUDGET = 2, "300"


def _drive(out: Path, stop_after: int | None = None, resume: bool = False,
           typos: bool = False) -> subprocess.CompletedProcess | None:
    """The session on machine SEED, its readings answered through the pipe from a lab of
    the true machine (built as calibrate builds it), stepped with each action the session
    announces; ``stop_after``: end the input after that many answers; ``typos``: answer
    every fifth reading first with text."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, errors="realistic", gauge_sigma=DEFAULT_SIGMA,
                   gauge_resolution=DEFAULT_RESOLUTION, backend="exact",
                   budget_s=float(BUDGET))
    observation, _ = env.reset(seed=machine_seed(SEED, 0))
    argv = [sys.executable, "-m", "calibrators.cli", "session", "--agent", "active",
            "--budget", BUDGET, "--seed", str(SEED), "--out", str(out), "--json"]
    proc = subprocess.Popen(argv + (["--resume"] if resume else []), stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    answered, asked, retyped = 0, 0, 0
    try:
        for line in proc.stdout:
            item = json.loads(line)
            if "action" in item:
                a = item["action"]
                observation, *_ = env.step({"op": int(a["op"]), "rho": np.array(a["rho"]),
                                            "stand": int(a["stand"]), "slot": int(a["slot"])})
            elif "ask" in item:
                asked += 1
                if typos and asked % 5 == 0 and not retyped:
                    proc.stdin.write("zero point one\n")
                    proc.stdin.flush()
                    retyped = 1
                    continue
                retyped = 0
                if stop_after is not None and answered == stop_after:
                    proc.stdin.close()
                    break
                k = item["ask"]["stand"] - 1
                value = float(observation["gauges"][k]) if observation["valid"][k] else None
                proc.stdin.write(json.dumps({"reading_mm": value}) + "\n")
                proc.stdin.flush()
                # A reading asked again (an answer the session finds suspect) is one
                # reading, answered the same: the notebook holds it once.
                answered += "again" not in item["ask"]
        proc.wait(timeout=600)
    finally:
        env.close()
        if proc.poll() is None:
            proc.kill()
    return subprocess.CompletedProcess(argv, proc.returncode, "", proc.stderr.read())


@pytest.fixture(scope="session")
def calibrated(tmp_path_factory) -> tuple[Path, dict]:
    """`calibrate --agent active` on the session's machine, run in this process: it is
    what the piped sessions are held against, not a command under test (they are)."""
    readings = tmp_path_factory.mktemp("session") / "calibrate.csv"
    with contextlib.redirect_stdout(io.StringIO()) as out:
        assert main(["calibrate", "--agent", "active", "--backend", "exact", "--seed",
                     str(SEED), "--budget", BUDGET, "--save-measurements", str(readings),
                     "--json"]) == 0
    return readings, json.loads(out.getvalue())


@pytest.mark.slow
def test_a_piped_session_is_calibrate_and_resumes(calibrated, tmp_path, capsys) -> None:
    """Fed the machine's readings as they come, with a slip of the finger typed now and
    then (asked again, never fatal), and its input ended after 40 answers (the notebook
    holds them, the command says how to go on, a new session there is refused: checked in
    this process, ``command_here``), then resumed: the session takes the same readings at
    the same lab times as `calibrate --agent active` on that machine and seed, and they fit
    to its estimate."""
    readings, cal = calibrated
    stopped = _drive(tmp_path / "s", stop_after=40, typos=True)
    assert stopped.returncode == 2 and "--resume goes on" in stopped.stderr
    assert len((tmp_path / "s" / "notebook.jsonl").read_text().splitlines()) == 40
    again = command_here(["session", "--agent", "active", "--out", str(tmp_path / "s")])
    assert again.returncode == 2 and "give --resume" in again.stderr
    resumed = _drive(tmp_path / "s", resume=True, typos=True)
    assert resumed.returncode == 0, resumed.stderr
    mine = Measurements.read(tmp_path / "s" / "readings.csv")
    theirs = Measurements.read(readings)
    assert mine.items == theirs.items
    assert [m.time_s for m in mine.items] == [m.time_s for m in theirs.items]
    # Both ran in the default world, the real lab's, which a file of readings does not name.
    assert main(["fit", str(tmp_path / "s" / "readings.csv"), "--conditions",
                 DEFAULT_CONDITIONS, "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)
    assert fitted["estimate"] == cal["estimate"]


@pytest.mark.parametrize(("text", "value"), [("0.12", 0.12), (" -0.5 ", -0.5), ("-", None),
                                             ('{"reading_mm": 0.03}', 0.03),
                                             ('{"reading_mm": null}', None)])
def test_answers(text, value) -> None:
    assert parse_answer(text) == value


@pytest.mark.parametrize("text", ["abc", "nan", "1e9", '{"reading": 1}', "true", ""])
def test_an_answer_that_is_no_reading_is_refused(text) -> None:
    with pytest.raises(ValueError, match="reading"):
        parse_answer(text)


def test_a_planned_agent_is_sent_to_plan(tmp_path) -> None:
    """In this process (``command_here``): the piped sessions start the command's own."""
    proc = command_here(["session", "--agent", "paper", "--out", str(tmp_path)])
    assert proc.returncode == 2 and "orthoglide plan" in proc.stderr


def _answering(env: gym.Env, observation: dict, slip):
    """A say and an answer of a session whose readings come from ``env`` (stepped with each
    action the session announces); ``slip(question, true_value)`` may answer otherwise."""
    state = {"observation": observation}

    def say(text, action=None):
        if action is not None:
            state["observation"], *_ = env.step(
                {"op": int(action["op"]), "rho": np.asarray(action["rho"], dtype=float),
                 "stand": int(action["stand"]), "slot": int(action["slot"])})

    def answer(question):
        k = question["stand"] - 1
        obs = state["observation"]
        value = float(obs["gauges"][k]) if obs["valid"][k] else None
        return slip(question, value)

    return say, answer


@pytest.mark.slow
def test_an_impossible_reading_is_asked_again_and_a_knock_offers_a_re_zero(tmp_path) -> None:
    from calibrators.workflow.session import Session

    env = gym.make(orthoglide_env.LAB_ENV_ID, errors="realistic", gauge_sigma=DEFAULT_SIGMA,
                   gauge_resolution=DEFAULT_RESOLUTION, backend="exact", budget_s=600.0,
                   conditions="ideal")
    observation, _ = env.reset(seed=machine_seed(SEED, 0))
    asked_again: list[str] = []
    state = {"asked": 0, "knocked": None}

    def slip(question, value):
        if "again" in question:
            asked_again.append(question["again"])
            # After the offer of a re-zero the dial is re-zeroed: it reads 0 at Zero.
            return 0.0 if "re-zero" in question["again"] else value
        state["asked"] += 1
        if state["asked"] >= 10 and value is not None and not state.get("slipped"):
            state["slipped"] = True
            return 7.5  # beyond the 10 mm gauge's +-5 mm about its zero
        at_zero = not any(question["rho"])
        if at_zero and state["asked"] > 20 and state["knocked"] is None and value is not None:
            state["knocked"] = question["stand"]
            return value + 0.3  # the stand was knocked: 0.3 mm off its zero
        return value

    session = Session("active", 600.0, tmp_path / "notebook.jsonl", design=PROTOTYPE,
                      seed=machine_seed(SEED, 0))
    say, answer = _answering(env, observation, slip)
    data = session.run(answer, say)
    env.close()
    assert any("outside the gauge's travel" in reason for reason in asked_again)
    assert state["knocked"] is not None, "the session never came back to Zero"
    assert any("may have been knocked; re-zero its dial" in reason for reason in asked_again)
    renamed = [m for m in data.items if m.mounting.endswith("+re-zeroed")]
    # From the re-zero on the stand's readings are a new mounting, which starts at Zero.
    assert renamed and renamed[0].is_zero and renamed[0].reading == 0.0
    assert 7.5 not in [m.reading for m in data.items]


def test_a_clean_lab_session_asks_again_only_at_a_sign_slip(tmp_path) -> None:
    """Under the real lab's conditions, a realistic machine's readings differ from the
    nominal machine's by up to ~1.5 mm at the ends of its gauges' travel (machine seed 2,
    600 s), and some the nominal machine cannot give at all: none of them is asked again.
    One reading written with the wrong sign, the first whose true value is beyond 2 mm
    (its slip moves it by > 4 mm, past NOMINAL_MM = 2.5 mm plus the ~1.5 mm a clean
    reading is off), is asked again, and it alone."""
    from calibrators.workflow.session import Session

    env = gym.make(orthoglide_env.LAB_ENV_ID, errors="realistic", gauge_sigma=DEFAULT_SIGMA,
                   gauge_resolution=DEFAULT_RESOLUTION, backend="exact", budget_s=600.0,
                   conditions=DEFAULT_CONDITIONS)
    observation, _ = env.reset(seed=machine_seed(SEED, 0))
    asked_again: list[tuple[int, int]] = []
    slipped: list[tuple[int, int]] = []

    def slip(question, value):
        where = (question["step"], question["stand"])
        if "again" in question:
            asked_again.append(where)
            return value
        if not slipped and value is not None and abs(value) > 2.0:
            slipped.append(where)
            return -value
        return value

    session = Session("active", 600.0, tmp_path / "notebook.jsonl", design=PROTOTYPE,
                      seed=machine_seed(SEED, 0))
    say, answer = _answering(env, observation, slip)
    session.run(answer, say)
    env.close()
    assert slipped, "no reading beyond 2 mm to slip"
    assert asked_again == slipped
