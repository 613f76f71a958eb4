"""The lab engine's named pieces (its clock, refusals and rewards), the scoring package's
modules, and the earlier names the renames keep."""

from __future__ import annotations

import numpy as np
import pytest

from orthoglide_env.lab.clock import overtravel_seconds, step_seconds, travel_seconds
from orthoglide_env.lab.operations import SLOTS, TIME, Op
from orthoglide_env.lab.refusals import assembled, raise_unreachable, refusals
from orthoglide_env.lab.rewards import ACCURACY_UNIT_MM, SECONDS_PER_HOUR, step_rewards
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams


def test_travel_seconds_add_the_tracker_the_remount_and_the_block() -> None:
    op = np.array([Op.MOVE, Op.REMOUNT, Op.REMOUNT])
    before, goal = np.zeros((3, 3)), np.array([[40.0, 0, 0], [0, 0, 0], [0, 0, 0]])
    plain = travel_seconds(op, before, goal, tracker=False)
    assert plain.tolist() == [40 / TIME.drive_speed_mm_s + TIME.settle_and_read_s,
                              TIME.settle_and_read_s + TIME.remount_s,
                              TIME.settle_and_read_s + TIME.remount_s]
    more = travel_seconds(op, before, goal, tracker=True,
                          blocked=np.array([False, False, True]))
    assert (more - plain).tolist() == [TIME.tracker_point_s, 0.0, TIME.reference_s]


def test_step_seconds_and_overtravel() -> None:
    ok = np.array([False, True, True, True])
    flicks = np.array([False, True, False, False])
    carried = np.array([False, False, True, False])  # the last one: a stop
    seconds = step_seconds(ok, flicks, carried, np.full(4, 50.0))
    assert seconds.tolist() == [TIME.lift_s, TIME.lift_s, 50.0, 0.0]
    new = np.array([[True, True], [False, False]])
    assert overtravel_seconds(new).tolist() == [2 * TIME.overtravel_s, 0.0]


def test_rewards_of_each_kind() -> None:
    seconds = np.array([10.0, 0.0])
    assert step_rewards("time", seconds).tolist() == [-10.0, -0.0]
    assert step_rewards("information", seconds, gains=np.array([2.0, 1.0])).tolist() == [
        0.2, 0.0]
    reward = step_rewards("accuracy", seconds, time_weight=2.0, final_errors=[0.03],
                          ended=np.array([False, True]))
    assert reward.tolist() == pytest.approx([-2 * 10 / SECONDS_PER_HOUR,
                                             -0.03 / ACCURACY_UNIT_MM])


def test_refusals_name_each_reason_and_solve_the_moves() -> None:
    machines = MachineParams.stack([MachineParams(design=PROTOTYPE)] * 3)
    rows = np.arange(3)
    op = np.array([Op.LIFT, Op.REMOUNT, Op.MOVE])
    rho = np.array([[0.0, 0, 0], [0, 0, 0], [10.0, 0, 0]])
    held = np.array([[-1, 1], [0, 1], [0, 1]])  # stand 0 of row 0 is not mounted
    out, reached = refusals(machines, rows, op, rho, np.array([0, 0, 0]),
                            np.array([0, 1, 0]), rho, held, list(SLOTS))
    assert out == ["stand 0 is not mounted", f"slot {SLOTS[1].slot} already holds a stand", ""]
    assert np.isnan(reached[:2]).all()
    assert np.allclose(reached[2], assembled(machines[rows[2:]], rho[2:])[0])
    raise_unreachable(machines, rows, op, rho, reached, rho, 3)  # nothing unreachable


def test_unreachable_moves_are_refused_and_raised() -> None:
    machines = MachineParams.stack([MachineParams(design=PROTOTYPE)] * 2)
    rho = np.array([[0.0, 0, 0], [1e4, 0, 0]])
    op = np.array([Op.MOVE, Op.MOVE])
    out, reached = refusals(machines, np.arange(2), op, rho, np.zeros(2, int),
                            np.zeros(2, int), rho, np.zeros((2, 1), int), list(SLOTS))
    assert out[0] == "" and out[1].startswith("the machine cannot assemble")
    with pytest.raises(ValueError, match="action of env 1"):
        raise_unreachable(machines, np.arange(2), op, rho, reached, rho, 2)


def test_earlier_names_stay_importable() -> None:
    from orthoglide_env.lab import engine, spec
    from orthoglide_env.reading_model import Design, ReadingLayout

    assert Design is ReadingLayout
    assert spec.Design is spec.DesignArg and spec.World is spec.ConditionsArg
    assert engine.assembled is assembled and engine.ACCURACY_UNIT_MM == ACCURACY_UNIT_MM
    assert engine.SECONDS_PER_HOUR == SECONDS_PER_HOUR


def test_the_scoring_package_exports_its_modules_names() -> None:
    import orthoglide_env.scoring as scoring
    from orthoglide_env.scoring import grid, predicted, reports, truth

    for module in (grid, predicted, reports, truth):
        for name in scoring.__all__:
            if hasattr(module, name) and not name.startswith("_"):
                assert getattr(scoring, name) is getattr(module, name)
    assert {"score", "score_batch", "predicted_tcp_frames", "rigid_weights", "FRAMES",
            "workspace_grid", "BLOCK"} <= set(scoring.__all__)
