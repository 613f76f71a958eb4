"""The exact backend's collision check: the separating-axis test against a linear
program, the joint cube's clearance, and agreement with the simulator's contact check."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog, minimize
from scipy.spatial.transform import Rotation

from orthoglide_env.model.boxes import BOX_NAMES, collision_boxes
from orthoglide_env.model.collisions import (
    PAIR_NAMES,
    box_gap,
    clearance,
    collisions,
    pair_gaps,
)
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.model.kinematics import direct

#: x-leg's R2 moved 8 mm toward the y axis: clear at Zero (2.5 mm), crashed at (60, 60, 60).
CRASHING = MachineParams(attach=[[-8.0, 8.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
#: PyBullet rounds box edges by its collision margin (exact again 1 mm from an edge, see
#: gauges.TIP_EDGE_MARGIN): near-edge contacts may differ by up to that much.
EDGE_ROUNDING = 1.0


def boxes_intersect(a: tuple, b: tuple) -> bool:
    """Oracle: a point inside both boxes exists (linear feasibility)."""
    rows, bounds = [], []
    for centre, rot, half in (a, b):
        # |rot^T (x - centre)| <= half, as two one-sided inequalities.
        rows += [rot.T, -rot.T]
        bounds += [half + rot.T @ centre, half - rot.T @ centre]
    result = linprog(np.zeros(3), A_ub=np.vstack(rows), b_ub=np.concatenate(bounds),
                     bounds=[(None, None)] * 3, method="highs")
    return result.status == 0


def test_gap_is_the_distance_between_face_separated_boxes() -> None:
    eye, half = np.eye(3), np.ones(3)
    assert box_gap(np.zeros(3), eye, half, np.array([2.5, 0.3, 0.0]), eye, half) == (
        pytest.approx(0.5)
    )
    assert box_gap(np.zeros(3), eye, half, np.array([1.5, 0.0, 0.0]), eye, half) < 0


def test_gap_sees_an_edge_to_edge_separation() -> None:
    # Two long bars, each turned 45° about its own length, crossed at right angles one
    # above the other: no face normal separates them, the cross product of their lengths
    # (world z) does, and along it each reaches sqrt(2).
    half = np.array([50.0, 1.0, 1.0])
    turned = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    tilt = Rotation.from_euler("x", 45, degrees=True).as_matrix()
    gap = box_gap(np.zeros(3), tilt, half, np.array([0.0, 0.0, 2.0]), turned @ tilt, half)
    assert gap == pytest.approx(2.0 - 2 * np.sqrt(2), abs=1e-12)  # overlapping corners
    gap = box_gap(np.zeros(3), tilt, half, np.array([0.0, 0.0, 3.0]), turned @ tilt, half)
    assert gap == pytest.approx(3.0 - 2 * np.sqrt(2), abs=1e-12)


def test_gap_sign_agrees_with_a_linear_program_on_random_boxes() -> None:
    rng = np.random.default_rng(0)
    for _ in range(400):
        a = (rng.normal(0, 1, 3), Rotation.random(random_state=rng).as_matrix(),
             rng.uniform(0.1, 2, 3))
        b = (rng.normal(0, 1, 3) * 3, Rotation.random(random_state=rng).as_matrix(),
             rng.uniform(0.1, 2, 3))
        gap = box_gap(*a, *b)
        if abs(gap) > 1e-9:  # exact touching is decided by round-off in both
            assert (gap <= 0) == boxes_intersect(a, b), gap


def test_pairs_are_named_as_in_the_simulator() -> None:
    machine_module = pytest.importorskip("orthoglide_env.sim.pybullet")
    sim = machine_module.OrthoglideMachine(MachineParams(), [])
    try:
        assert [name for *_, name in sim._pairs] == list(PAIR_NAMES)
        rho = np.array([30.0, -70.0, 10.0])
        sim.move(rho)
        centre, rot, _ = collision_boxes(MachineParams(), rho, direct(MachineParams(), rho))
        for leg in "xyz":
            k = BOX_NAMES.index(f"{leg}_carriage")
            pos, frame = sim._link_pose(f"{leg}_carriage")
            np.testing.assert_allclose(pos + frame @ [45.0, 0.0, 0.0], centre[k], atol=1e-6)
            np.testing.assert_allclose(frame, rot[k], atol=1e-9)
    finally:
        sim.close()


def worst_posture(machine: MachineParams, points: int) -> tuple[float, np.ndarray]:
    """Smallest clearance over the joint cube: a grid, then a local search from its worst
    nodes (the clearance is piecewise smooth, so the grid alone could step over a dip)."""
    axis = np.linspace(PROTOTYPE.rho_min, PROTOTYPE.rho_max, points)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    values = clearance(machine, grid)
    best, where = np.inf, grid[0]
    for start in grid[np.argsort(values)[:4]]:
        result = minimize(lambda r: float(clearance(machine, r)), start, method="Powell",
                          bounds=[(PROTOTYPE.rho_min, PROTOTYPE.rho_max)] * 3)
        if result.fun < best:
            best, where = float(result.fun), result.x
    return best, where


@pytest.mark.parametrize("machine", [MachineParams(), *(
    random_machine(s, "realistic", design=PROTOTYPE) for s in range(3))])
def test_no_crash_is_possible_within_the_joint_limits(machine: MachineParams) -> None:
    # Measured: the couplers come closest, ~6.1 mm apart on the nominal machine and
    # ~5.5-6 mm on realistic ones, at a corner of the cube with two joints at -100 mm.
    best, where = worst_posture(machine, 11)
    assert best > 4.0, (best, where)


def test_a_machine_far_from_nominal_crashes_its_couplers() -> None:
    assert clearance(CRASHING, np.zeros(3)) > 2.0
    assert collisions(CRASHING, np.full(3, PROTOTYPE.rho_max)) == ["x_coupler/y_coupler",
                                                          "x_coupler/z_coupler"]


@pytest.mark.parametrize("machine", [CRASHING, random_machine(4, "realistic", design=PROTOTYPE)])
def test_agrees_with_the_simulators_contact_check(machine: MachineParams) -> None:
    machine_module = pytest.importorskip("orthoglide_env.sim.pybullet")
    axis = np.linspace(PROTOTYPE.rho_min, PROTOTYPE.rho_max, 5)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    gaps = pair_gaps(machine, grid)
    sim = machine_module.OrthoglideMachine(machine, [])
    crashes = 0
    try:
        for rho, gap in zip(grid, gaps, strict=True):
            sim.move(rho)
            seen = set(sim.collisions())
            names = np.array(PAIR_NAMES)
            assert set(names[gap <= -EDGE_ROUNDING]) <= seen, rho
            assert seen <= set(names[gap <= EDGE_ROUNDING]), rho
            crashes += bool(seen)
    finally:
        sim.close()
    assert crashes > 10 if machine is CRASHING else crashes == 0
