"""The machines a lab works on (:class:`LabMachines`): the exact model, any batch
(:class:`ExactMachines`), or one PyBullet machine (:class:`SimulatedMachine`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from orthoglide_env.instruments.dial import pressed_past_travel
from orthoglide_env.instruments.gauges import Gauge, GaugeArray, as_gauge_array
from orthoglide_env.instruments.rays import exact_ray_distances, exact_target_boxes
from orthoglide_env.model.boxes import collision_boxes
from orthoglide_env.model.collisions import collision_mask
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import direct
from orthoglide_env.sim.motion import check_motion_mode

if TYPE_CHECKING:  # PyBullet is imported only by the back-end that needs it
    from orthoglide_env.sim.pybullet import OrthoglideMachine
    from orthoglide_env.sim.simulator import Simulator

class ExactMachine:
    """The machine as the exact kinematic model computes it (no dynamics, no solver).

    A batch of machines is one ``ExactMachine`` too: ``machine`` with a batch shape
    (:attr:`MachineParams.batch_shape`) and ``gauges`` a :class:`GaugeArray` of that batch
    shape; then ``rho`` and every reading carry the batch dimensions first.  One machine
    is the batch of shape ``()``, computed by the same code.
    """

    def __init__(self, machine: MachineParams, gauges: list[Gauge] | GaugeArray,
                 rho: np.ndarray | None = None, tcp: np.ndarray | None = None) -> None:
        """``rho``: the posture to start at (default Zero), as :meth:`move` takes it;
        ``tcp``: the TCP there, when already solved."""
        self.machine = machine
        self.gauge_array = as_gauge_array(gauges)
        self.move(np.zeros(3) if rho is None else rho, tcp=tcp)

    def move(self, rho: np.ndarray, mode: str = "quasi-static", tcp: np.ndarray | None = None
             ) -> None:
        """Go to control coordinates ``rho``, shape ``(*batch, 3)`` (or ``(3,)``: the same
        posture on every machine); ``tcp``: the TCP there, when already solved."""
        check_motion_mode(mode)
        rho = np.array(np.broadcast_to(rho, (*self.machine.batch_shape, 3)), dtype=float)
        # Solved before anything is stored: a posture the machine cannot be assembled in
        # raises and leaves the machine where it was.  The geometry of a posture is computed
        # once; every reading below uses it.
        tcp = direct(self.machine, rho) if tcp is None else np.asarray(tcp, dtype=float)
        self._boxes = collision_boxes(self.machine, rho, tcp)
        self._rho, self._tcp = rho, tcp
        self._picked: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def encoders(self) -> np.ndarray:
        return self._rho.copy()

    def tcp(self) -> np.ndarray:
        return self._tcp.copy()

    def gauge_distances(self) -> np.ndarray:
        """Ray distance ``t`` (mm) of every gauge's tip to its target; NaN when the ray
        does not hit the target first."""
        return exact_ray_distances(self.machine, self.gauge_array, self._rho, self._boxes,
                                   self._targets())

    def collision_mask(self) -> np.ndarray:
        """Which pairs of :data:`~orthoglide_env.model.collisions.PAIR_NAMES` are in contact.

        Within the joint limits the nearest crash pair stays millimetres apart on the
        nominal and realistic machines (tests/test_collisions.py); the check is for
        machines far from nominal, given through reset options."""
        return collision_mask(self.machine, self._rho, self._boxes)

    def target_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Box of every gauge's target: centres (mm), rotations, half extents (mm)."""
        return tuple(part.copy() for part in self._targets())  # type: ignore[return-value]

    def _targets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`target_boxes` at this posture, picked once (a look asks twice)."""
        if self._picked is None:
            self._picked = exact_target_boxes(self.gauge_array, self._boxes)
        return self._picked


class Sight(NamedTuple):
    """What the machines of some episodes show at their postures (one row per episode)."""

    t: np.ndarray  # (R, stands) ray distance of each stand's gauge; NaN where none
    pressed: np.ndarray  # (R, stands) the target bar presses the gauge past its travel
    crashed: np.ndarray  # (R, pairs) crash pairs in contact
    tcp: np.ndarray  # (R, 3) true TCP


class LabMachines:
    """The machines of a batch of lab episodes.  The batch keeps the machines' errors,
    postures and gauges; a back-end with machines of its own follows every change.  The
    methods as written here are a back-end's without any (the exact model's): nothing to
    build, drive, install or release, encoders that read the commanded posture, and no
    picture."""

    def start(self, rows: np.ndarray, machines: MachineParams) -> None:
        """New machines for episodes ``rows``, at Zero; a failure leaves the machines as
        they were."""

    def move(self, rows: np.ndarray, rho: np.ndarray) -> None:
        """Drive the machines of ``rows`` to ``rho`` (R, 3), reachable and in limits."""

    def set_gauges(self, rows: np.ndarray, gauges: GaugeArray, mounted: np.ndarray) -> None:
        """The gauges (R, stands) of the episodes ``rows``, those ``mounted`` in place."""

    def look(self, rows: np.ndarray, machines: MachineParams, gauges: GaugeArray,
             rho: np.ndarray, tcp: np.ndarray, engaged: np.ndarray) -> Sight:
        """What the machines of ``rows`` (errors ``machines``, gauges ``gauges`` of batch
        shape (R,), postures ``rho``) show; ``tcp``: their TCPs where the exact model
        already solved them (NaN rows where not); ``engaged`` (R, stands): the gauges whose
        tips are down (a lifted one reads nothing and cannot be pressed, so it may come
        back NaN and unpressed)."""
        raise NotImplementedError

    def encoders(self, rows: np.ndarray, rho: np.ndarray, actual: np.ndarray | None = None
                 ) -> np.ndarray:
        """Encoder readings (R, 3) of the machines of ``rows`` (commanded at ``rho``; their
        carriages at ``actual`` when the world puts them elsewhere: the motor encoders
        still read the command)."""
        return rho.copy()

    def render(self) -> np.ndarray:
        """An RGB picture (height, width, 3) of the machine, or ``ValueError``."""
        raise ValueError("the exact backend has no picture: use backend='pybullet' to render")

    def close(self) -> None:
        """Release every resource."""


class ExactMachines(LabMachines):
    """The exact model: a machine is its errors and posture, so there is nothing to keep
    in step; one :class:`ExactMachine` computes any batch.

    A look is a function of its arguments alone, so the last :data:`KEPT` are kept and a
    look asked again is not traced again: a procedure that goes back to its postures
    (the paper's Zero -> Max -> Min three times, every machine of a batch at once) traces
    each once.  Where the world moves the carriages between visits the arguments differ,
    and every look is traced."""

    #: Looks kept: a leg's three paper postures with room for the levers' looks between.
    KEPT: int = 8

    def __init__(self) -> None:
        # The arguments' bytes -> the machines and gauges looked at (held, so that the
        # objects compared by identity live on) and what they showed.
        self._looks: dict[tuple[bytes, ...], tuple[MachineParams, GaugeArray, Sight]] = {}

    def look(self, rows: np.ndarray, machines: MachineParams, gauges: GaugeArray,
             rho: np.ndarray, tcp: np.ndarray, engaged: np.ndarray) -> Sight:
        key = tuple(np.ascontiguousarray(x).tobytes() for x in (rows, rho, tcp, engaged))
        kept = self._looks.get(key)
        if kept is not None and kept[0] is machines and kept[1] is gauges:
            return kept[2]
        sight = self._traced(machines, gauges, rho, tcp, engaged)
        for part in sight:
            part.flags.writeable = False  # shared by every look that asks again
        if len(self._looks) >= self.KEPT:
            del self._looks[next(iter(self._looks))]  # the oldest
        self._looks[key] = (machines, gauges, sight)
        return sight

    def start(self, rows: np.ndarray, machines: MachineParams) -> None:
        self._looks.clear()

    def set_gauges(self, rows: np.ndarray, gauges: GaugeArray, mounted: np.ndarray) -> None:
        self._looks.clear()

    @staticmethod
    def _traced(machines: MachineParams, gauges: GaugeArray, rho: np.ndarray,
                tcp: np.ndarray, engaged: np.ndarray) -> Sight:
        """:meth:`look` computed: the gauges' rays traced to their targets."""
        # Only the stands engaged on some machine are traced (the paper's procedure keeps
        # two of six down): their rays against every box are most of a look's arithmetic.
        down = np.flatnonzero(engaged.any(axis=0))
        if not len(down):
            down = np.arange(1)  # the machines' boxes still need a gauge set to be built
        traced = gauges.columns(down)
        built = ExactMachine(machines, traced, rho,
                             tcp=tcp if np.isfinite(tcp).all() else None)
        t = np.full(engaged.shape, np.nan)
        pressed = np.zeros(engaged.shape, dtype=bool)
        t[:, down] = built.gauge_distances()
        pressed[:, down] = pressed_past_travel(traced, *built.target_boxes())
        return Sight(t, pressed, built.collision_mask(), built.tcp())


class SimulatedMachine(LabMachines):
    """One PyBullet machine (a batch of one episode), moved the ``motion`` way
    (:data:`~orthoglide_env.sim.motion.MOTION_MODES`).  Every machine of the env is built
    in the same client, made at the first start (a GUI window with ``gui``) and kept until
    :meth:`close`."""

    def __init__(self, motion: str = "quasi-static", gui: bool = False) -> None:
        check_motion_mode(motion)
        self.motion, self.gui = motion, gui
        self.machine: OrthoglideMachine | None = None
        self.sim: Simulator | None = None

    def start(self, rows: np.ndarray, machines: MachineParams) -> None:
        try:
            from orthoglide_env.sim.pybullet import OrthoglideMachine
            from orthoglide_env.sim.simulator import Simulator
        except ImportError as exc:
            raise ImportError(f"the pybullet backend is not available ({exc}); use "
                              "backend='exact'") from exc
        if self.sim is None:
            self.sim = Simulator(gui=self.gui)
        try:
            machine = OrthoglideMachine(machines[0], [], sim=self.sim)
        except BaseException:
            # The new machine took the old one's place in the client: the episode before
            # goes on, built again where it was.
            if self.machine is not None:
                self.machine.rebuild()
            raise
        self.machine = machine

    def move(self, rows: np.ndarray, rho: np.ndarray) -> None:
        self._require().move(rho[0], self.motion)

    def set_gauges(self, rows: np.ndarray, gauges: GaugeArray, mounted: np.ndarray) -> None:
        self._require().set_gauges([g for g, on in zip(gauges[0].to_gauges(), mounted[0],
                                                       strict=True) if on])

    def look(self, rows: np.ndarray, machines: MachineParams, gauges: GaugeArray,
             rho: np.ndarray, tcp: np.ndarray, engaged: np.ndarray) -> Sight:
        machine = self._require()
        mounted = np.isfinite(gauges.origin[0, :, 0])  # the simulator holds these, in order
        t = np.full(mounted.shape, np.nan)
        pressed = np.zeros(mounted.shape, dtype=bool)
        if mounted.any():
            t[mounted] = machine.gauge_distances()
            pressed[mounted] = pressed_past_travel(machine.gauge_array,
                                                   *machine.target_boxes())
        return Sight(t[None], pressed[None], machine.collision_mask()[None], machine.tcp()[None])

    def encoders(self, rows: np.ndarray, rho: np.ndarray, actual: np.ndarray | None = None
                 ) -> np.ndarray:
        joints = np.asarray(self._require().encoders(), dtype=np.float64)[None]
        # The servo's residue is the motor's; the rest of the way is the drive's, unseen.
        return joints if actual is None else rho + (joints - actual)

    def render(self) -> np.ndarray:
        """A TinyRenderer picture of the machine and its stands (no window needed)."""
        return self._require().render()

    def _require(self) -> OrthoglideMachine:
        if self.machine is None:
            raise RuntimeError("call reset() before using the environment")
        return self.machine

    def close(self) -> None:
        self.machine = None
        if self.sim is not None:
            self.sim.close()
            self.sim = None
