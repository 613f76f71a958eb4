"""Exact kinematics: identities, the paper's closed forms, and its Jacobian (eq. 5)."""

from __future__ import annotations

import numpy as np
import pytest

from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.model.kinematics import (
    ERROR_LEGS,
    UnreachableError,
    axis_postures,
    carriage_points,
    check_reachable,
    cross,
    direct,
    direct_paper,
    divided,
    inverse,
    inverse_paper,
    jacobian_paper,
    leg_angles,
    leg_vectors,
    paper_posture,
    platform_points,
    scaled,
    sensitivity_along,
)

# Round-off on ~300 mm quantities is ~1e-13 mm; the Newton solver stops at 1e-11 mm.
EXACT = 1e-9


def _bits(x: np.ndarray) -> np.ndarray:
    """The numbers' bit patterns (as integers), so -0.0 and 0.0 or two NaNs differ."""
    return np.ascontiguousarray(x, dtype=float).view(np.int64)


@pytest.mark.parametrize(("vectors", "scalars"), [((40, 7, 3), (40, 7)), ((7, 3), (40, 7)),
                                                  ((40, 7, 3), (7,)), ((40, 1, 3), (1, 5))])
def test_products_coordinate_by_coordinate_are_numpys_broadcast_ones(
        vectors: tuple[int, ...], scalars: tuple[int, ...]) -> None:
    # The geometry's (..., 3) by (...) products, written coordinate by coordinate, give
    # numpy's broadcast results to the bit, in its shape and C order, so that a model's
    # readings and derivatives keep their bits.
    rng = np.random.default_rng(3)
    v, s = rng.normal(size=vectors), rng.normal(size=scalars)
    s.flat[0] = 0.0  # a zero divisor: inf, -inf or NaN as numpy gives them
    with np.errstate(divide="ignore", invalid="ignore"):
        for ours, theirs in ((scaled(v, s), s[..., None] * v), (divided(v, s), v / s[..., None])):
            assert ours.shape == theirs.shape and ours.flags.c_contiguous
            np.testing.assert_array_equal(_bits(ours), _bits(theirs))
    w = rng.normal(size=vectors)
    np.testing.assert_array_equal(_bits(cross(v, w)), _bits(np.cross(v, w)))
    inv = rng.normal(size=(*vectors, 3))
    through = (v[..., 0, None] * inv[..., 0, :] + v[..., 1, None] * inv[..., 1, :]
               + v[..., 2, None] * inv[..., 2, :])
    row = rng.normal(size=(*vectors[:-1], 27))
    np.testing.assert_array_equal(_bits(sensitivity_along(inv, row, v)),
                                  _bits(np.take(through, ERROR_LEGS, axis=-1) * row))


@pytest.mark.parametrize("preset", ["paper", "realistic"])
def test_inverse_of_direct_is_identity(preset: str, joint_samples: np.ndarray) -> None:
    for seed in range(5):
        machine = random_machine(seed, preset, design=PROTOTYPE)
        p = direct(machine, joint_samples)
        np.testing.assert_allclose(inverse(machine, p), joint_samples, atol=EXACT, rtol=0)


def test_direct_closes_every_leg(joint_samples: np.ndarray) -> None:
    machine = random_machine(11, "realistic", design=PROTOTYPE)
    p = direct(machine, joint_samples)
    lengths = np.linalg.norm(leg_vectors(machine, joint_samples, p), axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(machine.leg_lengths, lengths.shape),
                               atol=EXACT, rtol=0)


def test_paper_closed_forms_match_general_model(joint_samples: np.ndarray) -> None:
    machine = random_machine(2, "paper", design=PROTOTYPE)
    p = direct_paper(joint_samples, machine.drho, machine.leg_lengths, PROTOTYPE.L)
    np.testing.assert_allclose(inverse(machine, p), joint_samples, atol=EXACT, rtol=0)
    np.testing.assert_allclose(inverse_paper(p, machine.drho, machine.leg_lengths, PROTOTYPE.L),
                               joint_samples, atol=EXACT, rtol=0)


def test_direct_paper_picks_the_assembly_mode_at_zero() -> None:
    # At Zero the quadratic's roots are t = 0 (this mode) and t = 2 L^2 / 3 (the other).
    np.testing.assert_allclose(direct_paper(np.zeros(3), np.zeros(3), np.full(3, PROTOTYPE.L),
                                            PROTOTYPE.L), 0.0, atol=1e-12)


def test_paper_postures_put_the_tcp_on_the_axes() -> None:
    nominal = MachineParams()
    alpha = np.arcsin(PROTOTYPE.rho_max / PROTOTYPE.L)
    np.testing.assert_allclose(direct(nominal, paper_posture("YMax", PROTOTYPE)),
                               [0, PROTOTYPE.L * np.sin(alpha), 0], atol=EXACT)
    np.testing.assert_allclose(direct(nominal, paper_posture("ZMin", PROTOTYPE)), [0, 0, -100],
                               atol=EXACT)
    with pytest.raises(ValueError, match="unknown posture"):
        paper_posture("WMax", PROTOTYPE)


def test_axis_postures_put_the_tcp_on_the_axes() -> None:
    """The TCP is on the leg's axis, at the leg's coordinate, from one limit to the other;
    the paper's Max and Min are the family's ends."""
    nominal = MachineParams()
    along = np.linspace(PROTOTYPE.rho_min, PROTOTYPE.rho_max, 9)
    for leg in range(3):
        expected = np.zeros((len(along), 3))
        expected[:, leg] = along
        np.testing.assert_allclose(direct(nominal, axis_postures(leg, along, PROTOTYPE)), expected,
                                   atol=EXACT)
        ends = axis_postures(leg, np.array([PROTOTYPE.rho_max, PROTOTYPE.rho_min]), PROTOTYPE)
        assert np.array_equal(ends, [paper_posture(f"{'XYZ'[leg]}{end}", PROTOTYPE)
                                     for end in ("Max", "Min")])


def test_zero_posture_follows_eq7() -> None:
    # Eq. (7): at Zero, dp_i = drho_i - dL_i to first order; the remainder is of order
    # |dp|^2 / L (the other coordinates shorten the leg's projection), bounded below.
    machine = MachineParams(drho=[1e-3, -2e-3, 3e-3], dL=[2e-3, 1e-3, -1e-3])
    dp = machine.drho - machine.dL
    second_order = 3 * np.max(np.abs(dp)) ** 2 / PROTOTYPE.L
    np.testing.assert_allclose(direct(machine, np.zeros(3)), dp, atol=second_order, rtol=0)


def test_jacobian_equals_finite_differences(joint_samples: np.ndarray) -> None:
    machine = random_machine(4, "paper", design=PROTOTYPE)
    rho = joint_samples[:50]
    p = direct(machine, rho)
    jac = jacobian_paper(p, rho, machine.drho, machine.leg_lengths, PROTOTYPE.L)
    h = 1e-4  # central differences: truncation ~h^2 * p''' ~ 1e-10 here
    fd = np.empty_like(jac)
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        plus = direct_paper(rho, machine.drho + step[:3], machine.leg_lengths + step[3:],
                            PROTOTYPE.L)
        minus = direct_paper(rho, machine.drho - step[:3], machine.leg_lengths - step[3:],
                             PROTOTYPE.L)
        fd[..., k] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(jac, fd, atol=1e-7, rtol=0)


def test_jacobian_at_zero_and_xmax_are_eq6_and_eq8() -> None:
    lengths = np.full(3, PROTOTYPE.L)
    j0 = jacobian_paper(np.zeros(3), np.zeros(3), np.zeros(3), lengths, PROTOTYPE.L)
    np.testing.assert_allclose(j0, np.hstack([np.eye(3), -np.eye(3)]), atol=1e-12)
    alpha = np.arcsin(PROTOTYPE.rho_max / PROTOTYPE.L)
    t, c = np.tan(alpha), np.cos(alpha)
    rho = paper_posture("XMax", PROTOTYPE)
    jx = jacobian_paper(direct_paper(rho, np.zeros(3), lengths, PROTOTYPE.L), rho, np.zeros(3),
                        lengths, PROTOTYPE.L)
    expected = np.array([[1, 0, 0, -1, 0, 0], [t, 1, 0, -t, -1 / c, 0], [t, 0, 1, -t, 0, -1 / c]])
    np.testing.assert_allclose(jx, expected, atol=1e-12)


def test_leg_angles_rebuild_the_leg_vectors(joint_samples: np.ndarray) -> None:
    from orthoglide_env.model.errors import R_LEG

    machine = random_machine(9, "realistic", design=PROTOTYPE)
    p = direct(machine, joint_samples)
    theta, beta = leg_angles(machine, joint_samples, p)
    local = -np.stack([np.cos(theta) * np.cos(beta), np.sin(theta) * np.cos(beta),
                       -np.sin(beta)], axis=-1) * machine.leg_lengths[:, None]
    np.testing.assert_allclose(np.einsum("lij,...lj->...li", R_LEG, local),
                               leg_vectors(machine, joint_samples, p), atol=EXACT)
    # Nominal Zero: every leg points straight at the platform.
    t0, b0 = leg_angles(MachineParams(), np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(np.concatenate([t0, b0]), 0.0, atol=1e-12)


def test_points_at_zero_are_nominal() -> None:
    nominal = MachineParams()
    np.testing.assert_allclose(carriage_points(nominal, np.zeros(3)),
                               (PROTOTYPE.L + 31.0) * np.eye(3))
    np.testing.assert_allclose(platform_points(nominal, np.zeros(3)), 31.0 * np.eye(3))


def test_unreachable_postures_raise_clear_errors() -> None:
    nominal = MachineParams()
    with pytest.raises(UnreachableError, match="out of reach"):
        inverse(nominal, np.array([0.0, 400.0, 0.0]))
    with pytest.raises(UnreachableError, match="control limits"):
        check_reachable(nominal, np.array([90.0, 0.0, 0.0]))
    with pytest.raises(UnreachableError, match="cannot be assembled"):
        direct(MachineParams(dL=[-250.0, -250.0, -250.0]), np.zeros(3))


def test_tcp_sensitivity_is_the_derivative_of_the_direct_kinematics() -> None:
    """The implicit-function derivative of the TCP over the 27 errors equals central
    differences of Newton-solved direct kinematics (step 1e-4 mm or rad: truncation
    ~(1e-4)^2 relative, round-off ~eps * 310 mm / 1e-4 ~ 1e-9), on a batch of two
    realistic machines at postures over the workspace."""
    from orthoglide_env.model.errors import get_preset
    from orthoglide_env.model.kinematics import tcp_sensitivity

    rng = np.random.default_rng(3)
    machines = MachineParams.stack([get_preset("realistic").sample(rng, PROTOTYPE)
                                    for _ in range(2)])
    rho = rng.uniform(-80.0, 40.0, (2, 20, 3))
    p = direct(machines, rho)
    jac = tcp_sensitivity(machines, rho, p)
    theta, h = machines.to_vector(), 1e-4
    for k in range(theta.shape[-1]):
        step = np.zeros(theta.shape[-1])
        step[k] = h
        plus = direct(MachineParams.from_vector(theta + step, PROTOTYPE), rho)
        minus = direct(MachineParams.from_vector(theta - step, PROTOTYPE), rho)
        assert np.allclose(jac[..., k], (plus - minus) / (2 * h), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("preset", ["paper", "realistic"])
def test_a_posture_alone_has_the_bits_it_has_in_a_batch(preset: str,
                                                        joint_samples: np.ndarray) -> None:
    # A single env's step solves one posture on Python floats, a batch on arrays in place:
    # the two forms must agree bit for bit, or a machine's readings would depend on how
    # many machines it is simulated with.
    machine = random_machine(7, preset, design=PROTOTYPE)
    together = direct(machine, joint_samples)
    for rho, tcp in zip(joint_samples, together, strict=True):
        assert np.array_equal(direct(machine, rho), tcp)
        assert np.array_equal(direct(machine, rho[None])[0], tcp)
