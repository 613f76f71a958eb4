"""The real-machine workflow's Python API (``calibrators.workflow``): docs/workflow.md's example
runs as it is printed, each stage checks its parameters at construction, and each result
writes its files and comes back from its JSON."""

from __future__ import annotations

import contextlib
import io
import json
import re
from contextlib import closing
from pathlib import Path

import numpy as np
import pytest

from calibrators import workflow
from calibrators.agents import get_agent
from calibrators.measurements import Measurements
from calibrators.study.episodes import run_episode
from calibrators.study.labs import lab_kwargs, nominal_lab, nominal_options
from calibrators.workflow.compensate import Compensate, Controller, read_estimate
from calibrators.workflow.fit import Calibration, Fit
from calibrators.workflow.plan import Plan, Procedure, SheetError
from calibrators.workflow.verify import Verification, VerificationPlan, Verify
from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    GaugeNoise,
    exact_readings,
)
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import PROTOTYPE, load_design
from orthoglide_env.model.errors import random_machine
from orthoglide_env.world.conditions import Conditions

ROOT = Path(__file__).resolve().parent.parent
SMALL = ROOT / "examples" / "designs" / "small.json"


def readme_block() -> str:
    """The Python block of the section 'The workflow in Python' of docs/workflow.md."""
    text = (ROOT / "docs" / "workflow.md").read_text(encoding="utf-8")
    section = text.split("## The workflow in Python\n", 1)[1].split("\n## ", 1)[0]
    found = re.search(r"```python\n(.*?)```", section, re.S)
    assert found, "the section holds no Python block"
    return found.group(1)


def test_the_readmes_workflow_runs_as_printed() -> None:
    """Design, plan, readings, fit, compensate, verify: the block runs, the second
    target's command is compensated (not the target itself) and the verification of the
    machine the estimate is of passes."""
    block = readme_block()
    assert len(block.splitlines()) <= 35
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(block, "docs/workflow.md", "exec"), {"__name__": "readme"})
    command, passed = out.getvalue().rsplit(" ", 1)
    assert passed.strip() == "True"
    assert not np.allclose(json.loads(command), [20, -10, 5], atol=1e-3)


def test_the_package_holds_a_module_per_command() -> None:
    for name in ("plan", "session", "fit", "compensate", "verify"):
        assert getattr(workflow, name).__name__ == f"calibrators.workflow.{name}"
    with pytest.raises(AttributeError):
        workflow.nothing  # noqa: B018


def _technician(seed: int):
    """Fills a sheet with the exact readings of a random machine of the paper's preset."""
    machine = random_machine(seed=seed, preset="paper", design=PROTOTYPE)
    gauges = installed_on(machine, install(PAPER_LAYOUT))

    def filled(sheet: list) -> Measurements:
        return Measurements([m.again(exact_readings(machine, gauges, np.array(m.rho))[
            PAPER_LAYOUT.index(m.gauge)], m.repetition, m.time_s, None, m.step)
            for m in sheet], design=PROTOTYPE)

    return filled


@pytest.fixture(scope="module")
def staged() -> dict:
    """The paper's plan, its filled sheet's fit and the verification of that fit."""
    filled = _technician(4)
    procedure = Plan(PROTOTYPE, agent="paper").run()
    calibration = Fit(filled(procedure.sheet), plan=procedure).run()
    check = VerificationPlan(calibration.estimate).run()
    result = Verify(calibration.estimate, filled(check.sheet)).run()
    return {"procedure": procedure, "calibration": calibration, "check": check,
            "verification": result, "filled": filled}


def test_a_plan_is_checked_at_construction() -> None:
    with pytest.raises(ValueError, match="budget_s"):
        Plan(PROTOTYPE, budget_s=0)
    with pytest.raises(ValueError, match="'active' chooses each move"):
        Plan(PROTOTYPE, agent="active")
    with pytest.raises(ValueError, match="nobody"):
        Plan(PROTOTYPE, agent="nobody")
    with pytest.raises(TypeError, match="MachineDesign"):
        Plan("prototype")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="sigma -1 mm is out of range"):
        Plan(PROTOTYPE, sigma=-1.0)


def test_a_plan_names_its_gauges_and_its_fit_reads_with_them(tmp_path) -> None:
    """The gauges a plan is made for (a digital indicator's here) go into plan.json and
    back; a fit of its sheet weighs the readings with them unless told other ones, and
    with the dial gauges' for a plan written before plans named their gauges."""
    digital = GaugeNoise(0.002, 0.001)
    made = Plan(PROTOTYPE, agent="paper", sigma=0.002, resolution=0.001).run()
    procedure = Procedure.read(made.write(tmp_path)[0])
    assert procedure.gauges == digital
    assert procedure.gauges_words() == "gauges of repeatability 0.002 mm read to 0.001 mm"
    readings = _technician(4)(made.sheet)
    assert Fit(readings, plan=procedure).sigma == digital.effective_sigma
    assert Fit(readings, plan=procedure, sigma=0.02).sigma == GaugeNoise(
        0.02, 0.001).effective_sigma
    older = Procedure.from_dict({k: v for k, v in procedure.to_dict().items()
                                 if k != "gauges"})
    assert older.gauges is None
    assert Fit(readings, plan=older).sigma == GaugeNoise(DEFAULT_SIGMA,
                                                         DEFAULT_RESOLUTION).effective_sigma


def test_the_procedure_writes_its_files_and_reads_back(staged, tmp_path) -> None:
    procedure = staged["procedure"]
    plan, sheet = procedure.write(tmp_path / "plan")
    assert (plan.name, sheet.name) == ("plan.json", "readings.csv")
    assert Procedure.read(plan).to_dict() == procedure.to_dict()
    assert len(sheet.read_text().splitlines()) == len(procedure.sheet) + 1
    assert procedure.summary().startswith(f"agent paper: {len(procedure.steps)} steps")


def test_a_plan_of_another_design_is_played_on_it() -> None:
    small = load_design(SMALL)
    procedure = Plan(small, agent="paper", budget_s=3600).run()
    assert procedure.design == small.to_dict()
    assert all(f"L = {small.L:g} mm" in s["place"] for s in procedure.stands)


def test_a_fit_refuses_a_sheet_its_plan_does_not_hold(staged) -> None:
    procedure = staged["procedure"]
    readings = staged["filled"](procedure.sheet)
    shifted = Procedure.from_dict({**procedure.to_dict(), "steps": [
        {**s, "number": s["number"] + 1} for s in procedure.to_dict()["steps"]]})
    with pytest.raises(SheetError, match="step 1 is not in the plan"):
        Fit(readings, plan=shifted)
    with pytest.raises(ValueError, match="sigma"):
        Fit(readings, sigma=-1.0)
    with pytest.raises(ValueError, match="unknown estimator 'guesswork'"):
        Fit(readings, estimator="guesswork")


def test_the_calibration_round_trips_and_writes_an_estimate_file(staged, tmp_path) -> None:
    calibration = staged["calibration"]
    again = Calibration.from_dict(json.loads(json.dumps(calibration.to_dict())))
    np.testing.assert_array_equal(again.estimate.theta, calibration.estimate.theta)
    [path] = calibration.write(tmp_path)
    np.testing.assert_array_equal(read_estimate(path).theta, calibration.estimate.theta)


def test_the_controller_round_trips_and_writes_its_files(staged, tmp_path) -> None:
    estimate = staged["calibration"].estimate
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        Compensate(estimate, np.zeros((2, 2)))
    controller = Compensate(estimate, [[0.0, 0.0, 0.0], [10.0, 5.0, -5.0]]).run()
    again = Controller.from_dict(json.loads(json.dumps(controller.to_dict())))
    np.testing.assert_array_equal(again.compensation.commands,
                                  controller.compensation.commands)
    assert again.joint_offsets() == controller.joint_offsets()
    names = {p.name for p in controller.write(tmp_path)}
    assert {"joint_offsets.csv", "machine.json", "commands.csv"} <= names
    assert Compensate(estimate).run().targets() == []


def test_the_verification_passes_round_trips_and_refuses_another_design(staged,
                                                                       tmp_path) -> None:
    result = staged["verification"]
    assert result.passed, result.reason
    assert Verification.from_dict(json.loads(json.dumps(result.to_dict()))) == result
    [path] = result.write(tmp_path)
    assert json.loads(path.read_text())["passed"] is True
    # Every posture of the calibration is verified, none left out.
    assert not [n for n in staged["check"].notes if "left out" in n]
    other = Measurements(staged["filled"](staged["check"].sheet).items[:0],
                         design=load_design(SMALL))
    with pytest.raises(ValueError, match="another design"):
        Verify(staged["calibration"].estimate, other)


class _Seen:
    """A watcher that counts what it is shown."""

    def __init__(self) -> None:
        self.resets, self.steps = 0, []

    def reset(self, i, observation) -> None:
        self.resets += 1

    def step(self, i, action, observation, info) -> None:
        self.steps.append(int(action["op"]))


def test_the_episode_loop_shows_a_watcher_every_step() -> None:
    """One reset and every step of the episode, the last being the agent's stop."""
    agent = get_agent("paper")
    seen = _Seen()
    with closing(nominal_lab(agent, PROTOTYPE, Conditions("ideal"), 3600, sigma=0.0,
                             resolution=0.0)) as env:
        run_episode(env, agent, 0, nominal_options(PROTOTYPE), watch=seen)
    assert seen.resets == 1 and len(seen.steps) > 10
    assert seen.steps[-1] == Op.STOP and Op.STOP not in seen.steps[:-1]


def test_a_lab_carries_the_instruments_its_agent_needs() -> None:
    assert lab_kwargs(get_agent("tracker"), budget_s=60.0) == {
        "budget_s": 60.0, "tracker": True, "reference": False}
    assert lab_kwargs(get_agent("paper"))["tracker"] is False
