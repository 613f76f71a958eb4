"""Write the URDF of any Orthoglide (its geometric errors baked in).

URDF holds trees only.  The tree is: base -> for each leg a prismatic carriage -> R1 body
(the carriage-side short link of the parallelogram) -> bar 1 -> coupler (platform-side
short link) -> R2 body; bar 2 hangs from the R1 body.  The platform is a fixed child of
the x leg's R2 body.  :mod:`orthoglide_env.machine` closes the loops in code: bar 2's far
end to the coupler, and the y and z legs' R2 bodies to the platform.

Joint conventions (the same as :func:`orthoglide_env.kinematics.leg_angles`): every leg
link is laid out in its leg frame ``R_LEG[i]``; R1 and R2 turn about local Z, the bar
hinges about local Y, the bars extend along local -X; at zero angles every leg points
straight at the platform.  The prismatic joint's value is the control coordinate
``rho_i`` (the encoder reading): the joint origin carries ``L + r + drho_i``.

Run ``python -m orthoglide_env.urdf_writer`` to regenerate the checked-in nominal URDF.
"""

from __future__ import annotations

import warnings
from importlib import resources
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
from scipy.spatial.transform import Rotation

from .geometry import (
    BAR_CLEARANCE,
    BAR_SECTION,
    CARRIAGE_SETBACK,
    CARRIAGE_SIZE,
    D_NOMINAL,
    L_NOMINAL,
    LEG_NAMES,
    PLATFORM_SIZE,
    R_LEG,
    R_TOOL,
    RHO_MAX,
    RHO_MIN,
    SHORT_LINK_SIZE,
    URDF_RHO_MARGIN,
    MachineParams,
)

MM = 1e-3  # URDF and PyBullet work in metres
URDF_NAME = "orthoglide.urdf"

# Masses (kg) of the prototype-like parts: aluminium bars and links, steel carriages.
MASS = {"carriage": 2.0, "r1": 0.3, "bar": 0.25, "coupler": 0.2, "r2": 0.1, "platform": 0.6}
COLOURS = {
    "base": (0.35, 0.35, 0.38, 1),
    "rail": (0.6, 0.6, 0.62, 1),
    "carriage": (0.15, 0.3, 0.6, 1),
    "joint": (0.85, 0.55, 0.1, 1),
    "bar": (0.8, 0.8, 0.82, 1),
    "platform": (0.7, 0.15, 0.15, 1),
}
HINGE_RADIUS = 8.0  # mm, visual hinge pins
RAIL_SECTION = (40.0, 30.0)  # mm, along local Y and Z
RAIL_BESIDE = 45.0  # mm, rail centre to actuator axis along -local Y (beside the carriage)

LINKS_PER_LEG = ("carriage", "r1", "bar1", "coupler", "r2", "bar2")


def link_name(leg: int, part: str) -> str:
    """Name of a leg's link, e.g. ``x_bar1``."""
    return f"{LEG_NAMES[leg]}_{part}"


def _xyz(v: np.ndarray) -> str:
    return " ".join(f"{x:.12g}" for x in np.asarray(v, dtype=float) * MM)


def _rpy(rot: np.ndarray) -> str:
    # scipy's extrinsic xyz Euler angles are URDF's rpy.  The y and z leg frames sit at
    # pitch +-90 deg (gimbal lock): scipy warns and folds the yaw into the roll, which still
    # represents the same rotation exactly, so the warning carries no information here.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        angles = Rotation.from_matrix(rot).as_euler("xyz")
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
    """A visual hinge pin (cylinder) along a local axis."""
    rot = {"x": Rotation.from_euler("y", 90, degrees=True),
           "y": Rotation.from_euler("x", 90, degrees=True),
           "z": Rotation.identity()}[axis].as_matrix()
    geometry = (
        f'<geometry><cylinder radius="{HINGE_RADIUS * MM:.6g}" length="{length * MM:.6g}"/>'
        "</geometry>"
    )
    return f'<visual>{_origin(xyz, rot)}{geometry}<material name="joint"/></visual>'


def _inertial(mass: float, com: np.ndarray, size: np.ndarray) -> str:
    # Box inertia about the centre of mass; the COM sits where the machine code expects it
    # (see machine.py: link frames are recovered from the double-precision COM pose).
    sx, sy, sz = np.asarray(size) * MM
    ixx, iyy, izz = (mass / 12 * (b * b + c * c) for b, c in ((sy, sz), (sx, sz), (sx, sy)))
    return (
        f"<inertial>{_origin(com)}<mass value=\"{mass}\"/>"
        f'<inertia ixx="{ixx:.6g}" iyy="{iyy:.6g}" izz="{izz:.6g}" ixy="0" ixz="0" iyz="0"/>'
        "</inertial>"
    )


def _link(name: str, body: str) -> str:
    return f'<link name="{name}">{body}</link>'


def _joint(name: str, kind: str, parent: str, child: str, origin: str, axis: str = "",
           limits: str = "") -> str:
    axis_xml = f'<axis xyz="{axis}"/>' if axis else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f"{origin}{axis_xml}{limits}</joint>"
    )


def bar_length(machine: MachineParams, leg: int) -> float:
    """Length of the bar box (hinge to hinge, less the clearance at both ends), mm."""
    return float(machine.leg_lengths[leg] - 2 * BAR_CLEARANCE)


def _leg(machine: MachineParams, i: int) -> list[str]:
    frame = R_LEG[i]
    length = machine.leg_lengths[i]
    u_local = frame.T @ machine.axis_directions[i]
    slide_origin = machine.axis_origins[i] + (L_NOMINAL + R_TOOL + machine.drho[i]) * (
        machine.axis_directions[i]
    )
    lo, hi = (RHO_MIN - URDF_RHO_MARGIN) * MM, (RHO_MAX + URDF_RHO_MARGIN) * MM
    limit = f'<limit lower="{lo:.6g}" upper="{hi:.6g}" effort="1e6" velocity="10"/>'
    free = '<limit lower="-3.14159" upper="3.14159" effort="0" velocity="100"/>'
    half_d = D_NOMINAL / 2
    bar = np.array([bar_length(machine, i), *BAR_SECTION])
    bar_mid = np.array([-length / 2, 0.0, 0.0])
    carriage = np.array(CARRIAGE_SIZE)
    short = np.array(SHORT_LINK_SIZE)
    n = lambda part: link_name(i, part)  # noqa: E731
    return [
        _link(n("carriage"), _inertial(MASS["carriage"], np.zeros(3), carriage)
              + _box(carriage, np.array([carriage[0] / 2 + CARRIAGE_SETBACK, 0, 0]), "carriage",
                     collide=True)),
        _joint(n("slide"), "prismatic", "base", n("carriage"), _origin(slide_origin, frame),
               _xyz(u_local / MM), limit),
        _link(n("r1"), _inertial(MASS["r1"], np.zeros(3), short)
              + _box(short, np.zeros(3), "joint", collide=False)),
        _joint(n("r1"), "revolute", n("carriage"), n("r1"), _origin(np.zeros(3)), "0 0 1", free),
        _link(n("bar1"), _inertial(MASS["bar"], bar_mid, bar)
              + _box(bar, bar_mid, "bar", collide=True) + _pin(30, np.zeros(3), "y")),
        _joint(n("bar1_hinge"), "revolute", n("r1"), n("bar1"),
               _origin(np.array([0, 0, half_d])), "0 1 0", free),
        _link(n("coupler"), _inertial(MASS["coupler"], np.array([0, 0, -half_d]), short)
              + _box(short, np.array([0, 0, -half_d]), "joint", collide=True)
              + _pin(30, np.zeros(3), "y") + _pin(30, np.array([0, 0, -D_NOMINAL]), "y")),
        _joint(n("coupler_hinge"), "revolute", n("bar1"), n("coupler"),
               _origin(np.array([-length, 0, 0])), "0 1 0", free),
        _link(n("r2"), _inertial(MASS["r2"], np.zeros(3), np.full(3, 20.0))
              + _pin(24, np.zeros(3), "z")),
        _joint(n("r2"), "revolute", n("coupler"), n("r2"),
               _origin(np.array([0, 0, -half_d])), "0 0 1", free),
        _link(n("bar2"), _inertial(MASS["bar"], bar_mid, bar)
              + _box(bar, bar_mid, "bar", collide=True) + _pin(30, np.zeros(3), "y")),
        _joint(n("bar2_hinge"), "revolute", n("r1"), n("bar2"),
               _origin(np.array([0, 0, -half_d])), "0 1 0", free),
    ]


def _base() -> str:
    body = _inertial(0.0, np.zeros(3), np.ones(3))
    # Each rail spans the carriage's travel between the control limits, nominal axes.
    start = L_NOMINAL + R_TOOL + RHO_MIN + CARRIAGE_SETBACK
    end = L_NOMINAL + R_TOOL + RHO_MAX + CARRIAGE_SETBACK + CARRIAGE_SIZE[0]
    for i in range(3):
        centre = R_LEG[i][:, 0] * (start + end) / 2 - R_LEG[i][:, 1] * RAIL_BESIDE
        size = np.abs(R_LEG[i] @ np.array([end - start, *RAIL_SECTION]))
        # Drawn only: a rail beside the axis lies in the sweep of its own leg's bars ahead
        # of the carriage, where the prototype's guideways (not modelled) do not.
        body += _box(size, centre, "rail", collide=False)
    return _link("base", body)


def _platform(machine: MachineParams) -> list[str]:
    size = np.full(3, PLATFORM_SIZE)
    body = _inertial(MASS["platform"], np.zeros(3), size)
    body += _box(size, np.zeros(3), "platform", collide=True)
    tool = np.array([8.0, 8.0, 40.0])
    body += _box(tool, np.array([0, 0, -20.0 - R_TOOL]), "joint", collide=False)
    return [
        _link("platform", body),
        _joint("platform_mount", "fixed", link_name(0, "r2"), "platform",
               _origin(-machine.attach_points[0])),
    ]


def write_urdf(machine: MachineParams) -> str:
    """The URDF (a string) of ``machine``; lengths in metres."""
    materials = "".join(
        f'<material name="{k}"><color rgba="{" ".join(map(str, v))}"/></material>'
        for k, v in COLOURS.items()
    )
    parts = [_base()]
    for i in range(3):
        parts += _leg(machine, i)
    parts += _platform(machine)
    body = "\n  ".join([materials, *parts])
    return (
        '<?xml version="1.0"?>\n'
        "<!-- Generated by orthoglide_env.urdf_writer: do not edit. -->\n"
        f'<robot name="orthoglide">\n  {body}\n</robot>\n'
    )


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
