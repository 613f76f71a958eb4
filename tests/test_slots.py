"""Carriage and platform slots: names, both backends, the reading model, the estimator, the
lab's overtravel rules and the random agent's safety."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.base import action
from calibrators.estimators.differences import differences, paper_matrix
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator, layout_and_values
from calibrators.measurements import Measurement, Measurements
from orthoglide_env.instruments.dial import exact_readings, pressed_past_travel, status_of
from orthoglide_env.instruments.rays import exact_ray_distances, exact_target_boxes
from orthoglide_env.instruments.slots import GaugeSpec, Part, layout_from_names
from orthoglide_env.instruments.stands import (
    ideal_rays,
    install,
    installed_on,
    stand_errors,
    stand_rays,
)
from orthoglide_env.lab.operations import (
    PAPER_SLOTS,
    SLOT_NAMES,
    SLOTS,
    Op,
    slot_index,
)
from orthoglide_env.model.boxes import collision_boxes
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import ERROR_NAMES, PRESETS, MachineParams, random_machine
from orthoglide_env.model.kinematics import direct
from orthoglide_env.reading_model import parameters_of, predict

#: The slots this file is about: every carriage face and platform face of the catalogue.
NEW_SLOTS: tuple[GaugeSpec, ...] = tuple(s for s in SLOTS if s.part != Part.BAR)
#: The fidelity bar of the simulator (tests/test_machine.py): a tenth of a dial's step.
FIDELITY = 1e-3  # mm
TABLE1 = MachineParams(drho=[4.66, -5.36, 1.46], dL=[5.20, -5.96, 3.16])
LAB = orthoglide_env.LAB_ENV_ID


def test_the_catalogue_appends_carriages_and_platform_faces_to_the_bars() -> None:
    bars = [GaugeSpec(leg, axis, at) for leg in range(3) for axis in range(3) if axis != leg
            for at in PROTOTYPE.slot_positions]
    assert list(SLOTS[:len(bars)]) == bars  # the bar slots keep their indices
    assert PAPER_SLOTS == (2, 7, 12, 17, 22, 27)
    assert SLOT_NAMES[len(bars):] == (
        "x-carriage/y", "x-carriage/z", "y-carriage/x", "y-carriage/z", "z-carriage/x",
        "z-carriage/y", "platform/x", "platform/y", "platform/z")
    for k, (name, spec) in enumerate(zip(SLOT_NAMES, SLOTS, strict=True)):
        assert slot_index(name, design=PROTOTYPE) == slot_index(spec, design=PROTOTYPE) == k
        assert layout_from_names([name]) == (spec,)
    with pytest.raises(ValueError, match="carriages with an axis across their drive"):
        slot_index("x-carriage/x", design=PROTOTYPE)
    for bad in ("x-carriage/x", "platform/w", "x-carriage/y@0.5", "platform/x@0.5", "w-carriage/y",
                "platform-leg/x"):
        with pytest.raises(ValueError):
            layout_from_names([bad])
    with pytest.raises(ValueError, match="one place per face"):
        GaugeSpec(0, 1, 0.3, Part.CARRIAGE)
    with pytest.raises(ValueError, match="no leg"):
        GaugeSpec(0, 1, part=Part.PLATFORM)
    env = gym.make(LAB)
    assert env.action_space["slot"].n == len(SLOTS) == 39
    flat = gym.make(orthoglide_env.FLAT_LAB_ENV_ID)
    assert flat.unwrapped.action_space["slot"].n == len(SLOTS)


def installed(machine: MachineParams, seed: int, preset: str = "realistic") -> list:
    """Every carriage and platform gauge on ``machine``, stands installed with the preset's
    errors, zeroed at Zero."""
    return installed_on(machine, install(NEW_SLOTS, machine, preset=PRESETS[preset],
                                         rng=np.random.default_rng(seed)))


@pytest.mark.parametrize("seed", [1, 2])
def test_pybullet_reads_carriages_and_platform_as_the_exact_model(seed: int) -> None:
    """The simulator's ray on the carriage and platform links gives the exact model's
    distances within the fidelity bar, the same status everywhere (valid, off the face,
    pressed past travel) and the same pressed-past-travel flags."""
    machine_module = pytest.importorskip("orthoglide_env.sim.pybullet")
    rng = np.random.default_rng(seed)
    machine = random_machine(rng, "realistic", design=PROTOTYPE)
    gauges = installed(machine, seed)
    sim = machine_module.OrthoglideMachine(machine, gauges)
    try:
        t0_sim, t0_exact = sim.gauge_distances(), exact_ray_distances(machine, gauges, np.zeros(3))
        # Small moves (every platform gauge in contact), moves off the faces and across
        # the joint cube.
        postures = np.vstack([rng.uniform(-4, 4, (5, 3)), rng.uniform(-40, 40, (4, 3)),
                              rng.uniform(-100, 60, (3, 3))])
        valid = 0
        for rho in postures:
            sim.move(rho)
            t_sim, t_exact = sim.gauge_distances(), exact_ray_distances(machine, gauges, rho)
            np.testing.assert_array_equal(status_of(gauges, t_sim), status_of(gauges, t_exact))
            ok = np.isfinite(t_sim)
            valid += ok.sum()
            np.testing.assert_allclose((t_sim - t0_sim)[ok], (t_exact - t0_exact)[ok],
                                       rtol=0, atol=FIDELITY)
            boxes = collision_boxes(machine, rho, direct(machine, rho))
            np.testing.assert_array_equal(
                pressed_past_travel(gauges, *sim.target_boxes()),
                pressed_past_travel(gauges, *exact_target_boxes(gauges, boxes)))
        assert valid >= 5 * len(NEW_SLOTS)  # the comparison is about real readings
    finally:
        sim.close()


def test_the_reading_model_is_the_exact_gauge_on_carriages_and_platform() -> None:
    """Stand errors invert the installed rays exactly, and the estimators' model readings
    (predict at the true parameters) are the exact backend's readings on every valid one:
    1e-9 mm is round-off on positions of ~300 mm."""
    machine = random_machine(5, design=PROTOTYPE)
    gauges = installed(machine, 3)
    origins, directions = ideal_rays(NEW_SLOTS, machine)
    true_origins = np.array([g.origin for g in gauges])
    true_directions = np.array([g.direction for g in gauges])
    stand = stand_errors(NEW_SLOTS, true_origins, true_directions, origins, directions)
    assert np.abs(stand[:, :2]).max() > 0.05  # the stands do carry installation errors
    o, d = stand_rays(NEW_SLOTS, origins, directions, stand)
    np.testing.assert_allclose(d, true_directions, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.cross(o - true_origins, true_directions), 0, atol=1e-12)

    rho = np.vstack([np.zeros(3), np.random.default_rng(0).uniform(-4, 4, (20, 3)),
                     [[30.0, 0.0, 0.0], [0.0, -30.0, 0.0], [0.0, 0.0, 30.0]]])
    readings = exact_readings(machine, gauges, rho)
    assert np.isfinite(readings[0]).all()
    assert np.isfinite(readings).sum() >= 20 * len(NEW_SLOTS)
    posture, gauge = np.nonzero(np.isfinite(readings))
    data = Measurements([Measurement(NEW_SLOTS[g], "", 1, readings[p, g], tuple(rho[p]))
                         for p, g in zip(posture, gauge, strict=True)])
    design, values = layout_and_values(data)
    model = predict(parameters_of(design, machine, gauges), design)
    zero = {m: model[k] - values[k] for k, m in enumerate(design.mounting)
            if not np.any(design.rho[k])}
    gap = model - values - np.array([zero[m] for m in design.mounting])
    assert np.abs(gap).max() < 1e-9


def noise_free_fit(machine: MachineParams, specs: tuple[GaugeSpec, ...], rho: np.ndarray,
                   params: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Ideal gauges at ``specs`` read ``machine`` at Zero and ``rho``; the exact estimator
    fits ``params`` with no prior.  Returns the estimate, the truth and the names fitted."""
    gauges = installed_on(machine, install(specs, machine))
    postures = np.vstack([np.zeros(3), rho])
    readings = exact_readings(machine, gauges, postures)
    posture, gauge = np.nonzero(np.isfinite(readings))
    data = Measurements([Measurement(specs[g], "", 1, readings[p, g], tuple(postures[p]))
                         for p, g in zip(posture, gauge, strict=True)])
    est = GaussNewtonCalibrator(params=params, sigma=0.0, prior="none", verify=False).fit(data)
    assert not est.warnings
    return est.theta[:len(ERROR_NAMES)], machine.to_vector(), est.names


def test_carriage_gauges_alone_see_the_actuator_tilts() -> None:
    """A carriage gauge reads its guideway's sideways run and nothing else: on a machine
    with all 27 errors, the six carriage slots and strokes of +-30 mm give the six tilts
    exactly though the fit holds the other 21 errors at zero.  Newton on an exact model
    converges to round-off; 1e-9 rad moves a reading by 3e-8 mm over the strokes."""
    machine = random_machine(7, "realistic", design=PROTOTYPE)
    carriages = tuple(s for s in NEW_SLOTS if s.part == Part.CARRIAGE)
    strokes = np.outer([-30.0, -15.0, 15.0, 30.0], np.ones(3))
    estimate, truth, names = noise_free_fit(machine, carriages, strokes, "axis_tilt")
    tilts = [ERROR_NAMES.index(n) for n in names]
    assert len(tilts) == 6 and np.abs(truth[tilts]).min() > 1e-5
    assert np.abs(estimate[tilts] - truth[tilts]).max() < 1e-9


def test_platform_gauges_alone_recover_the_papers_parameters() -> None:
    """The platform's displacement under small moves is the machine's Jacobian near Zero
    and its curvature: with ideal gauges on the three platform faces, moves within the
    travel toward each stand and sideways along the faces, the exact estimator recovers
    the noise-free Table 1 machine.  1e-6 mm, the bar of the paper experiment's recovery
    (tests/test_estimator.py)."""
    platform = tuple(s for s in NEW_SLOTS if s.part == Part.PLATFORM)
    grid = np.stack(np.meshgrid(*[[-4.0, 0.0, 4.0]] * 3, indexing="ij"), -1).reshape(-1, 3)
    sideways = np.vstack([np.diag([s] * 3) for s in (-15.0, 15.0, 30.0)])
    estimate, truth, _ = noise_free_fit(TABLE1, platform, np.vstack([grid[1:], sideways]),
                                        "paper6")
    assert np.abs(estimate[:6] - truth[:6]).max() < 1e-6


@pytest.mark.parametrize("backend", ["exact", "pybullet"])
def test_a_platform_gauge_faults_past_its_travel_and_a_lifted_one_never(backend: str) -> None:
    """A platform gauge allows moves within its travel toward its stand; one more is an
    overtravel (a fault, 120 s); lifted it lets the platform move anywhere, and engaged
    again at Zero it reads its old zero.  Moving away from the stand only lifts the tip
    off the face."""
    # The textbook world: the tip's travel is the platform's, with no give or creep.
    env = gym.make(LAB, backend=backend, stands=1, gauge_sigma=0.0, gauge_resolution=0.0,
                   conditions="ideal")
    env.reset(seed=4)
    here = slot_index("platform/x", design=PROTOTYPE)

    def step(op: Op, rho: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> tuple:
        obs, _, _, _, info = env.step(action(op, np.array(rho), stand=0, slot=here))
        assert not info["refused"] and not info["collision"]
        return obs, info

    obs, info = step(Op.REMOUNT)
    assert obs["valid"][0] == 1 and abs(obs["gauges"][0]) < FIDELITY
    rho = np.array([-3.0, 0.0, 0.0])
    obs, info = step(Op.MOVE, tuple(rho))
    lab = env.unwrapped
    expected = exact_readings(lab.true_machine, lab.true_gauges[-1:], rho)[0]
    assert obs["valid"][0] == 1 and abs(obs["gauges"][0] - expected) < FIDELITY
    # The platform's displacement along x, to second order in the stand's tilt (5 mrad
    # sigma: 1e-4 relative at 3 sigma).
    moved = direct(lab.true_machine, rho)[0] - direct(lab.true_machine, np.zeros(3))[0]
    assert abs(obs["gauges"][0] - moved) < 1e-3
    obs, info = step(Op.MOVE, (20.0, 0.0, 0.0))
    assert obs["valid"][0] == 0 and info["overtravel"] == []
    obs, info = step(Op.MOVE, (-6.0, 0.0, 0.0))
    assert len(info["overtravel"]) == 1 and obs["engaged"][0] == 0
    assert info["step_time_s"] == pytest.approx(26 / 20 + 5 + 120)
    step(Op.REMOUNT)
    step(Op.LIFT)
    for rho in ((-20.0, 0.0, 0.0), (-60.0, -60.0, -60.0), (0.0, 0.0, 0.0)):
        obs, info = step(Op.MOVE, rho)
        assert info["overtravel"] == [] and obs["valid"][0] == 0
    obs, info = step(Op.ENGAGE)
    assert info["overtravel"] == []
    obs, info = step(Op.MOVE)
    assert obs["valid"][0] == 1 and abs(obs["gauges"][0]) < FIDELITY
    env.close()


def test_random_agent_uses_the_new_slots_and_never_presses_a_gauge() -> None:
    """The random agent keeps every engaged gauge, platform gauges included, clear of its
    travel's end with the nominal model alone, over an hour of random operations."""
    env = gym.make(LAB, backend="exact", gauge_sigma=0.01)
    agent = get_agent("random")
    obs, info = env.reset(seed=2)
    agent.reset(env, obs, np.random.default_rng(2))
    faults, done = [], False
    while not done:
        obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
        faults += info["overtravel"]
        done = terminated or truncated
    assert faults == [] and not info["collision"]
    parts = {r.spec.part for r in env.unwrapped.records}
    # Readings were taken on bars, carriages and the platform (a lab without the gauge
    # block has no reference slot).
    assert parts == {Part.BAR, Part.CARRIAGE, Part.PLATFORM}


def test_the_paper_estimator_has_no_row_for_the_new_gauges() -> None:
    """Eq. (10) holds rows for bar gauges only: a platform gauge read at a Z posture (which a
    leg index of -1 would have matched) is refused by name."""
    gauge = GaugeSpec.platform(2)
    data = Measurements([Measurement(gauge, "Zero", 1, 0.0), Measurement(gauge, "ZMax", 1, 0.1)])
    with pytest.raises(ValueError, match="no row for gauge platform/z"):
        paper_matrix(differences(data))
