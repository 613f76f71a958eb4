"""The exact gauge model: the paper's eq. (10), the tool offset, ray geometry, noise."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import EQ10_ROWS, paper_matrix

from orthoglide_env.instruments.dial import GaugeNoise, Status, exact_readings, status_of
from orthoglide_env.instruments.rays import ray_box_distance
from orthoglide_env.instruments.slots import PAPER_LAYOUT, GaugeSpec, layout_from_names
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.model.kinematics import PAPER_POSTURES, paper_posture


def eq10_differences(theta: np.ndarray) -> np.ndarray:
    """The twelve gauge differences of eq. (10) for paper parameters ``theta``."""
    machine = MachineParams(drho=theta[:3], dL=theta[3:])
    gauges = installed_on(machine, install(PAPER_LAYOUT))
    return np.array([exact_readings(machine, gauges, paper_posture(p, PROTOTYPE))[k]
                     for p, k in EQ10_ROWS])


def test_finite_differences_reproduce_eq10() -> None:
    h = 1e-4  # central differences; the differences are smooth, truncation ~h^2/L ~ 1e-11
    jac = np.column_stack(
        [(eq10_differences(h * e) - eq10_differences(-h * e)) / (2 * h) for e in np.eye(6)]
    )
    np.testing.assert_allclose(jac, paper_matrix(), atol=1e-8, rtol=0)


def test_eq10_conditioning_matches_the_design_notes() -> None:
    sv = np.linalg.svd(paper_matrix(), compute_uv=False)
    np.testing.assert_allclose(sv, [1.0122, 0.6827, 0.6827, 0.01663, 0.01636, 0.01636], atol=5e-5)
    assert sv[0] / sv[-1] == pytest.approx(61.9, abs=0.1)


def test_nominal_machine_keeps_its_legs_parallel() -> None:
    nominal = MachineParams()
    gauges = installed_on(nominal, install(PAPER_LAYOUT))
    for posture in PAPER_POSTURES:
        readings = exact_readings(nominal, gauges, paper_posture(posture, PROTOTYPE))
        leg = "XYZ".find(posture[0])
        tested = [k for k, g in enumerate(gauges) if leg < 0 or g.spec.leg == leg]
        np.testing.assert_allclose(readings[tested], 0.0, atol=1e-9)


@pytest.mark.parametrize("tilted", [False, True])
def test_tool_offset_cancels_in_every_gauge_difference(tilted: bool) -> None:
    """r shifts leg i and its gauges along e_i, so it cancels, as the paper says.  A tilted
    actuator moves the carriage end along u_i instead: then r leaves an effect of order
    r * tilt, which the test shows is not negligible."""
    data = random_machine(6, "realistic", design=PROTOTYPE).to_dict()
    if not tilted:
        data["axis_tilt"] = np.zeros((3, 2)).tolist()
    machine = MachineParams.from_dict(data)
    # Small moves keep every tip on its bar; the paper postures add the large ones.
    small = np.random.default_rng(1).uniform(-6, 6, (50, 3))
    rho = np.vstack([small, [paper_posture(n, PROTOTYPE) for n in PAPER_POSTURES]])

    def differences(machine: MachineParams) -> np.ndarray:
        gauges = installed_on(machine, install(PAPER_LAYOUT, machine, travel=200.0))
        return exact_readings(machine, gauges, rho)

    with_r = differences(machine)
    without_r = differences(MachineParams.from_dict(data, MachineDesign.from_dict({"r": 0.0})))
    assert np.isfinite(with_r).sum() > 250  # the check is about real readings
    np.testing.assert_array_equal(np.isnan(with_r), np.isnan(without_r))
    gap = np.nanmax(np.abs(with_r - without_r))
    if tilted:
        assert gap > 1e-3
    else:
        assert gap < 1e-9


def test_ray_box_distance_on_a_known_box() -> None:
    centre, rot, half = np.zeros(3), np.eye(3), np.array([5.0, 1.0, 2.0])
    d = ray_box_distance(np.array([0.0, -10.0, 0.0]), np.array([0.0, 1.0, 0.0]), centre, rot, half)
    assert d == pytest.approx(9.0)
    # The box between tip and stand: the entry lies behind the origin (overtravel).
    d = ray_box_distance(np.array([0.0, 3.0, 0.0]), np.array([0.0, 1.0, 0.0]), centre, rot, half)
    assert d == pytest.approx(-4.0)
    # Parallel to a slab and outside it: a miss, not a hit at infinity.
    assert np.isnan(ray_box_distance(np.array([0.0, -10.0, 2.5]), np.array([0.0, 1.0, 0.0]),
                                     centre, rot, half))


def test_status_and_readings_respect_the_travel() -> None:
    gauges = install(PAPER_LAYOUT[:1])
    t = np.array([[-0.1], [0.0], [10.0], [10.1], [np.nan]])
    assert status_of(gauges, t).ravel().tolist() == [
        Status.OVERTRAVEL, Status.VALID, Status.VALID, Status.NO_CONTACT, Status.MISSED
    ]


def test_gauges_lose_contact_far_from_their_posture() -> None:
    machine = MachineParams()
    gauges = installed_on(machine, install(PAPER_LAYOUT))
    readings = exact_readings(machine, gauges, paper_posture("YMax", PROTOTYPE))
    # The x-leg follows the TCP 60 mm along y: its gauges cannot follow.
    assert np.isnan(readings[:2]).all() and np.isfinite(readings[2:4]).all()


def test_noise_and_quantisation() -> None:
    rng = np.random.default_rng(0)
    noise = GaugeNoise(sigma=0.02, resolution=0.01)
    out = noise.apply(np.full(20000, 0.1234), rng)
    np.testing.assert_allclose(out / 0.01, np.round(out / 0.01), atol=1e-9)
    # Standard error of a sample std over 2e4 draws is ~0.5%: 3% is generous.
    assert np.std(out) == pytest.approx(noise.effective_sigma, rel=0.03)
    assert np.isnan(noise.apply(np.array([np.nan]), rng)).all()
    np.testing.assert_array_equal(GaugeNoise(0, 0).apply(np.array([0.1234]), rng), [0.1234])
    with pytest.raises(ValueError):
        GaugeNoise(sigma=-1)


def test_layout_names() -> None:
    assert layout_from_names(["x-leg/y", "z/x@0.3"]) == (GaugeSpec(0, 1), GaugeSpec(2, 0, 0.3))
    assert [g.name for g in PAPER_LAYOUT] == [
        "x-leg/y", "x-leg/z", "y-leg/x", "y-leg/z", "z-leg/x", "z-leg/y"
    ]
    for bad in (["x-leg/x"], ["w/y"], ["x/y@0.99"]):
        with pytest.raises(ValueError):
            layout_from_names(bad)
