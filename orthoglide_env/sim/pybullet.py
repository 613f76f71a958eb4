"""The Orthoglide as a PyBullet closed-chain multibody, with its dial gauges.

The URDF (:mod:`orthoglide_env.sim.urdf`) holds the tree; this module closes the
loops: each parallelogram's second bar is pinned to the coupler with a point-to-point
constraint (its hinge axis is already fixed by its revolute joint at the other end, so
one point closes it), and the y and z legs' R2 bodies are welded to the platform with
fixed constraints.  The actuators are position-controlled; the passive joints are free.

Two ways to reach a posture:

* ``quasi-static`` (calibration): every joint is placed at the exact closed
  configuration of the true geometry, then the solver holds it for a few steps;
* ``dynamic``: the position motors drive the carriages and the mechanism is stepped
  until it has settled.

Readings use the double-precision centre-of-mass poses of PyBullet (the link-frame pose
it returns is single precision); every link's inertial frame is unrotated, so a link
frame is its COM frame shifted by the URDF's inertial origin.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from orthoglide_env.instruments.dial import GAUGE_BODY_RADIUS, STAND_LENGTH
from orthoglide_env.instruments.gauges import Gauge, GaugeArray
from orthoglide_env.instruments.rays import RAY_BACKOFF, on_flat_face, ray_box_distance
from orthoglide_env.instruments.slots import GaugeSpec, Part, on_platform
from orthoglide_env.model.collisions import collision_names, crash_pairs
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import LEG_NAMES, MachineParams
from orthoglide_env.model.kinematics import direct
from orthoglide_env.sim.motion import check_motion_mode
from orthoglide_env.sim.simulator import PhysicsSettings, Simulator, pb
from orthoglide_env.sim.urdf import (
    MM,
    LoopClosure,
    bar_length,
    joint_positions,
    link_name,
    loop_closures,
    rail_ends,
    write_urdf,
)

QUASI_STATIC_STEPS = 2  # steps after placement: enough for the solver to take hold
SETTLE_TOL = 1e-8  # m and m/s: a settled carriage is within 0.01 µm of its target, at rest
MAX_SETTLE_STEPS = 3000
POSITION_GAIN = 0.3
MOTOR_FORCE = 5000.0  # N, far above what gravity asks of the carriages
STAND_COLOUR = (0.1, 0.6, 0.2, 1.0)
CONTACT_QUERY = 1e-6  # m, query distance of the contact check
#: The default camera looks square-on along the machine's symmetry axis (1, 1, 1), where
#: the three legs look alike, from this far (mm), and frames the base's rails with this
#: margin around them.
CAMERA_DISTANCE = 1400.0
CAMERA_FOV = 50.0  # deg, for a camera placed by the caller
CAMERA_MARGIN = 1.3
ARM_RADIUS = 3.0  # mm, a stand's arm from its foot to the gauge body
FOOT_SIZE = np.array([30.0, 30.0, 30.0])  # mm, a stand's magnetic foot on a rail


class OrthoglideMachine:
    """A virtual Orthoglide in PyBullet, with gauges installed on its base."""

    def __init__(self, machine: MachineParams, gauges: list[Gauge], *, gui: bool = False,
                 gravity: bool = True, settings: PhysicsSettings | None = None,
                 sim: Simulator | None = None) -> None:
        """Build the machine in a new PyBullet client, or in ``sim``: a client that hosts
        one machine after another (everything in it is removed first).  A machine in a
        given client takes that client's settings, so ``gui``, ``gravity`` and ``settings``
        are for a new client only."""
        self.machine = machine
        self.gauges = list(gauges)
        self.gauge_array = GaugeArray.of(self.gauges)
        self._rho = np.zeros(3)
        if sim is not None and (gui or not gravity or settings is not None):
            raise ValueError("a machine built in a given simulator takes its settings: give "
                             "gui, gravity and settings to the Simulator")
        self._owns_sim = sim is None
        self._built = False
        if sim is None:
            settings = settings or PhysicsSettings(gravity=-9.81 if gravity else 0.0)
            sim = Simulator(gui=gui, settings=settings)
        self.sim = sim
        try:
            self._build()
        except BaseException:
            # A machine that cannot be built must not leave its client behind.
            if self._owns_sim:
                self.sim.close()
            raise

    def _build(self) -> None:
        """Load the tree, close the loops and place the machine at Zero, in a client
        cleared first."""
        if self._built or not self._owns_sim:  # a new client of its own holds nothing
            self.sim.clear()
        self._built = True
        self._generation = self.sim.generation
        self.bc = self.sim.client
        self.body = self.sim.load_urdf_text(write_urdf(self.machine))
        info = [self.bc.getJointInfo(self.body, j)
                for j in range(self.bc.getNumJoints(self.body))]
        self._index = {i[12].decode(): i[0] for i in info}  # by child link name
        self._joints = {i[1].decode(): (i[0], i[2]) for i in info}  # index, type
        self._com = {name: np.array(self.bc.getDynamicsInfo(self.body, j)[3]) / MM
                     for name, j in self._index.items()}
        self.slides = [self._index[link_name(i, "carriage")] for i in range(3)]
        self.platform = self._index["platform"]
        for j in range(self.bc.getNumJoints(self.body)):
            # Passive joints come with a velocity motor that would brake the mechanism.
            self.bc.setJointMotorControl2(self.body, j, pb.VELOCITY_CONTROL, force=0.0)
        self._closures = self._close_loops()
        self._pairs = self._collision_pairs()
        # The stands are drawn when a picture needs them: their shapes cost PyBullet a
        # fifth of a build, and a machine that is never looked at does not need them.
        self._stands: int | None = None
        if self.sim.gui:
            self._draw_stands()
        self.last_settle_steps = 0
        self.move(np.zeros(3))

    @property
    def in_client(self) -> bool:
        """Whether this machine is (still) what its client holds: another machine built in
        the same client replaces it."""
        return self.sim.connected and self.sim.generation == self._generation

    def rebuild(self) -> None:
        """Build this machine again in its client (after another one replaced it there) and
        place it at the posture it was last moved to."""
        rho = self._rho
        self._build()
        if np.any(rho != 0.0):
            self.move(rho)

    # -- construction ----------------------------------------------------------------
    def _pivot(self, link: str, point_mm: np.ndarray) -> list[float]:
        """A point given in a link's URDF frame, expressed in its COM frame (metres)."""
        return list((np.asarray(point_mm) - self._com[link]) * MM)

    def _close_loops(self) -> list[LoopClosure]:
        """Constraints for :func:`~orthoglide_env.sim.urdf.loop_closures`; returns the
        closures, for :meth:`loop_residual`."""
        closures = loop_closures(self.machine)
        for c in closures:
            a, b = self._index[c.link_a], self._index[c.link_b]
            pivots = self._pivot(c.link_a, c.point_a), self._pivot(c.link_b, c.point_b)
            if c.kind == "point":
                self.bc.createConstraint(self.body, a, self.body, b, pb.JOINT_POINT2POINT,
                                         [0, 0, 0], *pivots)
                continue
            cid = self.bc.createConstraint(
                self.body, a, self.body, b, pb.JOINT_FIXED, [0, 0, 0], *pivots,
                [0, 0, 0, 1], list(Rotation.from_matrix(c.rotation).as_quat()))
            self.bc.changeConstraint(cid, maxForce=1e9)
        return closures

    def _draw_stands(self) -> None:
        """Draw each gauge: its body behind the tip, an arm, and its stand's magnetic foot
        on the measured leg's rail, at the rail's end near the platform.  Visual shapes only:
        rays hit collision shapes, and these have none.  All parts are links of one static
        body, which goes as one when the gauges change."""
        if self._stands is not None:
            self.bc.removeBody(self._stands)
            self._stands = None
        if not self.gauges:
            return
        shapes, centres, axes = [], [], []
        for g in self.gauges:
            rear = g.origin - g.direction * STAND_LENGTH
            # A platform gauge has no leg: its stand stands behind it.
            foot = (rear - g.direction * STAND_LENGTH if on_platform(g.spec.part)
                    else rail_ends(self.machine.design)[g.spec.leg, 0])
            for a, b, radius in ((g.origin, rear, GAUGE_BODY_RADIUS), (rear, foot, ARM_RADIUS)):
                shapes.append(self.bc.createVisualShape(
                    pb.GEOM_CYLINDER, radius=radius * MM,
                    length=float(np.linalg.norm(b - a)) * MM, rgbaColor=STAND_COLOUR))
                centres.append((a + b) / 2)
                axes.append(b - a)
            shapes.append(self.bc.createVisualShape(
                pb.GEOM_BOX, halfExtents=list(FOOT_SIZE / 2 * MM), rgbaColor=STAND_COLOUR))
            centres.append(foot)
            axes.append(np.array([0.0, 0.0, 1.0]))
        n = len(shapes)
        self._stands = self.bc.createMultiBody(
            baseMass=0, linkMasses=[0.0] * n, linkCollisionShapeIndices=[-1] * n,
            linkVisualShapeIndices=shapes, linkPositions=[list(c * MM) for c in centres],
            linkOrientations=_z_turned_to(np.array(axes)).tolist(),
            linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n,
            linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
            linkParentIndices=[0] * n, linkJointTypes=[pb.JOINT_FIXED] * n,
            linkJointAxis=[[0.0, 0.0, 1.0]] * n)

    # -- motion -------------------------------------------------------------------------
    def move(self, rho: np.ndarray, mode: str = "quasi-static") -> None:
        """Drive the carriages to control coordinates ``rho`` (mm) and settle."""
        rho = np.asarray(rho, dtype=float)
        check_motion_mode(mode)
        # A posture the machine cannot be assembled in (beyond a singularity) raises
        # UnreachableError before anything moves: the exact configuration is solved first
        # (the motors alone would jam the mechanism against it).
        if mode == "quasi-static":
            self._place(rho)
            self._hold(rho)
            self.sim.step(QUASI_STATIC_STEPS)
            self.last_settle_steps = QUASI_STATIC_STEPS
        else:
            direct(self.machine, rho)
            self._hold(rho)
            self.last_settle_steps = self._settle(rho)
        self._rho = rho.copy()

    def _place(self, rho: np.ndarray) -> None:
        for name, value in joint_positions(self.machine, rho).items():
            j, kind = self._joints[name]
            self.bc.resetJointState(self.body, j, value * MM if kind == pb.JOINT_PRISMATIC
                                    else value, 0.0)

    def _hold(self, rho: np.ndarray) -> None:
        for i, j in enumerate(self.slides):
            self.bc.setJointMotorControl2(self.body, j, pb.POSITION_CONTROL,
                                          targetPosition=rho[i] * MM,
                                          positionGain=POSITION_GAIN, force=MOTOR_FORCE)

    def _settle(self, rho: np.ndarray) -> int:
        target = rho * MM
        for n in range(1, MAX_SETTLE_STEPS + 1):
            self.sim.step()
            pos, vel = np.array([s[:2] for s in self.bc.getJointStates(self.body, self.slides)]).T
            if np.all(np.abs(pos - target) < SETTLE_TOL) and np.all(np.abs(vel) < SETTLE_TOL):
                return n
        raise RuntimeError(f"the machine did not settle in {MAX_SETTLE_STEPS} steps")

    # -- readings -----------------------------------------------------------------------
    def encoders(self) -> np.ndarray:
        """Encoder readings: the prismatic joint values (mm)."""
        return np.array([s[0] for s in self.bc.getJointStates(self.body, self.slides)]) / MM

    def _link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Link frame position (mm) and rotation matrix from the double-precision COM pose."""
        state = self.bc.getLinkState(self.body, self._index[link], computeForwardKinematics=True)
        rot = np.array(self.bc.getMatrixFromQuaternion(state[1])).reshape(3, 3)
        return np.array(state[0]) / MM - rot @ self._com[link], rot

    def _point(self, link: str, local_mm: np.ndarray) -> np.ndarray:
        pos, rot = self._link_pose(link)
        return pos + rot @ np.asarray(local_mm)

    def tcp(self) -> np.ndarray:
        """TCP position (mm): the platform frame's origin."""
        return self._link_pose("platform")[0]

    def platform_orientation_error(self) -> float:
        """Rotation angle of the platform away from its nominal orientation (rad)."""
        rot = self._link_pose("platform")[1]
        return float(Rotation.from_matrix(rot).magnitude())

    def loop_residual(self) -> float:
        """The worst gap (mm) between the two sides of any loop closure."""
        return float(max(np.linalg.norm(self._point(c.link_a, c.point_a)
                                        - self._point(c.link_b, c.point_b))
                         for c in self._closures))

    def gauge_distances(self) -> np.ndarray:
        """Ray distance of each gauge's tip to its target (mm); NaN if the first thing the
        ray meets is not the target."""
        if not self.gauges:
            return np.empty(0)
        starts = np.array([g.origin - RAY_BACKOFF * g.direction for g in self.gauges])
        ends = np.array([g.origin + (g.travel + RAY_BACKOFF) * g.direction for g in self.gauges])
        hits = self.bc.rayTestBatch(list(starts * MM), list(ends * MM))
        out = np.full(len(self.gauges), np.nan)
        for k, (g, hit) in enumerate(zip(self.gauges, hits, strict=True)):
            link = target_link(g.spec)
            box = self._target_box(g.spec)
            if hit[0] == self.body and hit[1] == self._index[link] and hit[2] > 0:
                t = float(np.dot(np.array(hit[3]) / MM - g.origin, g.direction))
            else:
                # Another part first: in front of the tip it blocks the plunger, but a
                # target behind the tip presses the gauge whatever else the ray meets (or
                # the ray starts inside it and Bullet reports nothing useful); the
                # simulated target pose still shows where it is.
                t = float(ray_box_distance(g.origin, g.direction, *box))
                if not t < 0:
                    continue
            if on_flat_face(g.origin + t * g.direction, *box, face=g.spec.face):
                out[k] = t
        return out

    def target_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Box of every gauge's target as simulated: centres, rotations, half extents."""
        boxes = [self._target_box(g.spec) for g in self.gauges]
        return tuple(np.array(part) for part in zip(*boxes, strict=True))  # type: ignore[return-value]

    def _target_box(self, spec: GaugeSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre (mm), rotation and half extents (mm) of a gauge's target box, as
        simulated: where the URDF puts each box in its link's frame."""
        pos, rot = self._link_pose(target_link(spec))
        design = self.machine.design
        if on_platform(spec.part):
            return pos, rot, np.full(3, design.platform_size / 2)
        if spec.part == Part.CARRIAGE:
            ahead = np.array([design.carriage_setback + design.carriage_size[0] / 2, 0.0, 0.0])
            return pos + rot @ ahead, rot, np.array(design.carriage_size) / 2
        length = self.machine.leg_lengths[spec.leg]
        half = np.array([bar_length(self.machine, spec.leg) / 2,
                         *(np.array(design.bar_section) / 2)])
        return pos + rot @ np.array([-length / 2, 0.0, 0.0]), rot, half

    def _collision_pairs(self) -> list[tuple[int, int, str]]:
        """Link indices of :func:`~orthoglide_env.model.collisions.crash_pairs`.  The base has no
        collision shape (its rails are drawn only), so it is not checked."""
        return [(self._index[a], self._index[b], f"{a}/{b}") for a, b in crash_pairs()]

    def collision_mask(self) -> np.ndarray:
        """Which pairs of :meth:`_collision_pairs` are in contact."""
        # getClosestPoints(distance=0) reports nothing, not even a deep penetration: ask
        # for a hair more and keep what touches.
        return np.array([any(pt[8] <= 0.0 for pt in self.bc.getClosestPoints(
            self.body, self.body, CONTACT_QUERY, a, b)) for a, b, _ in self._pairs], dtype=bool)

    def collisions(self) -> list[str]:
        """Pairs of parts in contact that should never touch (see :meth:`_collision_pairs`)."""
        return collision_names(self.collision_mask())

    def set_gauges(self, gauges: list[Gauge]) -> None:
        self.gauges = list(gauges)
        self.gauge_array = GaugeArray.of(self.gauges)
        if self.sim.gui or self._stands is not None:
            self._draw_stands()

    def render(self, width: int = 640, height: int = 480, *, eye: np.ndarray | None = None,
               target: np.ndarray | None = None, fov: float | None = None) -> np.ndarray:
        """An RGB image (height, width, 3) of the machine and its gauges, TinyRenderer.

        ``eye`` and ``target``: camera position and aim point (mm, world), ``fov`` its
        vertical field of view (deg); by default the camera looks square-on along the
        symmetry axis and frames the base (:func:`square_on_camera`).
        """
        if self._stands is None and self.gauges:
            self._draw_stands()
        if eye is None or target is None:
            eye, target, framing = square_on_camera(width / height, self.machine.design)
            fov = framing if fov is None else fov
        view = self.bc.computeViewMatrix(cameraEyePosition=list(eye * MM),
                                         cameraTargetPosition=list(target * MM),
                                         cameraUpVector=[0, 0, 1])
        proj = self.bc.computeProjectionMatrixFOV(fov=fov or CAMERA_FOV, aspect=width / height,
                                                  nearVal=0.05, farVal=5.0)
        img = self.bc.getCameraImage(width, height, view, proj, renderer=pb.ER_TINY_RENDERER)
        return np.reshape(np.asarray(img[2], dtype=np.uint8), (height, width, 4))[..., :3]

    def close(self) -> None:
        """Release the client if this machine made it; a client it was given belongs to the
        caller (and may already hold the next machine)."""
        if self._owns_sim:
            self.sim.close()

    def __repr__(self) -> str:
        return f"OrthoglideMachine(legs={LEG_NAMES}, gauges={len(self.gauges)})"


def target_link(spec: GaugeSpec) -> str:
    """The link a gauge touches: a bar (``x_bar1`` at +d/2, ``x_bar2`` at -d/2), a
    carriage (``x_carriage``) or the platform."""
    if on_platform(spec.part):
        return "platform"
    if spec.part == Part.CARRIAGE:
        return link_name(spec.leg, "carriage")
    return link_name(spec.leg, "bar1" if spec.bar > 0 else "bar2")


def _z_turned_to(axes: np.ndarray) -> np.ndarray:
    """Quaternions (x, y, z, w) of rotations that turn the z axis along each of ``axes``
    (n, 3), for cylinders, which PyBullet makes along z: the shortest turn, and none
    for an axis along -z (a cylinder is the same either way up)."""
    unit = axes / np.linalg.norm(axes, axis=-1, keepdims=True)
    turn = np.cross([0.0, 0.0, 1.0], unit)
    size = np.linalg.norm(turn, axis=-1, keepdims=True)
    angle = np.arctan2(size, unit[:, 2:])
    rotvec = np.where(size > 1e-12, turn / np.where(size > 1e-12, size, 1.0) * angle, 0.0)
    return Rotation.from_rotvec(rotvec).as_quat()


def square_on_camera(aspect: float, design: MachineDesign
                     ) -> tuple[np.ndarray, np.ndarray, float]:
    """Camera ``eye``, ``target`` (mm) and vertical field of view (deg) looking along the
    machine's symmetry axis (1, 1, 1), world z up, framing the base's rails (and so the
    platform, legs and gauge stands between them) for an image of ``aspect`` = width /
    height."""
    view = np.ones(3) / np.sqrt(3)
    right = np.cross(-view, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -view)
    points = np.vstack([rail_ends(design).reshape(-1, 3), np.zeros((1, 3))])
    x, y = points @ right, points @ up
    target = (x.max() + x.min()) / 2 * right + (y.max() + y.min()) / 2 * up
    # The rails' far ends are nearer the eye than the target: frame them at their depth.
    nearest = CAMERA_DISTANCE - np.max(points @ view)
    half_height = max(np.ptp(y), np.ptp(x) / aspect) / 2 * CAMERA_MARGIN
    fov = float(2 * np.degrees(np.arctan(half_height / nearest)))
    return target + CAMERA_DISTANCE * view, target, fov
