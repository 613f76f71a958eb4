"""Identifiability of a design: eq. (10)'s singular values, the Cramér-Rao bound of the
paper's procedure, and the weak drho ~ dL directions."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_experiment
from conftest import paper_matrix as eq10

from calibrators.estimators.differences import differences
from calibrators.estimators.identifiability import analyse, of_design
from calibrators.measurements import Measurement, Measurements
from orthoglide_env.instruments.slots import PAPER_LAYOUT


@pytest.fixture(scope="module")
def paper_design() -> Measurements:
    """The paper's readings on a nominal machine with ideal gauges (values do not matter
    to identifiability, only where and how often the gauges are read)."""
    episode, _ = paper_experiment(errors="nominal", gauge_sigma=0.0, gauge_resolution=0.0)
    return episode.measurements


def test_eq10_singular_values_and_condition() -> None:
    ident = analyse(eq10(), np.eye(12), 1.0)
    # docs/estimators.md's values, printed to 3 significant digits.
    np.testing.assert_allclose(ident.singular_values,
                               [1.01, 0.683, 0.683, 0.0166, 0.0164, 0.0164], rtol=5e-3)
    assert ident.condition_number == pytest.approx(61.9, abs=0.1)


def test_exact_model_design_has_eq10_singular_values(paper_design) -> None:
    # Finite differences of the exact model at the nominal machine are eq. (10)'s matrix
    # to ~1e-7 (truncation of a 1e-4 mm step), so the singular values agree to that level.
    ident = of_design(paper_design, "paper6", 1.0)
    np.testing.assert_allclose(ident.singular_values, np.linalg.svd(eq10(), compute_uv=False),
                               rtol=1e-5)


def test_crlb_is_43_sigma_for_independent_differences() -> None:
    """docs/estimators.md: twelve independent differences of noise sigma bound every parameter's
    standard deviation at about 43 sigma."""
    ident = analyse(eq10(), np.eye(12), 0.01)
    np.testing.assert_allclose(ident.crlb / 0.01, 43.0, rtol=0.02)


def test_crlb_of_the_averaged_differences(paper_design) -> None:
    """The paper's procedure in the lab reads Max and Min 3 times and Zero 5 times per
    gauge (the lab reads every gauge as the episode opens, then at the leg's 4 Zero
    visits), so each difference has variance sigma^2 (1/3 + 1/5) and the Max and Min
    differences of one gauge share the Zero mean (covariance sigma^2 / 5).  The bound is
    computed here from that covariance, built by hand, and is 36.1 sigma: better than 43
    sigma per single reading because of the averaging, worse than 43 * sqrt(8/15) = 31.4
    sigma because the shared Zero mean is not independent noise."""
    sigma = 0.01
    rows = differences(paper_design)
    assert len(rows) == 12
    block = np.array([[1 / 3 + 1 / 5, 1 / 5], [1 / 5, 1 / 3 + 1 / 5]])
    cov = np.zeros((12, 12))
    for g in set(rows.gauges):
        idx = [k for k, h in enumerate(rows.gauges) if h == g]
        cov[np.ix_(idx, idx)] = block
    np.testing.assert_allclose(rows.cov_unit, cov, atol=1e-15)
    ident = of_design(paper_design, "paper6", sigma)
    np.testing.assert_allclose(ident.crlb / sigma, 36.1, rtol=0.01)
    assert np.all(ident.crlb / sigma > 43 * np.sqrt(8 / 15))


def test_fisher_information_scales_with_repetitions(paper_design) -> None:
    # Twice the readings of every posture: the Fisher information doubles exactly and
    # the bound shrinks by sqrt(2).
    doubled = Measurements(paper_design.items + [
        Measurement(m.gauge, m.posture, m.repetition + 10, m.reading)
        for m in paper_design.items
    ])
    one, two = of_design(paper_design, "paper6", 0.01), of_design(doubled, "paper6", 0.01)
    np.testing.assert_allclose(two.fisher, 2 * one.fisher, rtol=1e-9)
    np.testing.assert_allclose(two.crlb, one.crlb / np.sqrt(2), rtol=1e-9)


def test_weak_directions_are_drho_and_dl_together(paper_design) -> None:
    ident = of_design(paper_design, "paper6", 0.01)
    assert len(ident.weak_directions) == 3
    for weak in ident.weak_directions:
        for axis in "xyz":
            # drho_i and dL_i move together: at Zero a gauge sees only drho_i - dL_i.
            assert weak.get(f"drho_{axis}", 0.0) == pytest.approx(weak.get(f"dL_{axis}", 0.0),
                                                                 abs=0.02)


@pytest.mark.parametrize("params", ["drho", "dL"])
def test_reduced_sets_are_well_conditioned(paper_design, params: str) -> None:
    # Without its partner, either half of the parameters is seen directly.
    ident = of_design(paper_design, params, 0.01)
    assert ident.condition_number < 2
    assert not ident.weak_directions
    assert np.all(ident.crlb < 0.03)


def test_a_design_of_custom_postures() -> None:
    """Any strategy's readings: here a design that reads the x leg's gauges at two postures
    of its own (not paper postures) is analysed through the exact model."""
    postures = {"probe-1": (20.0, -5.0, -5.0), "probe-2": (-60.0, -10.0, 5.0)}
    items = []
    for spec in PAPER_LAYOUT[:2]:
        for rep in (1, 2):
            items.append(Measurement(spec, "Zero", rep, 0.0))
            items += [Measurement(spec, name, rep, 0.0, rho) for name, rho in postures.items()]
    ident = of_design(Measurements(items), "drho", 0.01)
    assert ident.fisher.shape == (3, 3) and np.all(np.isfinite(ident.crlb))
    # Four differences cannot identify six parameters.
    with pytest.raises(ValueError, match="4 differences for 6 parameters"):
        of_design(Measurements(items), "paper6", 0.01)


def test_a_design_the_gauges_cannot_see_is_an_error() -> None:
    # At "away" the x leg's bar has left the gauges' tips: no information, a clear error.
    postures = {"near": (20.0, -5.0, -5.0), "away": (30.0, -20.0, -20.0)}
    items = [Measurement(spec, "Zero", 1, 0.0) for spec in PAPER_LAYOUT[:2]]
    items += [Measurement(spec, name, 1, 0.0, rho) for spec in PAPER_LAYOUT[:2]
              for name, rho in postures.items()]
    with pytest.raises(ValueError, match="miss"):
        of_design(Measurements(items), "drho", 0.01)
