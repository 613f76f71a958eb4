"""One PyBullet client hosts one machine after another: a machine built in a reused client
reads what it reads in a new one, and an env's resets neither open clients nor pile up
bodies and constraints."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pybullet as pb
import pytest

import orthoglide_env
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import PRESETS, random_machine
from orthoglide_env.sim.pybullet import OrthoglideMachine
from orthoglide_env.sim.simulator import PhysicsSettings, Simulator

#: A client that kept anything of an earlier machine (warm-started constraint impulses,
#: contacts) would show at the solver's residue after its two steps, ~1e-8 mm (the loop
#: residual of the fidelity benchmark); 1e-9 mm sits below that.
SAME = 1e-9  # mm
#: The machine's body, and the body holding the gauge stands once a picture was taken;
#: three point-to-point and two fixed loop closures.
BODIES = 1
DRAWN = 2
CONSTRAINTS = 5


def machine_and_gauges(seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    machine = random_machine(rng, "realistic", design=PROTOTYPE)
    gauges = install(PAPER_LAYOUT, machine, preset=PRESETS["realistic"], rng=rng)
    return machine, installed_on(machine, gauges)


def readings(sim: OrthoglideMachine, postures: np.ndarray, mode: str) -> np.ndarray:
    """Gauge distances, TCP and encoders at each posture in turn, one row each."""
    rows = []
    for rho in postures:
        sim.move(rho, mode)
        rows.append(np.concatenate([sim.gauge_distances(), sim.tcp(), sim.encoders()]))
    return np.array(rows)


@pytest.mark.parametrize("mode", ["quasi-static", "dynamic"])
def test_a_reused_client_reads_what_a_new_one_reads(mode: str) -> None:
    rng = np.random.default_rng(5)
    postures = np.vstack([rng.uniform(-15, 15, (3, 3)),
                          rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (2, 3))])
    shared = Simulator()
    try:
        for seed in range(4):  # each machine replaces the one before in the shared client
            machine, gauges = machine_and_gauges(seed)
            fresh = OrthoglideMachine(machine, gauges)
            try:
                expected = readings(fresh, postures, mode)
            finally:
                fresh.close()
            got = readings(OrthoglideMachine(machine, gauges, sim=shared), postures, mode)
            np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
            np.testing.assert_allclose(got, expected, rtol=0, atol=SAME)
            assert np.isfinite(expected).sum() > 20  # gauges read, not only NaN
            assert shared.client.getNumBodies() == BODIES
            assert shared.client.getNumConstraints() == CONSTRAINTS
    finally:
        shared.close()


def test_clearing_keeps_the_solver_settings() -> None:
    settings = PhysicsSettings(gravity=-3.0)
    sim = Simulator(settings=settings)
    try:
        sim.clear()
        params = sim.client.getPhysicsEngineParameters()
        assert params["fixedTimeStep"] == settings.time_step
        assert params["numSolverIterations"] == settings.solver_iterations
        assert params["gravityAccelerationZ"] == settings.gravity
        assert sim.generation == 1
    finally:
        sim.close()


def test_a_replaced_machine_is_built_again_where_it_was() -> None:
    shared = Simulator()
    try:
        first = OrthoglideMachine(*machine_and_gauges(1), sim=shared)
        rho = np.array([12.0, -30.0, 5.0])
        first.move(rho)
        before = np.concatenate([first.gauge_distances(), first.tcp()])
        OrthoglideMachine(*machine_and_gauges(2), sim=shared)
        assert not first.in_client
        first.rebuild()
        assert first.in_client
        np.testing.assert_array_equal(np.concatenate([first.gauge_distances(), first.tcp()]),
                                      before)
        assert shared.client.getNumBodies() == BODIES
    finally:
        shared.close()


def test_a_machine_in_a_given_client_takes_its_settings() -> None:
    shared = Simulator()
    try:
        with pytest.raises(ValueError, match="settings"):
            OrthoglideMachine(*machine_and_gauges(1), sim=shared, gravity=False)
    finally:
        shared.close()


def _connected_clients() -> int:
    return sum(pb.getConnectionInfo(c)["isConnected"] for c in range(64))


def test_stands_are_drawn_for_pictures_only_and_once() -> None:
    sim = OrthoglideMachine(*machine_and_gauges(3))
    try:
        assert sim.bc.getNumBodies() == BODIES
        sim.render(64, 48)
        assert sim.bc.getNumBodies() == DRAWN
        sim.set_gauges(sim.gauges)  # redrawn in place of the old ones
        sim.render(64, 48)
        assert sim.bc.getNumBodies() == DRAWN
    finally:
        sim.close()


@pytest.mark.slow
def test_an_env_keeps_one_client_over_200_resets() -> None:
    base = _connected_clients()
    env = gym.make(orthoglide_env.ENV_ID, backend="pybullet", render_mode="rgb_array")
    try:
        env.reset(seed=0)
        client = env.unwrapped._batch.backend.sim.client
        for seed in range(1, 201):
            env.reset(seed=seed)
            if seed % 7 == 0:
                env.step(np.array([5.0, -3.0, 2.0]))
            if seed % 10 == 0:
                env.render()
            assert env.unwrapped._batch.backend.sim.client is client
            assert client.getNumBodies() == (DRAWN if seed % 10 == 0 else BODIES)
            assert client.getNumConstraints() == CONSTRAINTS
        assert _connected_clients() == base + 1
    finally:
        env.close()
    assert _connected_clients() == base
