"""What ``compare`` reports of its trials: failures counted, success against the truth,
intervals, paired comparisons."""

from __future__ import annotations

import numpy as np
import pytest

from calibrators.estimators.catalogue import for_study
from calibrators.study.compare import Config, Trial, _machines, agent_episodes, machine_z_scores
from calibrators.study.statistics import (
    median_interval,
    paired,
    summary,
    warning_kind,
    warning_title,
)
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.world.conditions import Conditions


def _trial(agent: str, machine: int, rigid: float, *, before: float = 0.5,
           predicted: float = 0.001, failed: str = "") -> Trial:
    frames = {"raw": 2 * rigid, "translation": 1.5 * rigid, "rigid": rigid}
    return Trial(agent, "extended", machine, failed=failed, time_s=60.0, readings=10,
                 tcp_before={f: before for f in frames}, tcp_after=frames,
                 predicted_rigid_mm=float("nan") if failed else predicted,
                 chi2_rejected=None if failed else False, z=[] if failed else [1.0],
                 warnings=[] if failed else ["the model does not explain the readings: "
                                             f"chi2/dof = {machine}"])


def test_a_failed_trial_counts_as_its_uncalibrated_machine_and_never_succeeds() -> None:
    """Ten machines: the agent fails on the three hardest (their uncalibrated error,
    0.5 mm, enters the median as the table says), succeeds against the truth on the five
    below 0.01 mm, and predicts success on all seven it fitted."""
    trials = [_trial("a", m, 0.002 if m < 5 else 0.02) for m in range(7)]
    trials += [_trial("a", m, 0.5, failed="did not converge") for m in range(7, 10)]
    row = summary(trials, 0.01)[0]
    assert row["failed"] == 3 and row["failed_counted_as"] == "uncalibrated"
    rigid = sorted([0.002] * 5 + [0.02] * 2 + [0.5] * 3)
    assert row["tcp_after_mm"]["rigid"]["median"] == pytest.approx(np.median(rigid))
    assert row["tcp_after_mm"]["rigid"]["ci95"] == list(median_interval(rigid))
    assert row["success_rate"] == pytest.approx(0.5)
    assert row["predicted_success_rate"] == pytest.approx(0.7)
    assert row["warnings"]["the model does not explain the readings"]["trials"] == 7
    assert summary([_trial("a", 0, 0.1, failed=""), _trial("a", 1, 0.1)])[0]["warnings"] == {
        "the model does not explain the readings": {
            "trials": 2, "example": "the model does not explain the readings: chi2/dof = 0"}}


def test_paired_comparison_is_per_machine() -> None:
    """Agent ``a`` is 2x better than ``b`` on every machine although their error
    distributions overlap: the paired ratio says 0.5 on all 20 machines with an interval
    of zero width, and a wins everywhere."""
    errors = np.geomspace(0.001, 0.1, 20)
    trials = [t for m, e in enumerate(errors)
              for t in (_trial("a", m, e), _trial("b", m, 2 * e))]
    (pair,) = paired(trials)
    assert (pair["agent"], pair["against"], pair["machines"]) == ("a", "b", 20)
    assert pair["ratio_median"] == pytest.approx(0.5)
    assert pair["ratio_ci95"] == pytest.approx([0.5, 0.5])
    assert pair["win_rate"] == 1.0


def test_paired_comparison_uses_only_the_machines_both_ran() -> None:
    trials = [_trial("a", m, 0.01) for m in range(8)] + [_trial("b", m, 0.04)
                                                         for m in range(4, 12)]
    (pair,) = paired(trials)
    assert pair["machines"] == 4 and pair["ratio_ci95"] is None
    assert pair["ratio_median"] == pytest.approx(0.25)


def test_warnings_of_one_kind_are_counted_together() -> None:
    assert warning_kind("3 outlier reading(s) left out: reading 7 (x-leg/y)") == \
        warning_kind("12 outlier reading(s) left out: reading 1 (z-leg/x)") == \
        "N outlier reading(s) left out"


def test_a_warning_kind_reads_without_its_placeholder() -> None:
    """The kind groups warnings by replacing their numbers; the line a user reads says
    "readings", not "N reading(s)", since the trials' count stands beside it."""
    text = ("3 reading(s) the model does not fit, though their repetitions read the same: "
            "reading 31 (y-leg/x@0.5, YMin)")
    assert warning_kind(text) == ("N reading(s) the model does not fit, though their "
                                  "repetitions read the same")
    assert warning_title(warning_kind(text)) == ("readings the model does not fit, though "
                                                 "their repetitions read the same")
    assert warning_title("N outlier reading(s) left out") == "outlier readings left out"
    assert warning_title("the model does not explain the readings") == (
        "the model does not explain the readings")


def test_a_paired_row_counts_the_machines_with_a_failed_fit() -> None:
    """Where a fit failed, the ratio compares uncalibrated machines: the row says on how
    many of its machines that happened (either side), so a ratio of 1 over failures is
    not read as a tie of two calibrations."""
    trials = [t for m in range(6) for t in (
        _trial("a", m, 0.5 if m < 2 else 0.01, failed="no Zero" if m < 2 else ""),
        _trial("b", m, 0.5 if m in (1, 3) else 0.02, failed="no Zero" if m in (1, 3) else ""))]
    (pair,) = paired(trials)
    assert pair["machines"] == 6 and pair["failed"] == 3  # machines 0, 1 and 3
    clean = [t for t in trials if t.machine >= 4]
    assert paired(clean)[0]["failed"] == 0


def test_the_scored_machines_and_z_scores_of_a_batch_are_each_estimates_own() -> None:
    """The scoring takes the estimated machines from their vectors at once and the
    z-scores from the group's stacked covariances: each machine is its estimate's own
    (the nominal one for a failed fit) and each trial's z-scores are those its estimate
    gets alone, to the bit."""
    config = Config(("paper",), ("paper6",), seed=3, conditions=Conditions("ideal"))
    episodes = agent_episodes(config, "paper", [0, 1, 2, 3])
    estimates: list = for_study("paper6", episodes[0].run.sigma).fit_many(
        [e.run.measurements for e in episodes])
    estimates[1] = ValueError("not fitted")
    batch, rows = _machines(episodes, estimates)
    assert batch.batch_shape == (4,)
    nominal = MachineParams(design=episodes[1].run.truth.design)
    for est, row in zip(estimates, rows, strict=True):
        assert row == (nominal if isinstance(est, Exception) else est.machine)
    fitted = [estimates[k] for k in (0, 2, 3)]
    truths = [episodes[k].run.truth for k in (0, 2, 3)]
    together = machine_z_scores(fitted, truths, [t.to_vector() for t in truths])
    for est, truth, z in zip(fitted, truths, together, strict=True):
        assert z.size and np.array_equal(z, machine_z_scores([est], [truth])[0])
