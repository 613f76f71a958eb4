"""The world's size from the readings (:mod:`calibrators.estimators.world_sizes`): the
restricted likelihood's scales on readings drawn from its own model, its test against a
told world, and the options that ask for it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calibrators.estimators.world_sizes import CEILING, estimate_scales, judge

ROOT = Path(__file__).resolve().parents[1]

#: The linear model of the module: N whitened readings, P geometric columns, K terms in
#: two families (the first K / 2 terms family 0).
M, N, P, K = 300, 120, 6, 24


def _draw(scales: tuple[float, float], seed: int = 0) -> tuple[np.ndarray, np.ndarray,
                                                              np.ndarray]:
    """``G`` (M, K, K), ``b`` (M, K) and each term's family, of readings ``J d + C x + e``
    with ``x`` of the families' ``scales`` and white unit noise, ``J`` projected out."""
    rng = np.random.default_rng(seed)
    member = np.repeat([0, 1], K // 2)
    jac = rng.normal(size=(M, N, P))
    # Terms of about a reading's noise each, so that every one is seen.
    c = rng.normal(size=(M, N, K)) * 0.3
    x = rng.normal(size=(M, K)) * np.sqrt(np.array(scales)[member])
    y = (jac @ rng.normal(size=(M, P, 1)))[..., 0] + (c @ x[..., None])[..., 0] + rng.normal(
        size=(M, N))
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
    90 % of machines and names family 1 there, rarely family 0 (its
    own test is at 1e-3: at most a few of 300 machines, five leaves room for the joint
    maximum's small bias)."""
    gram, b, member = _draw((1.0, 9.0), seed=1)
    sizes = judge(gram, b, member, np.ones((M, 2)))
    assert sizes.worse.mean() >= 0.9
    assert sizes.named[:, 1].mean() >= 0.9
    assert sizes.named[:, 0].sum() <= 5


def test_the_told_world_is_rarely_flagged() -> None:
    """Readings of the told world: the test at 1e-3 rejects at most a few of 300
    machines (the expected count is 0.3; Poisson's chance of more than 4 is ~3e-5)."""
    gram, b, member = _draw((1.0, 1.0), seed=2)
    assert judge(gram, b, member, np.ones((M, 2))).worse.sum() <= 4


def test_an_ideal_told_world_against_a_real_one_is_flagged() -> None:
    """Told none of the effects (``ideal``: every told scale 0) of readings with them."""
    gram, b, member = _draw((1.0, 1.0), seed=3)
    sizes = judge(gram, b, member, np.zeros((M, 2)))
    assert sizes.worse.mean() >= 0.9


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "calibrators.cli", *args],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)


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
