"""Estimators in scikit-learn's shape: configured and checked at construction, ``fit`` and
``fit_many``, the named catalogue, and the earlier call forms that still work."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import paper_experiment

from calibrators.cli import main
from calibrators.estimators import CATALOGUE, Estimate, Estimator, get_estimator
from calibrators.estimators.base import get_strategy
from calibrators.estimators.catalogue import for_study
from calibrators.estimators.constraints import InvalidParameterError
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator
from calibrators.estimators.paper_linear import NeedsExactFit, PaperCalibrator
from orthoglide_env.scoring import BLOCK


@pytest.fixture(scope="module")
def readings():
    """Three machines' readings of the paper's experiment and their gauges' sigma."""
    episodes = [paper_experiment(None, seed, errors="paper", gauge_sigma=0.01)[0]
                for seed in (1, 2, 3)]
    return [e.measurements for e in episodes], episodes[0].sigma


def test_every_catalogue_name_is_a_configured_instance() -> None:
    assert list(CATALOGUE) == ["paper", "paper6", "extended", "extended-base",
                               "extended-world", "full"]
    assert isinstance(get_estimator("paper"), PaperCalibrator)
    full = get_estimator("full", sigma=0.05, conditions="lab")
    assert isinstance(full, GaussNewtonCalibrator)
    assert (full.params, full.prior, full.sigma, full.conditions) == ("full", "auto", 0.05, "lab")
    assert get_estimator("extended-base").prior == "none"
    assert get_estimator("extended-world").fit_world is True
    # A new instance each time: the catalogue's own is never changed.
    assert get_estimator("full") is not CATALOGUE["full"]
    assert CATALOGUE["full"].sigma != 0.05
    with pytest.raises(ValueError, match=r"unknown estimator 'oracle'; choose from \['paper'"):
        get_estimator("oracle")


@pytest.mark.parametrize(
    ("name", "config", "fragment"),
    [
        ("full", {"holdout": 1.5}, "parameter 'holdout' must be a number in [0, 1), got 1.5"),
        ("full", {"solver": "newton"},
         "parameter 'solver' must be one of ['gauss-newton', 'scipy'], got 'newton'"),
        ("full", {"sigma": -1.0}, "parameter 'sigma' must be a number in [0, inf)"),
        ("full", {"verify": "yes"}, "parameter 'verify' must be True or False"),
        ("extended", {"left_out": "huge"},
         "parameter 'left_out' must be one of ['nominal', 'paper', 'realistic']"),
        ("extended", {"conditions": "moon"}, "parameter 'conditions' must be one of ['ideal'"),
        ("extended", {"fit_world": ("lead", "heat")}, "unknown estimator term(s) ['heat']"),
        ("extended", {"prior": "attach=-1"}, "prior sigma of 'attach' must be > 0"),
        ("extended", {"fix": {"drho_x": float("nan")}}, "parameter 'fix' must be None or"),
        ("extended", {"node_spacing": 0}, "parameter 'node_spacing' must be None or a number"),
        ("extended", {"seed": 1.5}, "parameter 'seed' must be an integer"),
        ("paper", {"sigma": float("inf")}, "parameter 'sigma' must be a number in [0, inf)"),
    ],
)
def test_a_bad_value_is_refused_at_construction_naming_the_parameter(name, config, fragment
                                                                     ) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        get_estimator(name, **config)
    assert fragment in str(caught.value)
    assert caught.value.parameter == next(iter(config))


def test_an_unknown_parameter_is_refused_naming_the_known_ones() -> None:
    with pytest.raises(InvalidParameterError, match="takes no sigmas; its parameters are "
                                                    "params, sigma, verify, prior"):
        get_estimator("full", sigmas=0.1)
    # What only the exact-model fit takes, the paper's fit refuses in its own words.
    with pytest.raises(NeedsExactFit, match="takes no prior, holdout; the exact-model fit"):
        get_estimator("paper", prior="none", holdout=0.3)
    with pytest.raises(NeedsExactFit, match="not 'extended'"):
        get_estimator("paper", params="extended")


def test_configuration_is_read_back_and_cloned() -> None:
    est = GaussNewtonCalibrator(params="extended", sigma=0.01, holdout=0.2)
    params = est.get_params()
    assert params["params"] == "extended" and params["holdout"] == 0.2
    assert GaussNewtonCalibrator(**params).get_params() == params
    other = est.clone(sigma=0.03)
    assert other.sigma == 0.03 and est.sigma == 0.01 and other.holdout == 0.2
    assert GaussNewtonCalibrator.takes("conditions") and not PaperCalibrator.takes("conditions")
    assert "GaussNewtonCalibrator(params='extended'" in repr(est)


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_fit_many_is_each_fit(readings, name: str) -> None:
    """The batched path (one solve for experiments of one design) gives each experiment
    the estimate it gets alone, to the solver's convergence (1e-9 of each scale)."""
    datas, sigma = readings
    estimator = for_study(name, sigma)
    batch = estimator.fit_many(datas)
    for data, together in zip(datas, batch, strict=True):
        alone = estimator.fit(data)
        assert isinstance(together, Estimate)
        np.testing.assert_allclose(together.theta, alone.theta, rtol=0, atol=1e-9)
        np.testing.assert_allclose(together.covariance, alone.covariance, rtol=0,
                                   atol=1e-8 * np.abs(alone.covariance).max())


def test_a_batch_over_several_blocks_gives_each_machine_its_own_error_covariance(readings
                                                                                 ) -> None:
    """The model-error covariance works through blocks of machines (``BLOCK``): a batch
    that spans several, each experiment many times over, gives every copy the covariance
    its experiment gets alone (to the solver's convergence, as above)."""
    datas, sigma = readings
    estimator = for_study("paper6", sigma)
    copies = BLOCK // len(datas) + 2
    batch = estimator.fit_many(datas * copies)
    assert len(batch) > BLOCK
    for k, data in enumerate(datas):
        alone = estimator.fit(data).error_covariance
        # The left-out errors fill the covariance beyond the six fitted parameters.
        assert np.count_nonzero(np.diagonal(alone)) > 6
        for together in batch[k::len(datas)]:
            np.testing.assert_allclose(together.error_covariance, alone, rtol=0,
                                       atol=1e-8 * np.abs(alone).max())


def test_fit_many_returns_a_failure_in_place_of_its_estimate(readings) -> None:
    datas, sigma = readings
    empty = type(datas[0])([])
    for name in ("paper", "extended"):
        out = get_estimator(name, sigma=sigma, verify=False).fit_many([datas[0], empty])
        assert isinstance(out[0], Estimate) and isinstance(out[1], ValueError)


def test_the_earlier_call_forms_give_the_same_estimates(readings) -> None:
    """``get_strategy(NAME).estimate(data, params, sigma, **options)`` and the
    catalogue's functions of ``calibrators.experiment`` still work, to the bit."""
    from calibrators.experiment import ESTIMATORS, estimate, estimate_many, make_estimator

    data, sigma = readings[0][0], readings[1]
    new = GaussNewtonCalibrator(params="extended", sigma=sigma, verify=False).fit(data)
    old = get_strategy("gauss-newton").estimate(data, "extended", sigma, verify=False)
    np.testing.assert_array_equal(new.theta, old.theta)
    assert isinstance(get_strategy("paper"), Estimator)
    assert ESTIMATORS is CATALOGUE
    np.testing.assert_array_equal(estimate(data, "extended", sigma).theta, new.theta)
    np.testing.assert_array_equal(estimate_many([data], "extended", sigma)[0].theta,
                                  new.theta)
    assert callable(make_estimator("paper6"))
    with pytest.raises(ValueError, match="unknown estimator"):
        make_estimator("oracle")


def test_estimator_and_strategy_name_one_estimator(tmp_path, capsys) -> None:
    """``--strategy paper`` is ``--estimator paper``, ``--strategy gauss-newton`` is
    ``--estimator full``: the same JSON to the byte."""
    machine = tmp_path / "m.json"
    machine.write_text(json.dumps({"drho": [0.5, -0.3, 0.2], "dL": [0.1, 0.2, -0.4]}))
    base = ["calibrate", "--machine", str(machine), "--backend", "exact", "--conditions",
            "ideal", "--json"]
    outputs = []
    for words in (["--strategy", "paper"], ["--estimator", "paper"],
                  ["--strategy", "gauss-newton", "--params", "paper6"],
                  ["--estimator", "full", "--params", "paper6"]):
        assert main([*base, *words]) == 0
        outputs.append(capsys.readouterr().out)
    assert outputs[0] == outputs[1] and outputs[2] == outputs[3]
    assert json.loads(outputs[0])["strategy"] == "paper"
    assert json.loads(outputs[2])["strategy"] == "gauss-newton"
