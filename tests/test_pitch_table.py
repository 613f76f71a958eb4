"""The controller's pitch-error tables: what the ``full`` estimator fits of the drives' lead
error, how a controller applies it, and what it leaves of the tool's error."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.estimators.base import Estimate
from calibrators.estimators.consider import (
    FULL_TERMS,
    consider_terms,
    lead_terms,
    table_prior,
    term_family,
)
from calibrators.estimators.exact_fit import fit_batch, world_columns
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator
from calibrators.estimators.prediction import predicted_tcp_error
from calibrators.study.episodes import run_episode
from orthoglide_env.model.compensation import PitchTable, interpolation_weights, node_count
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.scoring import score, tcp_error_vectors_many, workspace_grid
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.truth import World

sys.path.insert(0, str(Path(__file__).parent))
from test_consider import GAUGES, lead_machines


def test_a_table_interpolates_linearly_from_its_reference_and_round_trips() -> None:
    """A linear error is reproduced between nodes to round-off; the reference node is 0;
    beyond the last node the table is held flat; JSON and CSV keep every value."""
    count = node_count(PROTOTYPE.rho_max - PROTOTYPE.rho_min, 20.0)
    assert count == int(np.ceil((PROTOTYPE.rho_max - PROTOTYPE.rho_min) / 20.0))
    slope = np.array([1e-4, -2e-4, 3e-5])
    nodes = PROTOTYPE.rho_min + 20.0 * np.arange(count + 1)
    values = slope[:, None] * (nodes - PROTOTYPE.rho_min)[None]
    table = PitchTable(PROTOTYPE.rho_min, 20.0, values, np.full(values.shape, 1e-3))
    rho = np.random.default_rng(0).uniform(PROTOTYPE.rho_min, nodes[-1], (50, 3))
    np.testing.assert_allclose(table.error(rho), slope * (rho - PROTOTYPE.rho_min),
                               rtol=0, atol=1e-15)
    assert np.all(table.error(np.full((1, 3), PROTOTYPE.rho_min)) == 0)
    np.testing.assert_allclose(table.error(np.full((1, 3), nodes[-1] + 50)), values[:, -1:].T)
    again = PitchTable.from_dict(table.to_dict())
    np.testing.assert_array_equal(again.values, table.values)
    rows = table.to_csv().splitlines()
    assert rows[0] == "axis,position_mm,error_mm,sigma_mm" and len(rows) == 1 + 3 * (count + 1)
    weights = interpolation_weights(rho, PROTOTYPE.rho_min, 20.0, count)
    np.testing.assert_allclose(weights.sum(axis=-1), np.where(
        rho - PROTOTYPE.rho_min < 20.0, (rho - PROTOTYPE.rho_min) / 20.0, 1.0), atol=1e-12)


def _moments_agree(samples: np.ndarray, expected: np.ndarray) -> None:
    """The sample second moments of ``samples`` (D, K) against ``expected`` (K, K), each
    entry within 5 of its own standard errors (from the samples' spread of the products):
    over a few hundred entries a true match fails with probability below 1e-4, and with
    20,000 draws an error of about 5 % of a variance is found."""
    products = samples[:, :, None] * samples[:, None, :]
    error = products.std(axis=0) / np.sqrt(len(samples))
    difference = products.mean(axis=0) - expected
    worst = np.max(np.abs(difference) / (error + 1e-30))
    assert worst < 5.0, (worst, np.abs(difference).max(), expected.max())


@pytest.mark.parametrize("name", ["lab", "workshop"])
def test_the_fits_lead_prior_is_the_curve_the_lab_draws(name: str) -> None:
    """The fit's lead error has the truth's own second moments: the pitch table's prior
    at its nodes against the smooth part (scale and two sines) of 20,000 drawn worlds'
    lead errors, and the terms without a table, the screw's periodic error included,
    against the whole drawn error at postures off the nodes."""
    conditions = Conditions(name, effects=("lead",))
    spacing = 10.0
    count, root = table_prior(PROTOTYPE, conditions, spacing)
    nodes = PROTOTYPE.rho_min + spacing * np.arange(1, count + 1)
    off_nodes = np.linspace(PROTOTYPE.rho_min + 3.3, PROTOTYPE.rho_max - 1.7, 9)
    smooth, whole = [], []
    for m in range(20_000):
        world = World.draw(conditions, np.random.default_rng(m), 1)
        on_nodes = np.repeat(nodes[:, None], 3, axis=1)[None]
        smooth.append(replace(world, lead_periodic=np.zeros((1, 3))).lead_error(
            on_nodes, PROTOTYPE)[0, :, 0])
        whole.append(world.lead_error(np.repeat(off_nodes[:, None], 3, axis=1)[None],
                                      PROTOTYPE)[0, :, 0])
    _moments_agree(np.array(smooth), root @ root.T)
    patterns = np.stack([p[:, 0] for n, p in lead_terms(
        np.repeat(off_nodes[:, None], 3, axis=1), PROTOTYPE, conditions) if n.endswith("[x]")],
        axis=-1)
    _moments_agree(np.array(whole), patterns @ patterns.T)


@pytest.mark.parametrize(("spacing", "fragment"), [(0.0, "must be positive"),
                                                   (-5.0, "must be positive"),
                                                   (float("nan"), "must be positive"),
                                                   (1000.0, "larger than the drives' travel")])
def test_a_node_spacing_that_cannot_be_a_table_is_refused(spacing: float, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        node_count(PROTOTYPE.rho_max - PROTOTYPE.rho_min, spacing)


def test_a_controller_that_compensates_the_true_lead_error_meets_the_machine_without_it(
        ) -> None:
    """Commanding ``rho - lead(rho)`` puts the nut where the lead-free machine's would be,
    up to the lead error's change over the correction itself: at most its slope (the
    periodic term's 2 pi 4 um / 5 mm under workshop, 5e-3) times the correction (at most
    about 50 um): 0.25 um.  The scoring then sees the machine without the world."""
    truth = MachineParams.from_vector(np.random.default_rng(2).normal(0, 0.05, 27), PROTOTYPE)
    world = World.draw(Conditions("workshop", effects=("lead",)), np.random.default_rng(3), 6)
    grid = workspace_grid(design=PROTOTYPE)
    plain = tcp_error_vectors_many([truth], [truth], grid)
    leadless = tcp_error_vectors_many([truth], [truth], grid, [world])
    compensated = tcp_error_vectors_many(
        [truth], [truth], grid, [world],
        [lambda rho: world.lead_error(rho[None], PROTOTYPE)[0]])
    assert np.nanmax(np.abs(leadless - plain)) > 5e-3  # the lead error is there to remove
    assert np.nanmax(np.abs(compensated - plain)) < 2.5e-4


@pytest.mark.slow
def test_the_tables_error_bars_hold_against_the_true_lead_error() -> None:
    """Workshop lead error alone, the axial experiment of ``test_consider`` (200 postures
    at 3 um), the extended fit with the table's terms (10 mm nodes) fitted and the
    periodic ones considered: over 40 machines the table's nodes against the truth's
    smooth lead error (its periodic part taken off) have a z-RMS within [0.8, 1.25] (about
    1500 correlated values; measured 0.94).  Base-fixed gauges see almost nothing of it:
    the table's error stays near the truth's size (measured 9.6 against 9.5 um): a drive's
    error along its own travel is an encoder offset that changes slowly with the posture,
    which the legs' parallelism hardly sees."""
    conditions = Conditions("workshop", effects=("lead",))
    spacing = 10.0
    design, _, values, free, prior, scale = lead_machines(conditions)
    machines = len(values)
    fitted, rest = consider_terms(design, values, None, conditions, spacing).split(("lead",))
    assert rest.names and all(term_family(n) == "periodic" for n in rest.names)
    world = world_columns(design, fitted)
    k = world.shape[-1]

    def more(a: np.ndarray, v: float) -> np.ndarray:
        return np.concatenate([a, np.full(k, v, dtype=a.dtype)])

    fit = fit_batch(design, values, np.ones(values.shape, bool), 0.003, more(free, True),
                    np.zeros(len(scale) + k), more(prior, 1.0), more(scale, 1.0),
                    consider=rest, world=world)
    count, root = table_prior(PROTOTYPE, conditions, spacing)
    nodes = PROTOTYPE.rho_min + spacing * np.arange(1, count + 1)
    n, nf = len(scale), int(free.sum())
    z, error, size = [], [], []
    for m in range(machines):
        truth_world = World.draw(conditions, np.random.default_rng(m), len(GAUGES))
        lead = truth_world.lead_error(np.repeat(nodes[:, None], 3, axis=1)[None], PROTOTYPE)[0]
        periodic = truth_world.lead_periodic * np.sin(
            2 * np.pi * (nodes[:, None] - PROTOTYPE.rho_min) / 5.0 + truth_world.lead_phase)
        smooth = lead - periodic
        cov = fit.scaled_covariance[m][nf:, nf:]
        for a, axis in enumerate("xyz"):
            mine = [j for j, name in enumerate(fitted.names) if name.endswith(f"[{axis}]")]
            table = root @ fit.theta[m, n:][mine]
            sigma = np.sqrt(np.diag(root @ cov[np.ix_(mine, mine)] @ root.T))
            z.append((table - smooth[:, a]) / sigma)
            error.append(table - smooth[:, a])
            size.append(smooth[:, a])
    z_rms = np.sqrt(np.mean(np.concatenate(z) ** 2))
    assert 0.8 <= z_rms <= 1.25, z_rms
    assert np.sqrt(np.mean(np.concatenate(error) ** 2)) < 1.1 * np.sqrt(
        np.mean(np.concatenate(size) ** 2))


@pytest.fixture(scope="session")
def tracker_lab() -> tuple:
    """The tracker agent's hour under ``lab`` on one machine (exact backend), its
    readings, the truth and its world."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, backend="exact", conditions="lab", tracker=True,
                   errors="realistic")
    try:
        episode = run_episode(env, get_agent("tracker"), 7)
    finally:
        env.close()
    return episode.measurements, episode.sigma, episode.truth, episode.world


def test_full_fits_the_tables_and_its_prediction_carries_the_drives(tracker_lab,
                                                                     tmp_path) -> None:
    """``--params full``: the extended parameters and the lab's terms of FULL_TERMS (the
    table's among them), the rest considered; the estimate's table, sized by its
    covariance, survives JSON.  A tracker sees the drives' error: the table's sigma at
    the stroke's end is below its prior's.  Compensating with the table leaves a TCP
    error (rigid) no larger than the extended fit's, which carries the lead error in its
    error bars; each fit's predicted error includes the drives' part (above the
    geometry-only prediction)."""
    data, sigma, truth, world = tracker_lab
    full = GaussNewtonCalibrator(params="full", sigma=sigma, verify=False,
                                 conditions="lab").fit(data)
    extended = GaussNewtonCalibrator(params="extended", sigma=sigma, verify=False,
                                     conditions="lab").fit(data)
    fitted = {term_family(n[len("world."):]) for n in full.names if n.startswith("world.")}
    assert {"lead", "backlash", "warmup"} <= fitted <= set(FULL_TERMS)
    assert {"periodic", "dial"} <= {term_family(n) for n in full.considered}
    table = full.pitch_table
    assert table is not None and extended.pitch_table is None
    _, root = table_prior(PROTOTYPE, Conditions("lab"), full.node_spacing)
    prior_end = np.sqrt(np.sum(root[-1] ** 2))
    assert np.all(table.sigma[:, -1] < 0.9 * prior_end), (table.sigma[:, -1], prior_end)
    path = tmp_path / "full.json"
    full.to_json(path)
    again = Estimate.from_json(path)
    np.testing.assert_array_equal(again.pitch_table.values, table.values)
    np.testing.assert_array_equal(again.lead_covariance, full.lead_covariance)

    # The controller's backlash values, each within 4 of its sigmas of the truth's.
    backlash = full.backlash
    assert backlash is not None and extended.backlash is None
    for a, axis in enumerate("xyz"):
        value, std = backlash[axis]["value"], backlash[axis]["sigma"]
        assert std > 0 and abs(value - world.backlash[0, a]) < 4 * std, (axis, value, std)
    after = {name: score(est.machine, truth, world=world,
                         correction=est.lead_correction if est.fits_lead else None)
             for name, est in (("full", full), ("extended", extended))}
    assert after["full"].tcp_after.rigid.rms <= 1.05 * after["extended"].tcp_after.rigid.rms
    for est in (full, extended):
        geometry = Estimate.from_dict({**est.to_dict(), "lead_terms": []})
        assert predicted_tcp_error(est).rigid.rms > predicted_tcp_error(geometry).rigid.rms
