"""Predicted TCP errors from an estimate's covariance: the frames' projections on linear
toys, and a Monte-Carlo check against the scorer on sampled true machines."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_experiment

from calibrators.estimators.gauss_newton import GaussNewtonCalibrator
from calibrators.estimators.prediction import predicted_tcp_error
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import ERROR_NAMES, MachineParams
from orthoglide_env.model.kinematics import cross
from orthoglide_env.scoring import (
    FRAMES,
    motion_basis,
    predicted_frame_errors,
    score_batch,
    workspace_grid,
)

TABLE1 = {"drho": [4.66, -5.36, 1.46], "dL": [5.20, -5.96, 3.16]}
#: A projection leaves round-off of a few ulps of the largest column (~100 mm for a
#: rotation about the origin): 1e-12 of it.
PROJECTION_ROUND_OFF: float = 1e-10


def random_covariance(rng: np.random.Generator, size: int) -> np.ndarray:
    factor = rng.normal(size=(size, size))
    return factor @ factor.T


def test_a_translation_in_tcp_space_is_predicted_away() -> None:
    # delta moves every target by the same vector: raw error sqrt(trace C) everywhere.
    rng = np.random.default_rng(0)
    targets = workspace_grid(design=PROTOTYPE)
    jac = np.broadcast_to(np.eye(3), (len(targets), 3, 3))
    cov = random_covariance(rng, 3)
    frames = predicted_frame_errors(targets, jac, cov)
    assert frames.raw.rms == pytest.approx(np.sqrt(np.trace(cov)), rel=1e-12)
    assert frames.raw.max == pytest.approx(np.sqrt(np.trace(cov)), rel=1e-12)
    assert frames.translation.max < PROJECTION_ROUND_OFF
    assert frames.rigid.max < PROJECTION_ROUND_OFF


def test_a_small_rotation_is_predicted_away_only_by_the_rigid_frame() -> None:
    # delta = omega, a rotation about the origin: the error omega x target.
    rng = np.random.default_rng(1)
    targets = workspace_grid(design=PROTOTYPE)
    jac = np.stack([cross(axis, targets) for axis in np.eye(3)], axis=-1)
    frames = predicted_frame_errors(targets, jac, random_covariance(rng, 3))
    assert frames.rigid.max < PROJECTION_ROUND_OFF * np.abs(targets).max()
    assert frames.translation.rms > 1.0 and frames.raw.rms >= frames.translation.rms


def test_rigid_weights_give_the_rigid_frames_mean_square() -> None:
    """``trace(W C)`` of :func:`rigid_weights` is the square of the rigid RMS the per-target
    quadratic forms give, model by model: on realistic models, one of them with targets out
    of its reach (a shorter batch of targets), for random covariances; the two sum the same
    terms in another order (relative round-off ~1e-13)."""
    from orthoglide_env.model.errors import get_preset
    from orthoglide_env.scoring import predicted_tcp_frames_many, rigid_weights

    rng = np.random.default_rng(4)
    models = [get_preset("realistic").sample(rng, PROTOTYPE) for _ in range(3)]
    models.append(MachineParams(drho=[40.0, 0.0, 0.0]))  # loses the far targets along x
    covariances = [random_covariance(rng, 27) * 1e-6 for _ in models]
    weights = rigid_weights(models)
    frames = predicted_tcp_frames_many(models, covariances)
    for w, cov, frame in zip(weights, covariances, frames, strict=True):
        assert np.trace(w @ cov) == pytest.approx(frame.rigid.rms**2, rel=1e-10)


def test_the_rigid_basis_spans_six_motions() -> None:
    targets = workspace_grid(design=PROTOTYPE)
    assert motion_basis(targets, "raw").shape == (3 * len(targets), 0)
    assert np.linalg.matrix_rank(motion_basis(targets, "translation")) == 3
    assert np.linalg.matrix_rank(motion_basis(targets, "rigid")) == 6
    with pytest.raises(ValueError, match="unknown frame"):
        motion_basis(targets, "affine")


def test_predicted_rms_matches_sampled_true_machines() -> None:
    """Sample true machines theta_hat + delta, delta ~ N(0, C) of a gauss-newton estimate
    (over the 27 machine errors: the six fitted, and the 21 it leaves out at their
    a-priori size), score the estimate against each: the mean square of the scored RMS is
    the prediction, in every frame."""
    episode, _ = paper_experiment(TABLE1, errors="paper", gauge_sigma=0.0,
                                  gauge_resolution=0.0)
    readings = episode.measurements
    # The left-out errors wander by the realistic preset's sizes (up to 2 mrad, 0.5 mm), so
    # the second-order TCP error, ~|delta|^2 / L, is ~2e-3 of the first-order one; its share
    # of the mean square, ~4e-3, is far below the tolerance (13 % of it; the sampled and
    # predicted means differ by 1-2 %).
    est = GaussNewtonCalibrator(params="paper6", sigma=1e-4, verify=False).fit(readings)
    samples = 1000
    rng = np.random.default_rng(2)
    n = len(ERROR_NAMES)
    deltas = rng.multivariate_normal(np.zeros(n), est.error_covariance[:n, :n], size=samples)
    truths = [MachineParams.from_vector(t, PROTOTYPE) for t in est.theta[:n] + deltas]
    reports = score_batch([est.machine] * samples, truths)
    predicted = predicted_tcp_error(est)
    for frame in FRAMES:
        square = np.array([getattr(r.tcp_after, frame).rms for r in reports]) ** 2
        # Five standard errors of the sample mean (CLT over 1000 samples): a false alarm
        # has probability ~6e-7, and the seed is fixed.
        tolerance = 5 * square.std() / np.sqrt(samples)
        assert abs(square.mean() - getattr(predicted, frame).rms ** 2) < tolerance, frame
    assert predicted.rigid.rms < predicted.translation.rms < predicted.raw.rms



def test_rigid_weights_are_each_models_alone_whatever_its_block_and_commands() -> None:
    """A batch of more than one block of models, some reaching fewer targets (a rigid basis
    of their own, found again in the next block), gives each model the bits it gets alone,
    and the same bits again from the commands a scoring of the same models solved: the
    batch shares the bases and the commands, never a number of another model."""
    from orthoglide_env.model.errors import get_preset
    from orthoglide_env.scoring import commands_many, rigid_weights
    from orthoglide_env.scoring.grid import BLOCK

    rng = np.random.default_rng(5)
    models = [get_preset("realistic").sample(rng, PROTOTYPE) for _ in range(BLOCK + 4)]
    for k in (3, BLOCK + 1):  # one in each block loses the far targets along x
        models[k] = MachineParams(drho=[40.0, 0.0, 0.0])
    weights = rigid_weights(models)
    commands = commands_many(models, workspace_grid(design=PROTOTYPE))
    assert np.array_equal(rigid_weights(models, commands=commands), weights)
    for k in (0, 3, BLOCK - 1, BLOCK, BLOCK + 1, BLOCK + 3):
        assert np.array_equal(rigid_weights([models[k]])[0], weights[k]), k


def test_a_scoring_from_the_estimates_commands_is_the_same() -> None:
    """:func:`score_batch` given the estimates' commands over the grid (which compare
    solves once for the scoring and the predicted error) scores as it does solving them."""
    from orthoglide_env.model.errors import random_machine
    from orthoglide_env.scoring import commands_many

    estimates = [random_machine(k, "paper", design=PROTOTYPE) for k in range(3)]
    truths = [random_machine(10 + k, "realistic", design=PROTOTYPE) for k in range(3)]
    commands = commands_many(estimates, workspace_grid(design=PROTOTYPE))
    assert score_batch(estimates, truths, commands=commands) == score_batch(estimates, truths)
