"""The world's size from the readings (:mod:`calibrators.estimators.world_sizes`): the
restricted likelihood's scales on readings drawn from its own model, its test against a
told world, and the options that ask for it."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from conftest import command_here

from calibrators.estimators.world_sizes import (
    BLIND_SPOT,
    CEILING,
    DETERMINED,
    HONEST_RATIO,
    SEEN_POWER,
    WORLD_LEVEL,
    blind_spot,
    estimate_scales,
    judge,
    power_against,
    seen_families,
    threshold,
    thresholds,
    widening,
)

#: The linear model of the module: N whitened readings, P geometric columns, K terms in
#: two families (the first K / 2 terms family 0).
M, N, P, K = 300, 120, 6, 24


def _draw(scales: tuple[float, float], seed: int = 0, machines: int = M
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``G`` (M, K, K), ``b`` (M, K) and each term's family, of readings ``J d + C x + e``
    with ``x`` of the families' ``scales`` and white unit noise, ``J`` projected out."""
    rng = np.random.default_rng(seed)
    member = np.repeat([0, 1], K // 2)
    jac = rng.normal(size=(machines, N, P))
    # Terms of about a reading's noise each, so that every one is seen.
    c = rng.normal(size=(machines, N, K)) * 0.3
    x = rng.normal(size=(machines, K)) * np.sqrt(np.array(scales)[member])
    y = ((jac @ rng.normal(size=(machines, P, 1)))[..., 0] + (c @ x[..., None])[..., 0]
         + rng.normal(size=(machines, N)))
    q, _ = np.linalg.qr(jac)
    py = y - (q @ (np.swapaxes(q, 1, 2) @ y[..., None]))[..., 0]
    pc = c - q @ (np.swapaxes(q, 1, 2) @ c)
    return np.swapaxes(c, 1, 2) @ pc, (np.swapaxes(c, 1, 2) @ py[..., None])[..., 0], member


def test_the_scales_are_the_drawn_ones() -> None:
    """The median over machines of each family's scale is the drawn one: with 12 terms
    of about the noise's size a machine's scale has a relative spread of about
    sqrt(2 / 12) ~ 0.4, its median over 300 machines ~0.03; 15 % is five of those (the
    maximum of a likelihood is biased low by a few % at 12 terms: the median stays
    inside)."""
    gram, b, member = _draw((1.0, 3.0))
    scales = estimate_scales(gram, b, member, 2, np.ones((M, 2)))
    assert np.median(scales[:, 0]) == pytest.approx(1.0, rel=0.15)
    assert np.median(scales[:, 1]) == pytest.approx(3.0, rel=0.15)
    assert scales.max() <= CEILING


def test_a_world_worse_than_told_is_flagged_and_named() -> None:
    """Family 1 drawn at nine times the told second moment (three times its size, the
    workshop's backlash against the lab's): the test rejects the told world on at least
    90 % of machines and names family 1 there, rarely family 0: its own one-sided test at
    WORLD_LEVEL (0.01) names it on about 3 of 300 machines, and its cost is taken with
    family 1 held where the joint maximum put it, a little above the profile's; more than
    10 has a chance below 1e-3 even at 0.015."""
    gram, b, member = _draw((1.0, 9.0), seed=1)
    sizes = judge(gram, b, member, np.ones((M, 2)))
    assert sizes.worse.mean() >= 0.9
    assert sizes.named[:, 1].mean() >= 0.9
    assert sizes.named[:, 0].sum() <= 10


def test_the_threshold_is_the_law_of_a_ratio_at_a_bound() -> None:
    """One family: even odds of chi-square 0 and 1, so the threshold is chi-square 1's at
    twice the level; F families: the mixture's tail at the threshold is the level."""
    from scipy import special, stats

    assert threshold(1) == pytest.approx(stats.chi2.isf(2 * WORLD_LEVEL, 1), rel=1e-9)
    for f in (2, 6):
        k = np.arange(1, f + 1)
        tail = np.sum(special.comb(f, k) / 2.0**f * stats.chi2.sf(threshold(f), k))
        assert tail == pytest.approx(WORLD_LEVEL, rel=1e-6)
    assert threshold(0) == np.inf


def test_a_batchs_thresholds_are_each_machines_own() -> None:
    """Solved once per count of families seen, each machine's threshold is the one of its
    own count, to the bit, in the machines' order (none seen: no ratio passes)."""
    seen = np.random.default_rng(0).random((50, 3)) < 0.5
    assert {int(n) for n in seen.sum(axis=1)} == {0, 1, 2, 3}
    expected = [threshold(int(n)) for n in seen.sum(axis=1)]
    assert thresholds(seen).tolist() == expected
    assert thresholds(seen[:0]).shape == (0,)


@pytest.mark.slow
def test_the_told_world_is_flagged_at_the_tests_level() -> None:
    """Readings of the told world, 4000 machines: the share flagged is the test's level
    (0.01) to within the binomial spread: 40 expected, standard deviation 6.3, and
    [20, 62] holds 99.9 % of it (seed 2 flags 31: the families' columns overlap a little,
    and the mixture's even odds per family hold only apart).  The ratio read as
    chi-square with 2 degrees flags 13 of them."""
    machines = 4000
    gram, b, member = _draw((1.0, 1.0), seed=2, machines=machines)
    flagged = judge(gram, b, member, np.ones((machines, 2))).worse.sum()
    assert 20 <= flagged <= 62


def test_an_ideal_told_world_against_a_real_one_is_flagged() -> None:
    """Told none of the effects (``ideal``: every told scale 0) of readings with them."""
    gram, b, member = _draw((1.0, 1.0), seed=3)
    sizes = judge(gram, b, member, np.zeros((M, 2)))
    assert sizes.worse.mean() >= 0.9


def _widening_drawn(seed: int, size: float, share: float) -> tuple[float, float, float]:
    """Least squares of readings ``J d + C x + e`` (unit noise, terms ``C`` of ``size``,
    coefficients of unit second moment) over 4000 machines, with error bars that hold the
    terms at ``share`` of their second moment (``cov + share moved moved^T``): the pooled
    z-RMS along the eigenvectors of that covariance, the widening the terms at the rest of
    their size predict, and the widening of terms that move nothing."""
    rng = np.random.default_rng(seed)
    machines, n, p, k = 4000, 60, 6, 8
    jac = rng.normal(size=(n, p))
    terms = rng.normal(size=(n, k)) * size
    noise_cov = np.linalg.inv(jac.T @ jac)
    moved = noise_cov @ jac.T @ terms
    told_cov = noise_cov + share * moved @ moved.T
    # A prior wide enough that every direction is determined (variance <= DETERMINED).
    scale = np.full(p, 10 * np.sqrt(np.linalg.eigvalsh(told_cov).max() / DETERMINED))
    truth = rng.normal(size=(machines, p))
    readings = truth @ jac.T + rng.normal(size=(machines, k)) @ terms.T + rng.normal(
        size=(machines, n))
    error = readings @ (noise_cov @ jac.T).T - truth
    values, vectors = np.linalg.eigh(told_cov)
    z = (error @ vectors) / np.sqrt(values)
    predicted = widening(told_cov[None], moved[None] * np.sqrt(1 - share), scale)[0]
    return (float(np.sqrt(np.mean(z**2))), float(predicted),
            float(widening(told_cov[None], moved[None] * 0.0, scale)[0]))


def test_the_widening_is_the_z_rms_the_terms_give() -> None:
    """Error bars of the noise alone (share 0): the z-RMS is the widening's (about 1.4
    here).  Each z^2 is Gaussian's square, mean w^2 and variance 2 w^4: the pooled mean of
    4000 x 6 has a relative spread of sqrt(2 / 24000) ~ 0.009, 0.005 on the z-RMS; 2.5 %
    is five of those.  Terms that move nothing widen nothing."""
    measured, predicted, nothing = _widening_drawn(4, 0.4, 0.0)
    assert predicted > HONEST_RATIO
    assert measured == pytest.approx(predicted, rel=0.025)
    assert nothing == pytest.approx(1.0)


def test_the_widening_against_a_harsher_world_counts_only_what_the_told_one_leaves_out(
        ) -> None:
    """A fit told a world that carries the terms at a share 0.3 of a harsher world's
    second moment, the readings drawn in the harsher world: the z-RMS is the widening of
    the terms at the rest of their size, ``sqrt(1 - s)`` of them (about 1.3 here).  As
    above, 2.5 % is five standard deviations, a false failure below 1e-6."""
    measured, predicted, nothing = _widening_drawn(9, 0.6, 0.3)
    assert predicted > HONEST_RATIO
    assert measured == pytest.approx(predicted, rel=0.025)
    assert nothing == pytest.approx(1.0)


@pytest.mark.slow
def test_the_power_bounds_the_share_flagged_from_below() -> None:
    """Family 1 drawn at a scale above the told one, 300 machines a case: the share the
    world test flags is at least the bound's mean less three binomial standard deviations
    (at most sqrt(0.25 / 300) ~ 0.029 each: a false failure about 1e-3 per case), and the
    bound is not empty: it passes SEEN_POWER only where the test flags at least that
    share, and the family held at its told size gets none."""
    machines = 300
    for told_scale, drawn, seed in ((1.0, 3.0, 5), (0.0, 0.2, 7), (0.0, 0.4, 8)):
        gram, b, member = _draw((told_scale, drawn), seed=seed, machines=machines)
        told = np.full((machines, 2), told_scale)
        alternative = np.tile([told_scale, drawn], (machines, 1))
        flagged = judge(gram, b, member, told).worse.mean()
        power = power_against(gram, member, told, alternative,
                              seen_families(gram, member, 2))
        assert (power[:, 0] == 0).all()
        bound = power[:, 1].mean()
        assert flagged >= bound - 3 * np.sqrt(0.25 / machines)
        if bound >= SEEN_POWER:
            assert flagged >= SEEN_POWER - 3 * np.sqrt(0.25 / machines)


def test_a_blind_spot_names_the_fewest_families_that_pass_the_band() -> None:
    """Blind families whose excesses of z^2 add beyond HONEST_RATIO^2 - 1 are named,
    largest first, as few as pass the band; a family the test sees, one not understated
    (factor 1) or a sum inside the band says nothing."""
    families = ("lead", "periodic", "backlash", "warmup", "stands", "dial")
    factors = np.array([1.10, 1.0, 1.01, 1.20, 1.0, 1.03])
    blind = np.zeros(6)
    words = blind_spot("ideal", "lab", families, factors, blind)
    assert words is not None and words.startswith(BLIND_SPOT)
    assert "warmup (1.20x" in words and "lead (1.10x" in words and "dial" not in words
    assert f"{np.sqrt(1 + np.sum(factors**2 - 1)):.2f}x too narrow" in words
    seen = blind.copy()
    seen[3] = 0.95
    assert blind_spot("ideal", "lab", families, factors, seen) is None
    assert blind_spot("lab", "lab", families, np.ones(6), blind) is None


def test_a_blind_spot_is_asked_of_every_harsher_world_and_gone_when_told_the_harshest(
        ) -> None:
    """The tracker's experiment on 4 machines of an ideal world, fitted told ``ideal``: its
    readings see the lab's lead error at least in part, and the lab's unseen effects
    widen its error bars about 1.24x, inside the band, but the workshop's do beyond it.
    Where the world test is silent (it flags a told world's experiment at 0.01: all four
    flagged, which would leave nothing to check, has a chance of 1e-8), the fit names a
    blind spot whose factor passes the band; told the ``workshop``, no world is harsher
    and none is named."""
    from calibrators.estimators.catalogue import for_study
    from calibrators.study.compare import Config, agent_episodes
    from orthoglide_env.world.conditions import Conditions

    config = Config(agents=("tracker",), estimators=("full",), conditions=Conditions("ideal"),
                    seed=1, sigma=0.02)
    readings = [e.run.measurements for e in agent_episodes(config, "tracker", [0, 1, 2, 3])]
    fits = {told: for_study("full", 0.02, Conditions(told), "realistic",
                            world_check=True).fit_many(readings)
            for told in ("ideal", "workshop")}
    checked = 0
    for ideal, workshop in zip(fits["ideal"], fits["workshop"], strict=True):
        assert not any(w.startswith(BLIND_SPOT) for w in workshop.warnings)
        words = [w for w in ideal.warnings if w.startswith("world:")]
        if words and not words[0].startswith(BLIND_SPOT):
            continue
        checked += 1
        assert len(words) == 1
        factor = float(words[0].split("its error bars are ")[1].split("x too narrow")[0])
        assert factor > HONEST_RATIO
    assert checked > 0


def _cli(*args: str) -> subprocess.CompletedProcess:
    """The command, run in this process (``command_here``: what it writes and its status
    are tested here, the process a user starts in tests/test_cli.py)."""
    return command_here(list(args))


def test_calibrate_tells_the_fit_auto_and_refuses_an_auto_lab() -> None:
    """``--fit-conditions auto`` fits; ``--conditions auto`` names no world to draw the
    readings from: one line, status 2, pointing to ``--fit-conditions``."""
    run = _cli("calibrate", "--conditions", "workshop", "--fit-conditions", "auto",
               "--backend", "exact", "--agent", "paper", "--json")
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["z_rms"] > 0
    refused = _cli("calibrate", "--conditions", "auto", "--agent", "paper")
    assert refused.returncode == 2
    assert len(refused.stderr.strip().splitlines()) == 1
    assert "--fit-conditions auto" in refused.stderr


def test_fit_auto_refuses_effects(tmp_path) -> None:
    """``fit --conditions auto`` estimates every effect: a list of them is refused."""
    sheet = tmp_path / "m.csv"
    made = _cli("calibrate", "--conditions", "lab", "--backend", "exact", "--agent", "paper",
                "--save-measurements", str(sheet))
    assert made.returncode == 0, made.stderr
    auto = _cli("fit", str(sheet), "--conditions", "auto", "--json")
    assert auto.returncode == 0, auto.stderr
    refused = _cli("fit", str(sheet), "--conditions", "auto", "--effects", "lead")
    assert refused.returncode == 2 and "--conditions auto" in refused.stderr


def test_a_run_kept_without_the_new_options_resumes() -> None:
    """A comparison's kept options (config.json) are those of before, unless the fit is
    told another world or checks it."""
    from calibrators.cli.compare import _config_dict
    from calibrators.study.compare import Config

    plain = _config_dict(Config(agents=("paper",), estimators=("paper6",)), 3)
    assert "fit_conditions" not in plain and "world_check" not in plain
    told = _config_dict(Config(agents=("paper",), estimators=("full",),
                               fit_conditions="auto", world_check=True), 3)
    assert told["fit_conditions"] == "auto" and told["world_check"] is True


def test_an_auto_fit_keeps_the_world_it_found_in_its_estimate_file(tmp_path) -> None:
    """``fit --conditions auto --save-estimate``: the estimate file holds each effect
    family's scale that the readings showed, within its bounds (positive: kept at least at
    the lab's size and at FLOOR; at most CEILING times the workshop's second moment), and
    they come back from the file; a fit told the world writes no scales."""
    from calibrators.estimators.base import Estimate
    from calibrators.workflow.compensate import CALIBRATION_KEY, read_estimate

    sheet = tmp_path / "m.csv"
    made = _cli("calibrate", "--conditions", "lab", "--backend", "exact", "--agent", "paper",
                "--save-measurements", str(sheet))
    assert made.returncode == 0, made.stderr
    for told in ("auto", "lab"):
        run = _cli("fit", str(sheet), "--conditions", told, "--save-estimate",
                   str(tmp_path / f"{told}.json"))
        assert run.returncode == 0, run.stderr
    auto = read_estimate(tmp_path / "auto.json")
    assert set(auto.world_scales) and all(0 < v <= CEILING for v in auto.world_scales.values())
    assert Estimate.from_dict(json.loads(json.dumps(auto.to_dict()))).world_scales == (
        auto.world_scales)
    assert "world_scales" not in json.loads((tmp_path / "lab.json").read_text())[
        CALIBRATION_KEY]
