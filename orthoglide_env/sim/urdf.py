"""Write the URDF of any Orthoglide (its geometric errors baked in).

URDF holds trees only.  The tree is: base -> for each leg a prismatic carriage -> R1 body
(the carriage-side short link of the parallelogram) -> bar 1 -> coupler (platform-side
short link) -> R2 body; bar 2 hangs from the R1 body.  The platform is a fixed child of
the x leg's R2 body.  :mod:`orthoglide_env.sim.pybullet` closes the loops in code: bar 2's far
end to the coupler, and the y and z legs' R2 bodies to the platform.

Joint conventions (the same as :func:`orthoglide_env.model.kinematics.leg_angles`): every leg
link is laid out in its leg frame ``R_LEG[i]``; R1 and R2 turn about local Z, the bar
hinges about local Y, the bars extend along local -X; at zero angles every leg points
straight at the platform.  The prismatic joint's value is the control coordinate
``rho_i`` (the encoder reading): the joint origin carries ``L + r + drho_i``.

Run ``python -m orthoglide_env.sim.urdf`` to regenerate the checked-in nominal URDF.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import LEG_NAMES, R_LEG, MachineParams
from orthoglide_env.model.kinematics import direct, leg_angles

MM = 1e-3  # URDF and PyBullet work in metres
URDF_NAME = "orthoglide.urdf"

# Masses (kg) of the prototype-like parts: aluminium bars and links, steel carriages.
MASS = {"carriage": 2.0, "r1": 0.3, "bar": 0.25, "coupler": 0.2, "r2": 0.1, "platform": 0.6}
COLOURS = {"base": (0.35, 0.35, 0.38, 1), "rail": (0.6, 0.6, 0.62, 1),
           "carriage": (0.15, 0.3, 0.6, 1), "joint": (0.85, 0.55, 0.1, 1),
           "bar": (0.8, 0.8, 0.82, 1), "platform": (0.7, 0.15, 0.15, 1)}
HINGE_RADIUS = 8.0  # mm, visual hinge pins
RAIL_SECTION = (40.0, 30.0)  # mm, along local Y and Z
RAIL_BESIDE = 45.0  # mm, rail centre to actuator axis along -local Y (beside the carriage)

LINKS_PER_LEG = ("carriage", "r1", "bar1", "coupler", "r2", "bar2")


def link_name(leg: int, part: str) -> str:
    """Name of a leg's link, e.g. ``x_bar1``."""
    return f"{LEG_NAMES[leg]}_{part}"


def _xyz(v: np.ndarray) -> str:
    return " ".join(f"{x:.12g}" for x in np.asarray(v, dtype=float) * MM)


def _rotation() -> type:
    """SciPy's ``Rotation``, imported when a URDF is written, not with the package (the
    command line and the model start without SciPy)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _rpy(rot: np.ndarray) -> str:
    # scipy's extrinsic xyz Euler angles are URDF's rpy.  The y and z leg frames sit at
    # pitch +-90 deg (gimbal lock): scipy warns and folds the yaw into the roll, which still
    # represents the same rotation exactly, so the warning carries no information here.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        angles = _rotation().from_matrix(rot).as_euler("xyz")
    return " ".join(f"{a:.15g}" for a in angles)


def _origin(xyz: np.ndarray, rot: np.ndarray | None = None) -> str:
    rpy = _rpy(rot) if rot is not None else "0 0 0"
    return f'<origin xyz="{_xyz(xyz)}" rpy="{rpy}"/>'


def _box(size: np.ndarray, xyz: np.ndarray, colour: str, *, collide: bool) -> str:
    geometry = f'<geometry><box size="{_xyz(size)}"/></geometry>'
    out = f"<visual>{_origin(xyz)}{geometry}<material name={quoteattr(colour)}/></visual>"
    if collide:
        out += f"<collision>{_origin(xyz)}{geometry}</collision>"
    return out


def _pin(length: float, xyz: np.ndarray, axis: str) -> str:
    """A visual hinge pin (cylinder) along local Y or Z."""
    rotation = _rotation()
    rot = {"y": rotation.from_euler("x", 90, degrees=True),
           "z": rotation.identity()}[axis].as_matrix()
    geometry = (f'<geometry><cylinder radius="{HINGE_RADIUS * MM:.6g}" '
                f'length="{length * MM:.6g}"/></geometry>')
    return f'<visual>{_origin(xyz, rot)}{geometry}<material name="joint"/></visual>'


def _inertial(mass: float, com: np.ndarray, size: np.ndarray) -> str:
    # Box inertia about the centre of mass; the COM sits where the machine code expects it
    # (see machine.py: link frames are recovered from the double-precision COM pose).
    sx, sy, sz = np.asarray(size) * MM
    ixx, iyy, izz = (mass / 12 * (b * b + c * c) for b, c in ((sy, sz), (sx, sz), (sx, sy)))
    return (f"<inertial>{_origin(com)}<mass value=\"{mass}\"/>"
            f'<inertia ixx="{ixx:.6g}" iyy="{iyy:.6g}" izz="{izz:.6g}" ixy="0" ixz="0" iyz="0"/>'
            "</inertial>")


def _link(name: str, body: str) -> str:
    return f'<link name="{name}">{body}</link>'


def bar_length(machine: MachineParams, leg: int) -> float:
    """Length of the bar box (hinge to hinge, less the clearance at both ends), mm."""
    return float(machine.leg_lengths[leg] - 2 * machine.design.bar_clearance)


@dataclass(frozen=True)
class JointOrigin:
    """One joint of the URDF tree, in the workbench's units (mm, rad).

    ``xyz`` (mm) and ``rotation`` (3x3, the joint frame's axes as columns) place the joint
    frame in the parent link's frame; the child link's frame is the joint frame moved by
    the joint value along (prismatic, mm) or about (revolute, rad) ``axis``, a unit vector
    in the joint frame (zero for the fixed joint).  The URDF file holds the same numbers
    in metres and roll-pitch-yaw angles.
    """

    name: str
    kind: str  # "prismatic", "revolute" or "fixed"
    parent: str
    child: str
    xyz: np.ndarray
    rotation: np.ndarray
    axis: np.ndarray


def joint_origins(machine: MachineParams) -> dict[str, JointOrigin]:
    """Where every joint of ``machine``'s URDF sits, by joint name, in the file's order.

    The 18 moving joints are six per leg (``x_slide``, ``x_r1``, ``x_bar1_hinge``,
    ``x_coupler_hinge``, ``x_r2``, ``x_bar2_hinge``, and the same for y and z); the fixed
    ``platform_mount`` hangs the platform from the x leg's R2 body.  The machine's errors
    enter here and nowhere else in the tree:

    * ``<leg>_slide``: at ``o_i + (L + r + drho_i) u_i`` (actuator axis position and
      encoder offset), in the leg frame ``R_LEG[i]``, moving along ``u_i`` (axis tilt);
    * ``<leg>_coupler_hinge``: ``L + dL_i`` from the bar's first hinge (leg length);
    * ``platform_mount``: ``-(r e_x + attach[0])`` from the x leg's R2 centre (the y and z
      legs' attachments are loop closures, outside the tree: see
      :mod:`orthoglide_env.sim.pybullet`).

    The other joints sit at the nominal ``d/2`` offsets of the parallelogram's hinges.
    """
    z, y, none = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.zeros(3)
    same = np.eye(3)
    design = machine.design
    up, down = np.array([0.0, 0.0, design.d / 2]), np.array([0.0, 0.0, -design.d / 2])
    out: list[JointOrigin] = []
    for i in range(3):
        n = functools.partial(link_name, i)
        slide = (machine.axis_origins[i]
                 + (design.L + design.r + machine.drho[i]) * machine.axis_directions[i])
        bar_end = np.array([-machine.leg_lengths[i], 0.0, 0.0])
        out += [
            JointOrigin(n("slide"), "prismatic", "base", n("carriage"), slide, R_LEG[i],
                        R_LEG[i].T @ machine.axis_directions[i]),
            JointOrigin(n("r1"), "revolute", n("carriage"), n("r1"), none, same, z),
            JointOrigin(n("bar1_hinge"), "revolute", n("r1"), n("bar1"), up, same, y),
            JointOrigin(n("coupler_hinge"), "revolute", n("bar1"), n("coupler"), bar_end,
                        same, y),
            JointOrigin(n("r2"), "revolute", n("coupler"), n("r2"), down, same, z),
            JointOrigin(n("bar2_hinge"), "revolute", n("r1"), n("bar2"), down, same, y),
        ]
    out.append(JointOrigin("platform_mount", "fixed", link_name(0, "r2"), "platform",
                           -machine.attach_points[0], same, none))
    return {j.name: j for j in out}


@dataclass(frozen=True)
class LoopClosure:
    """A loop the URDF tree leaves open: ``point_a`` of link ``link_a`` coincides with
    ``point_b`` of ``link_b`` (mm, each in its link's frame).  A ``fixed`` closure also
    locks the orientation: ``link_a``'s frame axes are the columns of ``rotation`` in
    ``link_b``'s frame."""

    kind: str  # "point" or "fixed"
    link_a: str
    point_a: np.ndarray
    link_b: str
    point_b: np.ndarray
    rotation: np.ndarray


def loop_closures(machine: MachineParams) -> list[LoopClosure]:
    """The five loops a simulator must close to make ``machine``'s URDF the machine.

    Each parallelogram's second bar ends at its coupler's lower hinge (a point: the bar's
    hinge axis is already fixed at its other end), and the y and z legs' R2 bodies are
    welded to the platform at ``r e_i + attach[i]``, so these closures carry the y and z
    attachment errors.
    """
    return [*(LoopClosure("point", link_name(i, "bar2"),
                          np.array([-machine.leg_lengths[i], 0.0, 0.0]), link_name(i, "coupler"),
                          np.array([0.0, 0.0, -machine.design.d]), np.eye(3)) for i in range(3)),
            *(LoopClosure("fixed", link_name(i, "r2"), np.zeros(3), "platform",
                          machine.attach_points[i], R_LEG[i]) for i in (1, 2))]


def _closures_comment(machine: MachineParams) -> str:
    lines = [f"  {c.kind} {c.link_a} ({_xyz(c.point_a)}) = {c.link_b} ({_xyz(c.point_b)})"
             + (f", {c.link_a} axes in {c.link_b} rpy ({_rpy(c.rotation)})"
                if c.kind == "fixed" else "") for c in loop_closures(machine)]
    return ("<!-- Loops the tree leaves open, to close in the simulator (points in metres, "
            "each in its link's frame):\n" + "\n".join(lines) + "\n-->\n")


def joint_positions(machine: MachineParams, rho: np.ndarray) -> dict[str, float]:
    """Values of the 18 moving joints (mm for the slides, rad) with the machine at control
    coordinates ``rho``: the slides read ``rho``, the passive joints follow from the exact
    closed configuration (:func:`~orthoglide_env.model.kinematics.leg_angles`).  With these, the
    forward kinematics of the tree puts the platform at
    :func:`~orthoglide_env.model.kinematics.direct`'s TCP and every loop closes."""
    rho = np.asarray(rho, dtype=float)
    theta, beta = leg_angles(machine, rho, direct(machine, rho))
    out = {}
    for i in range(3):
        # The platform only translates: the coupler undoes the bars' turn, R2 undoes R1's.
        values = {"slide": rho[i], "r1": theta[i], "bar1_hinge": beta[i],
                  "coupler_hinge": -beta[i], "r2": -theta[i], "bar2_hinge": beta[i]}
        out.update({link_name(i, part): float(v) for part, v in values.items()})
    return out


def _joint_xml(joint: JointOrigin, design: MachineDesign) -> str:
    """A joint element: the slides keep URDF limits wider than ``design``'s control limits
    (PyBullet's position motors silently clamp targets to URDF limits; the control limits
    are enforced in code, where a violation can be reported), the passive joints turn
    freely."""
    limits = {
        "prismatic": (f'<limit lower="{(design.rho_min - design.urdf_margin) * MM:.6g}" '
                      f'upper="{(design.rho_max + design.urdf_margin) * MM:.6g}" effort="1e6" '
                      'velocity="10"/>'),
        "revolute": '<limit lower="-3.14159" upper="3.14159" effort="0" velocity="100"/>',
        "fixed": "",
    }[joint.kind]
    axis = "" if joint.kind == "fixed" else f'<axis xyz="{_xyz(joint.axis / MM)}"/>'
    return (f'<joint name="{joint.name}" type="{joint.kind}"><parent link="{joint.parent}"/>'
            f'<child link="{joint.child}"/>{_origin(joint.xyz, joint.rotation)}{axis}{limits}'
            "</joint>")


def _leg(machine: MachineParams, i: int, joints: dict[str, JointOrigin]) -> list[str]:
    """The leg's links, each followed by the joint that carries it."""
    design = machine.design
    length = machine.leg_lengths[i]
    half_d = design.d / 2
    bar = np.array([bar_length(machine, i), *design.bar_section])
    bar_mid = np.array([-length / 2, 0.0, 0.0])
    carriage = np.array(design.carriage_size)
    short = np.array(design.short_link_size)
    bar_body = (_inertial(MASS["bar"], bar_mid, bar) + _box(bar, bar_mid, "bar", collide=True)
                + _pin(30, np.zeros(3), "y"))
    bodies = {
        "carriage": _inertial(MASS["carriage"], np.zeros(3), carriage)
        + _box(carriage, np.array([carriage[0] / 2 + design.carriage_setback, 0, 0]), "carriage",
               collide=True),
        "r1": _inertial(MASS["r1"], np.zeros(3), short)
        + _box(short, np.zeros(3), "joint", collide=False),
        "bar1": bar_body,
        "coupler": _inertial(MASS["coupler"], np.array([0, 0, -half_d]), short)
        + _box(short, np.array([0, 0, -half_d]), "joint", collide=True)
        + _pin(30, np.zeros(3), "y") + _pin(30, np.array([0, 0, -design.d]), "y"),
        "r2": _inertial(MASS["r2"], np.zeros(3), np.full(3, 20.0))
        + _pin(24, np.zeros(3), "z"),
        "bar2": bar_body,
    }
    out = []
    for joint in joints.values():
        if joint.name.startswith(f"{LEG_NAMES[i]}_"):
            out += [_link(joint.child, bodies[joint.child.split("_", 1)[1]]),
                    _joint_xml(joint, design)]
    return out


def rail_ends(design: MachineDesign) -> np.ndarray:
    """Ends of each leg's rail on the base (mm, shape (3 legs, near/far end, 3)): beside
    the nominal actuator axis, spanning the carriage's travel between the control limits.
    The base is drawn only; the gauge stands stand on these rails."""
    slide = design.L + design.r
    span = (slide + design.rho_min + design.carriage_setback,
            slide + design.rho_max + design.carriage_setback + design.carriage_size[0])
    return np.array([[R_LEG[i][:, 0] * s - R_LEG[i][:, 1] * RAIL_BESIDE for s in span]
                     for i in range(3)])


def _base(design: MachineDesign) -> str:
    body = _inertial(0.0, np.zeros(3), np.ones(3))
    for i, (start, end) in enumerate(rail_ends(design)):
        centre = (start + end) / 2
        size = np.abs(R_LEG[i] @ np.array([np.linalg.norm(end - start), *RAIL_SECTION]))
        # Drawn only: a rail beside the axis lies in the sweep of its own leg's bars ahead
        # of the carriage, where the prototype's guideways (not modelled) do not.
        body += _box(size, centre, "rail", collide=False)
    return _link("base", body)


def _platform(machine: MachineParams) -> list[str]:
    design = machine.design
    size = np.full(3, design.platform_size)
    body = _inertial(MASS["platform"], np.zeros(3), size)
    body += _box(size, np.zeros(3), "platform", collide=True)
    tool = np.array([8.0, 8.0, 40.0])
    body += _box(tool, np.array([0, 0, -20.0 - design.r]), "joint", collide=False)
    return [_link("platform", body),
            _joint_xml(joint_origins(machine)["platform_mount"], design)]


def write_urdf(machine: MachineParams) -> str:
    """The URDF (a string) of ``machine``; lengths in metres."""
    materials = "".join(f'<material name="{k}"><color rgba="{" ".join(map(str, v))}"/></material>'
                        for k, v in COLOURS.items())
    joints = joint_origins(machine)
    parts = [_base(machine.design), *(x for i in range(3) for x in _leg(machine, i, joints)),
             *_platform(machine)]
    body = "\n  ".join([materials, *parts])
    return ('<?xml version="1.0"?>\n<!-- Generated by orthoglide_env.sim.urdf: do not edit. -->\n'
            f'{_closures_comment(machine)}<robot name="orthoglide">\n  {body}\n</robot>\n')


def nominal_urdf_path() -> Path:
    """Path of the checked-in nominal URDF inside the installed package."""
    return Path(str(resources.files("orthoglide_env.urdf").joinpath(URDF_NAME)))


def main() -> None:
    """Regenerate the checked-in nominal URDF."""
    path = nominal_urdf_path()
    path.write_text(write_urdf(MachineParams()))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
