"""Scoring: exact-model identities of TCP compensation."""

from __future__ import annotations

import numpy as np
import pytest

from orthoglide_env.geometry import RHO_MAX, RHO_MIN, MachineParams, random_machine
from orthoglide_env.kinematics import inverse
from orthoglide_env.scoring import score, tcp_errors, workspace_grid


def test_grid_commands_respect_the_limits() -> None:
    grid = workspace_grid()
    rho = inverse(MachineParams(), grid)
    assert len(grid) > 200 and np.all((rho >= RHO_MIN) & (rho <= RHO_MAX))


def test_compensating_with_the_truth_leaves_no_error() -> None:
    truth = random_machine(3, "paper")
    report = score(truth, truth)
    # inverse then direct of the same model: round-off only (1e-9 mm, see kinematics tests).
    assert report.tcp_after.max < 1e-9
    assert report.tcp_before.rms > 0.1
    assert report.drho_error == [0.0, 0.0, 0.0]


def test_compensating_with_nominal_is_uncompensated() -> None:
    truth = random_machine(4, "realistic")
    report = score(MachineParams(), truth)
    assert report.tcp_after == report.tcp_before


def test_paper_errors_at_zero_follow_eq7() -> None:
    # At Zero the uncompensated TCP is off by drho - dL (eq. 7) to first order.
    truth = MachineParams(drho=[0.01, 0.0, 0.0], dL=[0.0, 0.02, 0.0])
    err = tcp_errors(MachineParams(), truth, np.zeros((1, 3)))[0]
    assert err == pytest.approx(np.hypot(0.01, 0.02), rel=1e-3)


def test_score_report_round_trips_to_dict() -> None:
    report = score(random_machine(5, "paper"), random_machine(6, "paper"))
    data = report.to_dict()
    assert set(data) == {"drho_error", "dL_error", "tcp_before", "tcp_after", "n_targets",
                         "n_skipped"}
    assert set(data["tcp_after"]) == {"rms", "max"}


@pytest.mark.parametrize("seed", range(3))
def test_compensating_a_realistic_machine_with_its_truth_leaves_no_error(seed: int) -> None:
    truth = random_machine(seed, "realistic")
    report = score(truth, truth)
    # The general direct model is Newton's method converged to 1e-11 mm per step;
    # measured maxima are ~2e-13 mm.
    assert report.tcp_after.max < 1e-9
    assert report.n_targets + report.n_skipped == len(workspace_grid())


def test_commands_outside_the_limits_are_skipped_and_counted() -> None:
    # An estimate that believes the x encoder reads 30 mm high commands 30 mm less on x:
    # targets near the -100 mm limit get commands the controller refuses.
    report = score(MachineParams(drho=[30.0, 0.0, 0.0]), random_machine(1, "realistic"))
    assert report.n_skipped > 0
    assert report.n_targets + report.n_skipped == len(workspace_grid())


def test_a_wild_estimate_is_scored_without_crashing() -> None:
    # Legs of 60 mm cannot reach most targets: no command, no crash, NaN errors.
    wild = MachineParams(dL=[-250.0, 0.0, 0.0])
    assert np.all(np.isnan(tcp_errors(wild, MachineParams(), workspace_grid())))
    with pytest.raises(ValueError, match="no target"):
        score(wild, MachineParams())
