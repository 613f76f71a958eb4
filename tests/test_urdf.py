"""The URDF writer and the checked-in nominal URDF."""

from __future__ import annotations

import pybullet as pb

from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.sim.simulator import Simulator
from orthoglide_env.sim.urdf import LINKS_PER_LEG, MM, link_name, nominal_urdf_path, write_urdf


def test_checked_in_urdf_is_current() -> None:
    assert nominal_urdf_path().read_text() == write_urdf(MachineParams()), (
        "urdf/orthoglide.urdf is stale: run `python -m orthoglide_env.sim.urdf`"
    )


def test_urdf_loads_with_the_expected_tree() -> None:
    sim = Simulator()
    try:
        body = sim.load_urdf_text(write_urdf(random_machine(1, "realistic", design=PROTOTYPE)))
        info = [sim.client.getJointInfo(body, j) for j in range(sim.client.getNumJoints(body))]
    finally:
        sim.close()
    links = {i[12].decode(): i for i in info}
    expected = {link_name(leg, part) for leg in range(3) for part in LINKS_PER_LEG} | {"platform"}
    assert set(links) == expected
    kinds = [links[link_name(leg, "carriage")][2] for leg in range(3)]
    assert kinds == [pb.JOINT_PRISMATIC] * 3
    assert links["platform"][2] == pb.JOINT_FIXED
    for leg in range(3):
        lower, upper = links[link_name(leg, "carriage")][8:10]
        # URDF limits must be wider than the control limits: PyBullet clamps silently.
        assert lower < PROTOTYPE.rho_min * MM and upper > PROTOTYPE.rho_max * MM


def test_machine_errors_change_the_urdf() -> None:
    machine = random_machine(1, "realistic", design=PROTOTYPE)
    assert write_urdf(machine) != write_urdf(MachineParams())
