"""Scoring: exact-model identities of TCP compensation, and the three frames' best fits
against scipy's Kabsch and their own identities."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.model.kinematics import inverse
from orthoglide_env.scoring import (
    FRAMES,
    best_rigid_motion,
    frame_errors,
    remove_rigid,
    remove_translation,
    score,
    score_batch,
    tcp_error_vectors,
    tcp_errors,
    workspace_grid,
)

#: Round-off of the best fits on coordinates of ~100 mm: a few ulps (1e-14 mm) per sum
#: over ~300 targets and a 3x3 SVD; measured ~1e-13 mm.
FIT_ROUND_OFF: float = 1e-11


def test_grid_commands_respect_the_limits() -> None:
    grid = workspace_grid(design=PROTOTYPE)
    rho = inverse(MachineParams(), grid)
    assert len(grid) > 200 and np.all((rho >= PROTOTYPE.rho_min) & (rho <= PROTOTYPE.rho_max))


def test_compensating_with_the_truth_leaves_no_error() -> None:
    truth = random_machine(3, "paper", design=PROTOTYPE)
    report = score(truth, truth)
    # inverse then direct of the same model: round-off only (1e-9 mm, see kinematics tests).
    for frame in FRAMES:
        assert getattr(report.tcp_after, frame).max < 1e-9
    assert report.tcp_before.raw.rms > 0.1
    assert report.drho_error == [0.0, 0.0, 0.0]


def test_compensating_with_nominal_is_uncompensated() -> None:
    truth = random_machine(4, "realistic", design=PROTOTYPE)
    report = score(MachineParams(), truth)
    assert report.tcp_after == report.tcp_before


def test_paper_errors_at_zero_follow_eq7() -> None:
    # At Zero the uncompensated TCP is off by drho - dL (eq. 7) to first order; the
    # second-order term is ~|dL|^2 / L ~ 1e-6 mm, 1e-4 of the error.
    truth = MachineParams(drho=[0.01, 0.0, 0.0], dL=[0.0, 0.02, 0.0])
    vector = tcp_error_vectors(MachineParams(), truth, np.zeros((1, 3)))[0]
    np.testing.assert_allclose(vector, truth.drho - truth.dL, rtol=0, atol=1e-3 * 0.02)
    assert tcp_errors(MachineParams(), truth, np.zeros((1, 3)))[0] == np.linalg.norm(vector)


def test_score_report_to_dict_has_the_documented_shape() -> None:
    report = score(random_machine(5, "paper", design=PROTOTYPE),
                   random_machine(6, "paper", design=PROTOTYPE))
    data = report.to_dict()
    assert set(data) == {"drho_error", "dL_error", "tcp_before", "tcp_after", "n_targets",
                         "n_skipped"}
    for when in ("tcp_before", "tcp_after"):
        frames = getattr(report, when)
        assert data[when] == {frame: {"rms": getattr(frames, frame).rms,
                                      "max": getattr(frames, frame).max} for frame in
                              ("raw", "translation", "rigid")}


@pytest.mark.parametrize("seed", range(3))
def test_compensating_a_realistic_machine_with_its_truth_leaves_no_error(seed: int) -> None:
    truth = random_machine(seed, "realistic", design=PROTOTYPE)
    report = score(truth, truth)
    # The general direct model is Newton's method converged to 1e-11 mm per step;
    # measured maxima are ~2e-13 mm.
    assert report.tcp_after.raw.max < 1e-9 and report.tcp_after.rigid.max < 1e-9
    assert report.n_targets + report.n_skipped == len(workspace_grid(design=PROTOTYPE))


def test_commands_outside_the_limits_are_skipped_and_counted() -> None:
    # An estimate that believes the x encoder reads 30 mm high commands 30 mm less on x:
    # targets near the -100 mm limit get commands the controller refuses.
    report = score(MachineParams(drho=[30.0, 0.0, 0.0]),
                   random_machine(1, "realistic", design=PROTOTYPE))
    assert report.n_skipped > 0
    assert report.n_targets + report.n_skipped == len(workspace_grid(design=PROTOTYPE))


def test_a_wild_estimate_is_scored_without_crashing() -> None:
    # Legs of 60 mm cannot reach most targets: no command, no crash, NaN errors.
    wild = MachineParams(dL=[-250.0, 0.0, 0.0])
    assert np.all(np.isnan(tcp_errors(wild, MachineParams(), workspace_grid(design=PROTOTYPE))))
    with pytest.raises(ValueError, match="no target"):
        score(wild, MachineParams())


def test_equal_attachment_errors_shift_the_workspace_rigidly() -> None:
    # The same offset a on every R2 centre is the platform moved by a: the true machine
    # puts the TCP at (nominal TCP) - a exactly, so the uncompensated error is -a at every
    # target, all of it a translation.
    offset = np.array([0.3, -0.2, 0.5])
    truth = MachineParams(attach=np.tile(offset, (3, 1)))
    grid = workspace_grid(design=PROTOTYPE)
    # Newton's direct solve converges to 1e-11 mm.
    np.testing.assert_allclose(tcp_error_vectors(MachineParams(), truth, grid),
                               np.broadcast_to(-offset, grid.shape), rtol=0, atol=1e-10)
    before = score(MachineParams(), truth).tcp_before
    assert before.raw.rms == pytest.approx(np.linalg.norm(offset), abs=1e-10)
    assert before.translation.max < 1e-10 and before.rigid.max < 1e-10


def random_batch(seed: int, machines: int = 5, points: int = 30):
    """Targets, reached points and masks of a batch, with reflected data in machine 1 so
    that the best orthogonal fit there is a reflection."""
    rng = np.random.default_rng(seed)
    targets = rng.uniform(-100, 100, (machines, points, 3))
    reached = targets @ Rotation.from_rotvec(rng.normal(size=3)).as_matrix().T + rng.normal(
        0, 5, (machines, points, 3))
    reached[1] *= [-1.0, 1.0, 1.0]
    mask = rng.random((machines, points)) < 0.8
    mask[:, :3] = True
    return targets, reached, mask


def test_best_rigid_motion_is_scipys_kabsch() -> None:
    targets, reached, mask = random_batch(0)
    rotation, shift = best_rigid_motion(targets, reached, mask)
    for q, p, m, r, t in zip(targets, reached, mask, rotation, shift, strict=True):
        cq, cp = q[m].mean(axis=0), p[m].mean(axis=0)
        expected = Rotation.align_vectors(q[m] - cq, p[m] - cp)[0].as_matrix()
        # Both are the SVD solution of one 3x3 problem: agreement to round-off.
        np.testing.assert_allclose(r, expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(t, cq - expected @ cp, rtol=0, atol=1e-12 * 100)
    assert np.allclose(np.linalg.det(rotation), 1.0, rtol=0, atol=1e-12)


def test_a_pure_translation_or_rigid_motion_of_the_reached_points_is_removed() -> None:
    targets, _, mask = random_batch(1)
    rng = np.random.default_rng(2)
    shifted = targets + rng.normal(0, 10, (len(targets), 1, 3))
    moved = np.einsum("bij,bnj->bni", Rotation.from_rotvec(rng.normal(0, 0.1, (
        len(targets), 3))).as_matrix(), shifted)
    assert np.nanmax(np.abs(remove_translation(targets, shifted, mask))) < FIT_ROUND_OFF
    assert np.nanmax(np.abs(remove_rigid(targets, shifted, mask))) < FIT_ROUND_OFF
    assert np.nanmax(np.abs(remove_rigid(targets, moved, mask))) < FIT_ROUND_OFF
    assert np.all(np.isnan(remove_rigid(targets, moved, mask)[~mask]))
    # A rotation by ~0.1 rad of points ~100 mm out is no translation.
    assert all(f.translation.rms > 1.0 for f in frame_errors(targets, moved, mask))


def test_rigid_errors_ignore_a_rigid_motion_of_the_reached_points() -> None:
    targets, reached, mask = random_batch(3)
    rng = np.random.default_rng(4)
    rotation = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    moved = reached @ rotation.T + rng.normal(0, 50, 3)
    for a, b in zip(frame_errors(targets, reached, mask), frame_errors(targets, moved, mask),
                    strict=True):
        assert b.rigid.rms == pytest.approx(a.rigid.rms, abs=FIT_ROUND_OFF)
        assert b.rigid.max == pytest.approx(a.rigid.max, abs=FIT_ROUND_OFF)


@settings(max_examples=200)
@given(st.integers(1, 3).flatmap(lambda machines: st.integers(1, 12).flatmap(
    lambda points: st.tuples(
        arrays(float, (machines, points, 3), elements=st.floats(-200, 200)),
        arrays(float, (machines, points, 3), elements=st.floats(-200, 200)),
        arrays(bool, (machines, points))))))
def test_each_frame_fits_at_least_as_well_as_the_last(data) -> None:
    # A translation is a rigid motion and no motion is a translation, so each best fit
    # is at most the one before (up to round-off).
    targets, reached, mask = data
    mask[:, 0] = True
    for f in frame_errors(targets, reached, mask):
        assert f.rigid.rms <= f.translation.rms + FIT_ROUND_OFF
        assert f.translation.rms <= f.raw.rms + FIT_ROUND_OFF


def assert_same_frames(a, b) -> None:
    # One computation, whatever the batch around it: equal but for the order of sums.
    for frame in FRAMES:
        assert getattr(a, frame).rms == pytest.approx(getattr(b, frame).rms, rel=1e-14)
        assert getattr(a, frame).max == pytest.approx(getattr(b, frame).max, rel=1e-14)


def test_a_batch_is_its_machines_one_by_one() -> None:
    targets, reached, mask = random_batch(5)
    alone = [frame_errors(q, p[None], m[None])[0]
             for q, p, m in zip(targets, reached, mask, strict=True)]
    for a, b in zip(frame_errors(targets, reached, mask), alone, strict=True):
        assert_same_frames(a, b)
    estimates = [random_machine(k, "paper", design=PROTOTYPE) for k in range(3)]
    truths = [random_machine(10 + k, "realistic", design=PROTOTYPE) for k in range(3)]
    for a, e, t in zip(score_batch(estimates, truths), estimates, truths, strict=True):
        b = score(e, t)
        assert_same_frames(a.tcp_before, b.tcp_before)
        assert_same_frames(a.tcp_after, b.tcp_after)
        assert (a.drho_error, a.dL_error, a.n_targets) == (b.drho_error, b.dL_error, b.n_targets)
