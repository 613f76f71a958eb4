"""``orthoglide urdf``: any machine's true geometry, read back by a third-party URDF parser.

How the check works: the URDF is a tree, so a posture is a value for each of its 18
joints.  The slides take the control coordinates; the passive joints take the angles of
the exact model's closed configuration (``joint_positions``, from ``leg_angles``).
yourdfpy's forward kinematics then places every link; the platform frame must sit at
``kinematics.direct``'s TCP, and the five loops the tree leaves open must close.  Both to
1e-6 mm: the file holds lengths to 12 significant digits (1e-10 mm at 0.3 m), far below.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.model.kinematics import direct
from orthoglide_env.sim.urdf import (
    MM,
    joint_origins,
    joint_positions,
    loop_closures,
    nominal_urdf_path,
    write_urdf,
)

yourdfpy = pytest.importorskip("yourdfpy")

TOLERANCE = 1e-6  # mm
#: A machine with every kind of error, some of them large (inside the validity range).
MACHINE = MachineParams(
    drho=[3.0, -4.0, 1.5], dL=[-2.5, 3.5, 1.0],
    axis_tilt=[[4e-3, -3e-3], [2e-3, 5e-3], [-4e-3, 1e-3]],
    axis_offset=[[1.0, -0.8], [0.5, 1.2], [-1.0, 0.3]],
    attach=[[0.5, -0.4, 0.3], [-0.6, 0.2, 0.4], [0.3, 0.5, -0.5]],
)


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> yourdfpy.URDF:
    folder = tmp_path_factory.mktemp("export")
    MACHINE.to_json(folder / "m.json")
    package_urdf = nominal_urdf_path().read_bytes()
    proc = subprocess.run([sys.executable, "-m", "calibrators.cli", "urdf", "--machine",
                           "m.json", "-o", "m.urdf"], cwd=folder, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    # The command writes where it is told and nowhere else (never into the package).
    assert nominal_urdf_path().read_bytes() == package_urdf
    assert sorted(p.name for p in folder.iterdir()) == ["m.json", "m.urdf"]
    assert (folder / "m.urdf").read_text() == write_urdf(MACHINE)
    return yourdfpy.URDF.load(str(folder / "m.urdf"), load_meshes=False,
                              build_collision_scene_graph=False)


def test_the_public_joint_table_is_what_the_file_says(exported) -> None:
    origins = joint_origins(MACHINE)
    assert len([j for j in origins.values() if j.kind != "fixed"]) == 18
    assert set(origins) == set(exported.joint_map)
    for name, joint in origins.items():
        parsed = exported.joint_map[name]
        assert (parsed.type, parsed.parent, parsed.child) == (joint.kind, joint.parent,
                                                               joint.child)
        np.testing.assert_allclose(parsed.origin[:3, 3] / MM, joint.xyz, atol=1e-9)
        np.testing.assert_allclose(parsed.origin[:3, :3], joint.rotation, atol=1e-12)
        if joint.kind != "fixed":
            np.testing.assert_allclose(parsed.axis, joint.axis, atol=1e-12)


def _pose(urdf: yourdfpy.URDF, link: str) -> tuple[np.ndarray, np.ndarray]:
    """A link frame's position (mm) and rotation in the base frame, by the parser."""
    transform = urdf.get_transform(link, "base")
    return transform[:3, 3] / MM, transform[:3, :3]


def test_forward_kinematics_of_the_export_matches_the_exact_model(exported) -> None:
    rng = np.random.default_rng(12)
    kinds = {name: j.type for name, j in exported.joint_map.items()}
    for rho in rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (100, 3)):
        values = joint_positions(MACHINE, rho)
        assert len(values) == 18
        exported.update_cfg({name: v * MM if kinds[name] == "prismatic" else v
                             for name, v in values.items()})
        tcp, rotation = _pose(exported, "platform")
        np.testing.assert_allclose(tcp, direct(MACHINE, rho), atol=TOLERANCE)
        np.testing.assert_allclose(rotation, np.eye(3), atol=1e-9)  # it only translates
        for c in loop_closures(MACHINE):
            (pa, ra), (pb, rb) = _pose(exported, c.link_a), _pose(exported, c.link_b)
            np.testing.assert_allclose(pa + ra @ c.point_a, pb + rb @ c.point_b,
                                       atol=TOLERANCE, err_msg=f"{c.link_a}/{c.link_b}")
            if c.kind == "fixed":
                np.testing.assert_allclose(rb.T @ ra, c.rotation, atol=1e-9)


def test_every_machine_error_reaches_the_export() -> None:
    # Each group moves some joint or closure: none is lost on the way to other simulators.
    nominal = (joint_origins(MachineParams()), loop_closures(MachineParams()))
    for key, value in random_machine(3, "realistic", design=PROTOTYPE).to_dict().items():
        machine = MachineParams(**{key: value})
        origins, closures = joint_origins(machine), loop_closures(machine)
        moved = any(not np.allclose(a.xyz, b.xyz) or not np.allclose(a.axis, b.axis)
                    for a, b in zip(origins.values(), nominal[0].values(), strict=True))
        moved |= any(not np.allclose(a.point_a, b.point_a) or not np.allclose(a.point_b,
                                                                              b.point_b)
                     for a, b in zip(closures, nominal[1], strict=True))
        assert moved, key
