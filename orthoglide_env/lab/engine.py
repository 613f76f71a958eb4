"""The lab's rules on a batch of episodes: one implementation for one lab and for many.

``OrthoglideLab-v0`` (:mod:`orthoglide_env.envs.lab`, whose docstring is the spec) runs a
:class:`LabBatch` of one episode; its native vector env (:mod:`orthoglide_env.envs.lab_vector`)
runs one of N.  Every rule (refusals, the time table, gauge handling, overtravel,
readings, the tracker, collisions, termination, rewards) is written once here, on arrays
whose first axis is the episode, and every random draw comes from the episode's own
stream in the order a lone lab draws it: the batched numbers equal the lone lab's to the
last bit.  The machines themselves are behind :class:`LabMachines`: the exact model
(:class:`ExactMachines`, any batch) or a PyBullet machine (:class:`SimulatedMachine`,
a batch of one).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Any, NamedTuple, Protocol

import numpy as np
from gymnasium import spaces

from orthoglide_env.envs.backend import ExactMachine, MachineBackend
from orthoglide_env.instruments.gauges import (
    DEFAULT_TRAVEL,
    NOISE_FLOOR,
    Gauge,
    GaugeArray,
    GaugeNoise,
    Status,
    check_noise,
    install_array,
    installation_errors,
    pressed_past_travel,
    readings_from_distances,
    status_of,
)
from orthoglide_env.lab.operations import (
    OP_NAMES,
    PAPER_SLOTS,
    SLOT_NAMES,
    SLOTS,
    TIME,
    TRACKER_DISTANCE,
    Op,
)
from orthoglide_env.model.collisions import PAIR_NAMES, collision_names
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import (
    AXIS_NAMES,
    ERROR_NAMES,
    ErrorPreset,
    MachineParams,
    check_rho,
    get_preset,
)
from orthoglide_env.model.kinematics import UnreachableError, direct
from orthoglide_env.model.reading_model import (
    Design,
    ParameterSpace,
    Spec,
    TrackerAxis,
    default_scales,
    jacobian,
    station_of,
)
from orthoglide_env.scoring import predicted_tcp_frames, score

REWARDS: tuple[str, ...] = ("time", "accuracy", "information")
#: The accuracy reward counts the final TCP error (after the best-fit rigid motion) in
#: units of this many mm, and time in hours: -error/unit - time_weight * hours.
ACCURACY_UNIT_MM: float = 0.01
ENCODER_MARGIN: float = 1.0
#: Operations that put the machine somewhere and read it.
_READS: tuple[Op, ...] = (Op.MOVE, Op.REMOUNT)


@dataclass(frozen=True)
class Record:
    """One reading the lab wrote down: which instrument, which mounting, where, what."""

    spec: Spec  # a gauge's slot, or one coordinate of the tracker
    mounting: str
    rho: tuple[float, float, float]
    reading: float
    step: int
    time_s: float  # lab time when it was read


Estimator = Callable[[list[Record], float], MachineParams]


@dataclass(frozen=True)
class LabSettings:
    """A lab's checked construction arguments (see the lab env's docstring)."""

    preset: ErrorPreset
    noise: GaugeNoise
    backend: str
    stands: int
    tracker: bool
    tracker_sigma: float
    budget_s: float
    reward: str
    estimator: Estimator | None
    time_weight: float
    success_mm: float
    travel: float
    design: MachineDesign = PROTOTYPE

    @classmethod
    def check(cls, errors: str, gauge_sigma: float, gauge_resolution: float, backend: str,
              stands: int, tracker: bool, tracker_sigma: float, budget_s: float, reward: str,
              estimator: Estimator | None, time_weight: float, success_mm: float,
              travel: float | None, design: MachineDesign | None = None) -> LabSettings:
        """The settings, or ``ValueError`` naming the first bad argument.  ``design``: the
        machines' design (default the prototype); ``travel`` None: its gauge travel."""
        design = PROTOTYPE if design is None else design
        if not isinstance(design, MachineDesign):
            raise ValueError(f"design must be a MachineDesign, got {type(design).__name__}")
        if design.slot_positions != PROTOTYPE.slot_positions:
            raise ValueError("the lab's slot indices are the prototype's slot catalogue: a "
                             f"design's slot_positions must be {list(PROTOTYPE.slot_positions)}")
        travel = design.gauge_travel if travel is None else travel
        preset = get_preset(errors)
        if backend not in ("exact", "pybullet"):
            raise ValueError(f"unknown backend '{backend}'; choose from ['exact', 'pybullet']")
        if reward not in REWARDS:
            raise ValueError(f"unknown reward '{reward}'; choose from {list(REWARDS)}")
        if reward == "accuracy" and estimator is None:
            raise ValueError("reward 'accuracy' needs an estimator: records -> machine, e.g. "
                             "calibrators.experiment.make_estimator()")
        if not 1 <= int(stands) <= len(SLOTS):
            raise ValueError(f"stands must be between 1 and {len(SLOTS)}, got {stands}")
        for name, value in (("budget_s", budget_s), ("success_mm", success_mm),
                            ("tracker_sigma", tracker_sigma), ("travel", travel)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if not (np.isfinite(time_weight) and time_weight >= 0):
            raise ValueError(f"time_weight must be a number >= 0, got {time_weight}")
        noise = check_noise(gauge_sigma, gauge_resolution, travel)
        return cls(preset, noise, backend, int(stands), bool(tracker), tracker_sigma, budget_s,
                   reward, estimator, time_weight, success_mm, float(travel), design)

    def spaces(self) -> tuple[spaces.Dict, spaces.Dict]:
        """One lab's action and observation spaces."""
        n = self.stands
        action_space = spaces.Dict({
            "op": spaces.Discrete(len(Op)),
            "rho": spaces.Box(self.design.rho_min, self.design.rho_max, shape=(3,),
                              dtype=np.float64),
            "stand": spaces.Discrete(n),
            "slot": spaces.Discrete(len(SLOTS)),
        })
        observation_space = spaces.Dict({
            "gauges": spaces.Box(-self.travel, self.travel, shape=(n,), dtype=np.float64),
            "valid": spaces.MultiBinary(n),
            "engaged": spaces.MultiBinary(n),
            "slot": spaces.MultiDiscrete([len(SLOTS) + 1] * n),
            "mounting": spaces.Box(0.0, 1e6, shape=(n,), dtype=np.float64),
            "joints": spaces.Box(self.design.rho_min - ENCODER_MARGIN,
                                 self.design.rho_max + ENCODER_MARGIN, shape=(3,),
                                 dtype=np.float64),
            "tracker": spaces.Box(-1e5, 1e5, shape=(3,), dtype=np.float64),
            "tracker_valid": spaces.MultiBinary(1),
            "time": spaces.Box(0.0, self.budget_s + self.longest_step(), shape=(1,),
                               dtype=np.float64),
        })
        return action_space, observation_space

    def longest_step(self) -> float:
        """The most one operation can cost (a re-mount from the far corner, the tracker, and
        every stand pushed past its travel): the clock never passes budget + this."""
        far = TIME.move(np.full(3, self.design.rho_min), np.full(3, self.design.rho_max))
        return far + TIME.remount_s + TIME.tracker_point_s + TIME.overtravel_s * self.stands


# -- actions -------------------------------------------------------------------------------
def check_actions(action: Any, shape: tuple[int, ...], stands: int,
                  rows: np.ndarray | None = None, design: MachineDesign = PROTOTYPE
                  ) -> tuple[np.ndarray, ...]:
    """``op``, ``rho``, ``stand``, ``slot`` of a lab action (``shape ()``) or of a batch of
    them (``shape (N,)``, each field with the batch axis first), as arrays, or
    ``ValueError`` naming the field (and the env).  ``rows``: the envs whose action is used
    (the others are not checked); ``design``: whose control limits bound ``rho``."""
    if not isinstance(action, dict) or set(action) != {"op", "rho", "stand", "slot"}:
        raise ValueError("action must be a dict with keys op, rho, stand, slot")
    used = np.ones(shape, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    op = _integers(action["op"], "op", len(Op), shape, used)
    stand = _integers(action["stand"], "stand", stands, shape, used)
    slot = _integers(action["slot"], "slot", len(SLOTS), shape, used)
    moving = used & (op == Op.MOVE)
    rho = np.zeros((*shape, 3))
    if moving.any():
        raw = action["rho"]
        try:
            given = np.array(raw, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action rho must be 3 numbers (mm), got {raw!r}") from None
        if given.shape != (*shape, 3):
            raise ValueError(f"action rho must have shape {(*shape, 3)}, got {given.shape}")
        rho[moving] = given[moving]
        try:
            check_rho(rho[moving], design=design)
        except ValueError as exc:
            if shape:
                bad = next(i for i in np.flatnonzero(moving)
                           if not _valid_rho(rho[i], design))
                raise ValueError(f"action rho of env {bad}: {exc}") from None
            raise
    return op, rho, stand, slot


def _valid_rho(rho: np.ndarray, design: MachineDesign) -> bool:
    try:
        check_rho(rho, design=design)
    except ValueError:
        return False
    return True


def _integers(value: Any, name: str, size: int, shape: tuple[int, ...], used: np.ndarray
              ) -> np.ndarray:
    """An action's integer field: integers (not booleans) in ``[0, size)`` of ``shape``."""
    array = np.asarray(value) if isinstance(value, int | np.integer | np.ndarray) else None
    if array is None or array.dtype.kind not in "iu" or array.shape != shape:
        if shape:
            raise ValueError(f"action {name} must be an integer array of shape {shape}, got "
                             f"{value!r}")
        raise ValueError(f"action {name} must be an integer in [0, {size}), got {value!r}")
    bad = used & ((array < 0) | (array >= size))
    if bad.any():
        where = f" of env {np.flatnonzero(bad)[0]}" if shape else ""
        shown = array[np.flatnonzero(bad)[0]] if shape else value
        raise ValueError(f"action {name}{where} must be an integer in [0, {size}), got "
                         f"{shown!r}")
    return np.where(used, array, 0).astype(np.int64)


# -- the notebook and its information ---------------------------------------------------------
class Notebook:
    """One episode's lab notebook: its records, every installation (truth, for scoring),
    and the information the records carry about the machine's errors."""

    def __init__(self, gauge_sigma: float, tracker_sigma: float,
                 design: MachineDesign = PROTOTYPE) -> None:
        self.records: list[Record] = []
        self._design = design
        self._installed: dict[str, Gauge] = {}
        #: The first installations, as mounting names and the row of a batch of gauge sets:
        #: turned into gauges when asked for (a sweep's scoring never asks).
        self._first: tuple[list[str], GaugeArray, int] | None = None
        self._gauge_sigma = max(gauge_sigma, NOISE_FLOOR)
        self._tracker_sigma = tracker_sigma
        # Per mounting: count, sum and sum of outer products of its Jacobian rows, names.
        self._sums: dict[str, tuple[int, Any, Any, tuple[str, ...]]] = {}
        self._informed = 0  # records already in the sums
        self._logdet = 0.0

    def install(self, names: list[str], gauges: GaugeArray, row: int) -> None:
        """The episode's first installations: ``names``' gauges are row ``row`` of
        ``gauges``."""
        self._installed, self._first = {}, (names, gauges, row)

    @property
    def installed(self) -> dict[str, Gauge]:
        """Every installation by mounting name, in mounting order (truth, for scoring)."""
        if self._first is not None:
            names, gauges, row = self._first
            self._first = None
            self._installed = dict(zip(names, gauges[row].to_gauges(), strict=True))
        return self._installed

    def design_key(self) -> tuple:
        """What the information depends on: every record's mounting and posture (a lab's
        mounting name holds its slot, hence its instrument)."""
        return tuple((r.mounting, r.rho) for r in self.records)

    def _add_information(self, records: list[Record]) -> None:
        """Add the records' rows of the Jacobian (at the nominal machine, per unit of each
        parameter's scale, per unit of noise; one batched call) to their mountings' sums:
        the information of a mounting, its zero eliminated, is ``S2 - S1 S1^T / n``."""
        design = Design.of([r.mounting for r in records], [r.spec for r in records],
                           np.array([r.rho for r in records]), self._design)
        space = design.space
        rows = jacobian(np.zeros(len(space)), design, np.ones(len(space), bool),
                        default_scales(space))
        for record, row, m in zip(records, rows, design.mounting, strict=True):
            sigma = (self._tracker_sigma if isinstance(record.spec, TrackerAxis)
                     else self._gauge_sigma)
            # The mounting's own columns: the machine's errors and its instrument's.
            mine = _mounting_columns(space, m)
            names = tuple(space.names[c] for c in mine)
            row = row[mine] / sigma
            n, s1, s2, _ = self._sums.get(record.mounting, (0, 0.0, 0.0, names))
            self._sums[record.mounting] = (n + 1, s1 + row, s2 + np.outer(row, row), names)

    def information(self) -> tuple[np.ndarray, list[str]]:
        """The records' information about every parameter they involve, in units of each
        parameter's scale, and the parameters' names."""
        if self._informed < len(self.records):
            self._add_information(self.records[self._informed:])
        self._informed = len(self.records)
        names = list(ERROR_NAMES)
        for _, _, _, mine in self._sums.values():
            names += [n for n in mine if n not in names]
        info = np.zeros((len(names), len(names)))
        for n, s1, s2, mine in self._sums.values():
            idx = [names.index(x) for x in mine]
            info[np.ix_(idx, idx)] += s2 - np.outer(s1, s1) / n
        return info, names

    def share_information(self, other: Notebook) -> None:
        """Take the information sums of ``other``, whose records read what this notebook's
        read where they read it (:meth:`design_key`), both summed in one go: the same
        numbers, computed once."""
        self._sums, self._informed = dict(other._sums), other._informed

    def update_logdet(self) -> float:
        """The gain in log det(I + F) since the last call."""
        info, _ = self.information()
        logdet = float(np.linalg.slogdet(np.eye(len(info)) + info)[1])
        gain, self._logdet = logdet - self._logdet, logdet
        return gain

    def predicted_tcp_rigid_mm(self) -> float:
        """TCP error RMS after the best-fit rigid motion that the records' information
        predicts (at the nominal machine, a priori sizes from the realistic preset)."""
        info, names = self.information()
        space = ParameterSpace()
        n = len(ERROR_NAMES)
        scale = np.concatenate([default_scales(space), np.ones(len(names) - n)])
        posterior = np.linalg.inv(np.eye(len(info)) + info)[:n, :n]
        covariance = posterior * np.outer(scale[:n], scale[:n])
        return predicted_tcp_frames(MachineParams(design=self._design), covariance).rigid.rms


def _mounting_columns(space: ParameterSpace, mounting: int) -> list[int]:
    """Columns of ``space`` a reading of ``mounting`` depends on: the machine's errors and
    its own instrument's parameters (a stand's four, a tracker station's three)."""
    names = space.names
    prefix = space.mountings[mounting]
    if isinstance(space.specs[mounting], TrackerAxis):
        prefix = station_of(prefix)
    return list(range(len(ERROR_NAMES))) + [
        c for c in range(len(ERROR_NAMES), len(names))
        if names[c].rsplit(".", 1)[0] == prefix]


def predicted_many(notebooks: Sequence[Notebook]) -> list[float]:
    """:meth:`Notebook.predicted_tcp_rigid_mm` of each notebook; notebooks whose
    information is not summed yet and whose records share a design share one computation
    (a fixed plan on many machines reads the same design on each)."""
    out: list[float] = []
    done: dict[tuple, tuple[Notebook, float]] = {}
    for book in notebooks:
        if book._informed:
            out.append(book.predicted_tcp_rigid_mm())
            continue
        key = book.design_key()
        if key in done:
            first, value = done[key]
            book.share_information(first)
        else:
            value = book.predicted_tcp_rigid_mm()
            done[key] = (book, value)
        out.append(value)
    return out


# -- the machines -------------------------------------------------------------------------------
class Sight(NamedTuple):
    """What the machines of some episodes show at their postures (one row per episode)."""

    t: np.ndarray  # (R, stands) ray distance of each stand's gauge; NaN where none
    pressed: np.ndarray  # (R, stands) the target bar presses the gauge past its travel
    crashed: np.ndarray  # (R, pairs) crash pairs in contact
    tcp: np.ndarray  # (R, 3) true TCP


class LabMachines(Protocol):
    """The machines of a batch of lab episodes.  The batch keeps the machines' errors,
    postures and gauges; a backend with machines of its own follows every change."""

    def start(self, rows: np.ndarray, machines: MachineParams) -> None:
        """New machines for episodes ``rows``, at Zero."""

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

    def encoders(self, rows: np.ndarray, rho: np.ndarray) -> np.ndarray:
        """Encoder readings (R, 3) of the machines of ``rows`` (commanded at ``rho``)."""

    def close(self) -> None:
        """Release every resource."""


class ExactMachines:
    """The exact model: a machine is its errors and posture, so there is nothing to keep
    in step; one :class:`~orthoglide_env.envs.backend.ExactMachine` computes any batch."""

    def start(self, rows: np.ndarray, machines: MachineParams) -> None:
        """Nothing to build."""

    def move(self, rows: np.ndarray, rho: np.ndarray) -> None:
        """Nothing to drive: the batch keeps the postures."""

    def set_gauges(self, rows: np.ndarray, gauges: GaugeArray, mounted: np.ndarray) -> None:
        """Nothing to install: the batch keeps the gauges."""

    def look(self, rows: np.ndarray, machines: MachineParams, gauges: GaugeArray,
             rho: np.ndarray, tcp: np.ndarray, engaged: np.ndarray) -> Sight:
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

    def encoders(self, rows: np.ndarray, rho: np.ndarray) -> np.ndarray:
        return rho.copy()

    def close(self) -> None:
        """Nothing to release."""


class SimulatedMachine:
    """One PyBullet machine (a batch of one episode)."""

    def __init__(self) -> None:
        self.machine: MachineBackend | None = None

    def start(self, rows: np.ndarray, machines: MachineParams) -> None:
        from orthoglide_env.sim.pybullet import OrthoglideMachine

        self.close()
        self.machine = OrthoglideMachine(machines[0], [])

    def move(self, rows: np.ndarray, rho: np.ndarray) -> None:
        self._require().move(rho[0])

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
            pressed[mounted] = pressed_past_travel(machine.gauges, *machine.target_boxes())
        return Sight(t[None], pressed[None], machine.collision_mask()[None], machine.tcp()[None])

    def encoders(self, rows: np.ndarray, rho: np.ndarray) -> np.ndarray:
        return np.asarray(self._require().encoders(), dtype=np.float64)[None]

    def _require(self) -> MachineBackend:
        if self.machine is None:
            raise RuntimeError("call reset() before using the environment")
        return self.machine

    def close(self) -> None:
        if self.machine is not None:
            self.machine.close()
            self.machine = None


# -- the batch ----------------------------------------------------------------------------------
@dataclass
class StepResult:
    """One step of episodes ``rows`` (one entry per row)."""

    obs: dict[str, np.ndarray]
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    op: np.ndarray
    seconds: np.ndarray
    overtravel: list[list[str]]
    collision: list[str]
    refused: list[str]
    predicted: np.ndarray  # predicted TCP error at the end, NaN where the episode goes on
    success: np.ndarray  # at the end: the predicted error meets the lab's target

    def info(self, i: int) -> dict[str, Any]:
        """Row ``i``'s info, as the lab env gives it."""
        info = step_info(OP_NAMES[self.op[i]], float(self.seconds[i]), self.overtravel[i],
                         self.collision[i])
        info["refused"] = self.refused[i]
        if self.terminated[i] or self.truncated[i]:
            info.update(is_success=bool(self.success[i]),
                        predicted_tcp_rigid_mm=float(self.predicted[i]))
        return info


def step_info(op: str, seconds: float, overtravel: list[str], collision: str
              ) -> dict[str, Any]:
    return {"op": op, "step_time_s": seconds, "overtravel": overtravel, "collision": collision}


class LabBatch:
    """The state of ``size`` lab episodes and the lab's rules applied to any of them.

    Episodes are rows; each has its random stream (``streams``), given at its reset.  The
    truth for scoring is on ``machines`` and each notebook's ``installed``; agents see
    observations and ``notebooks[i].records`` only."""

    def __init__(self, settings: LabSettings, size: int, backend: LabMachines) -> None:
        self.settings, self.size, self.backend = settings, size, backend
        n, s = size, settings.stands
        self.streams: list[np.random.Generator | None] = [None] * n
        self.machines: MachineParams | None = None
        self.rho = np.zeros((n, 3))
        self.tcp = np.full((n, 3), np.nan)  # the TCP at ``rho`` where solved, else NaN
        self.time = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.mounts = np.zeros(n, dtype=np.int64)  # mountings so far (names new ones)
        self.slot = np.full((n, s), -1, dtype=np.int64)  # -1: not mounted
        self.engaged = np.zeros((n, s), dtype=bool)
        self.faulted = np.zeros((n, s), dtype=bool)  # pushed past its travel
        self.count = np.zeros((n, s), dtype=np.int64)  # times each stand was mounted
        self.mounting: list[list[str]] = [[""] * s for _ in range(n)]
        self.gauges = _unmounted((n, s), settings.travel)
        self.notebooks = [self._notebook() for _ in range(n)]
        self.tracker_rotation = np.zeros((n, 3, 3))
        self.tracker_position = np.zeros((n, 3))
        self.tracker_reading = np.zeros((n, 3))

    def _notebook(self) -> Notebook:
        return Notebook(self.settings.noise.effective_sigma, self.settings.tracker_sigma,
                        self.settings.design)

    def require(self) -> MachineParams:
        if self.machines is None:
            raise RuntimeError("call reset() before using the environment")
        return self.machines

    # -- reset --------------------------------------------------------------------------------
    def reset(self, rows: np.ndarray, streams: list[np.random.Generator],
              machine: MachineParams | None = None) -> dict[str, np.ndarray]:
        """New episodes for ``rows`` (each drawing from its stream in ``streams``, or on
        ``machine`` when given): the stands at the paper's slots, zeroed at Zero, and the
        first reading.  Their observation rows."""
        settings = self.settings
        first = [int(s) for s in PAPER_SLOTS[: settings.stands]]
        drawn, rotations, positions, errors = [], [], [], []
        for stream in streams:
            drawn.append(settings.preset.sample(stream, settings.design) if machine is None
                         else machine)
            rotations.append(_random_rotation(stream))
            direction = stream.normal(size=3)
            positions.append(TRACKER_DISTANCE * direction / np.linalg.norm(direction))
            errors.append(installation_errors(len(first), settings.preset, stream))
        machines = MachineParams.stack(drawn)
        installed = _installed(machines, [SLOTS[s] for s in first], settings.travel,
                               np.stack(errors))
        # Nothing above is stored: a failure leaves every episode as it was.
        self.machines = machines if self.machines is None or len(rows) == self.size else (
            _with_rows(self.machines, rows, machines))
        self.backend.start(rows, machines)
        for i, stream in zip(rows, streams, strict=True):
            self.streams[i] = stream
        self.rho[rows] = 0.0
        self.tcp[rows] = np.nan
        self.time[rows] = 0.0
        self.steps[rows] = 0
        self.mounts[rows] = len(first)
        self.slot[rows] = -1
        self.slot[rows, : len(first)] = first
        self.engaged[rows] = False
        self.engaged[rows, : len(first)] = True
        self.faulted[rows] = False
        self.count[rows] = 0
        self.count[rows, : len(first)] = 1
        self.gauges = _with_gauges(self.gauges, rows[:, None], np.arange(settings.stands),
                                   _unmounted((len(rows), settings.stands), settings.travel))
        self.gauges = _with_gauges(self.gauges, rows[:, None], np.arange(len(first)), installed)
        names = [SLOT_NAMES[s] for s in first]
        for r, i in enumerate(rows):
            self.mounting[i] = names + [""] * (settings.stands - len(first))
            book = self._notebook()
            book.install(names, installed, r)
            self.notebooks[i] = book
        self.tracker_rotation[rows] = rotations
        self.tracker_position[rows] = positions
        self._sync(rows)
        values = self._read(rows, np.zeros(len(rows)), self._look(rows))
        return self.observation(rows, values)

    # -- step ---------------------------------------------------------------------------------
    def step(self, rows: np.ndarray, op: np.ndarray, rho: np.ndarray, stand: np.ndarray,
             slot: np.ndarray) -> StepResult:
        """Apply each row's checked action (see :func:`check_actions`) to its episode."""
        settings = self.settings
        self.require()
        refused, reached = self._refusals(rows, op, rho, stand, slot)
        ok = np.array([not r for r in refused], dtype=bool)
        moves, remounts = ok & (op == Op.MOVE), ok & (op == Op.REMOUNT)
        flicks = ok & ((op == Op.LIFT) | (op == Op.ENGAGE))
        # New installations first (they draw from the streams before the readings do, and
        # may fail): nothing is stored before they are made.
        mounted = self._installations(rows[remounts], stand[remounts], slot[remounts])
        seconds = np.where(ok, 0.0, TIME.lift_s)
        seconds[flicks] = TIME.lift_s
        if moves.any():
            tracker = TIME.tracker_point_s if settings.tracker else 0.0
            seconds[moves] = TIME.move(self.rho[rows[moves]], rho[moves]) + tracker
            self.rho[rows[moves]] = rho[moves]
            self.tcp[rows[moves]] = reached[moves]
            self.backend.move(rows[moves], rho[moves])
        self.engaged[rows[flicks], stand[flicks]] = op[flicks] == Op.ENGAGE
        if remounts.any():
            seconds[remounts] = TIME.move(self.rho[rows[remounts]], np.zeros(3)) + TIME.remount_s
            self.rho[rows[remounts]] = 0.0
            self.tcp[rows[remounts]] = np.nan
            self.backend.move(rows[remounts], self.rho[rows[remounts]])
            self._mount(rows[remounts], stand[remounts], slot[remounts], mounted)
            self._sync(rows[remounts])
        reads = ok & np.isin(op, _READS)
        presses = reads | (ok & (op == Op.ENGAGE))
        looks = np.isin(op, _READS) | presses  # a refused move still checks for a crash
        sight = self._look(rows[looks])
        at = np.cumsum(looks) - 1  # row of each looked-at episode in ``sight``
        overtravel: list[list[str]] = [[] for _ in rows]
        if presses.any():
            new = (sight.pressed[at[presses]] & self.engaged[rows[presses]]
                   & ~self.faulted[rows[presses]] & (self.slot[rows[presses]] >= 0))
            self.faulted[rows[presses]] |= new
            seconds[presses] += TIME.overtravel_s * np.count_nonzero(new, axis=-1)
            for r, hit in zip(np.flatnonzero(presses), new, strict=True):
                overtravel[r] = [f"stand {k} ({self.mounting[rows[r]][k]})"
                                 for k in np.flatnonzero(hit)]
        values = np.full((len(rows), settings.stands), np.nan)
        if reads.any():
            values[reads] = self._read(rows[reads], seconds[reads], Sight(
                *(part[at[reads]] for part in sight)))
        self.time[rows] += seconds
        self.steps[rows] += 1
        collision = [""] * len(rows)
        crashed = np.zeros(len(rows), dtype=bool)
        crashed[looks] = sight.crashed.any(axis=-1)
        for r in np.flatnonzero(crashed & np.isin(op, _READS)):
            collision[r] = ", ".join(collision_names(sight.crashed[at[r]]))
        terminated = (op == Op.STOP) | np.array([bool(c) for c in collision], dtype=bool)
        truncated = ~terminated & (self.time[rows] >= settings.budget_s)
        ended = terminated | truncated
        reward = self._rewards(rows, seconds, ended)
        predicted = np.full(len(rows), np.nan)
        predicted[ended] = predicted_many([self.notebooks[i] for i in rows[ended]])
        return StepResult(self.observation(rows, values, reads), reward, terminated, truncated,
                          op, seconds, overtravel, collision, refused, predicted,
                          ended & (predicted <= settings.success_mm))

    def _refusals(self, rows: np.ndarray, op: np.ndarray, rho: np.ndarray, stand: np.ndarray,
                  slot: np.ndarray) -> tuple[list[str], np.ndarray]:
        """Why each well-formed operation cannot be done ("" when it can): a stand that is
        not mounted cannot be lifted or engaged, a slot holds one stand, and the machine
        cannot be driven where it cannot assemble; and the TCP (R, 3) where each move
        takes it (NaN where none), solved to know that."""
        out = [""] * len(rows)
        reached = np.full((len(rows), 3), np.nan)
        stands = self.slot[rows]
        flick = (op == Op.LIFT) | (op == Op.ENGAGE)
        for r in np.flatnonzero(flick & (stands[np.arange(len(rows)), stand] < 0)):
            out[r] = f"stand {stand[r]} is not mounted"
        others = (stands == slot[:, None]) & (np.arange(self.settings.stands) != stand[:, None])
        for r in np.flatnonzero((op == Op.REMOUNT) & others.any(axis=-1)):
            out[r] = f"slot {SLOT_NAMES[slot[r]]} already holds a stand"
        moves = np.flatnonzero(op == Op.MOVE)
        if len(moves):
            reached[moves] = assembled(self.require()[rows[moves]], rho[moves])
            for r in moves[np.isnan(reached[moves, 0])]:
                out[r] = f"the machine cannot assemble at rho = {rho[r].tolist()}"
        return out, reached

    def _installations(self, rows: np.ndarray, stand: np.ndarray, slot: np.ndarray
                       ) -> GaugeArray | None:
        """New installations of stands ``stand`` at ``slot`` on the machines of ``rows``
        (drawn from their streams), zeroed at Zero: one gauge per row, (R,)."""
        if not len(rows):
            return None
        errors = np.stack([installation_errors(1, self.settings.preset, self.streams[i])
                           for i in rows])
        per_row: list[GaugeArray] = [None] * len(rows)  # type: ignore[list-item]
        for value in np.unique(slot):
            mine = np.flatnonzero(slot == value)
            try:
                part = _installed(self.require()[rows[mine]], [SLOTS[value]],
                                  self.settings.travel, errors[mine])
            except ValueError:
                raise ValueError(f"slot {SLOT_NAMES[value]} cannot be reached on this "
                                 "machine") from None
            for j, r in enumerate(mine):
                per_row[r] = part[j]
        return GaugeArray.stack(per_row)

    def _mount(self, rows: np.ndarray, stand: np.ndarray, slot: np.ndarray,
               gauges: GaugeArray) -> None:
        """Store the installations of :meth:`_installations` (one gauge per row)."""
        self.gauges = _with_gauges(self.gauges, rows, stand, gauges)
        self.mounts[rows] += 1
        self.slot[rows, stand] = slot
        self.engaged[rows, stand] = True
        self.faulted[rows, stand] = False
        self.count[rows, stand] += 1
        for r, (i, k, s) in enumerate(zip(rows, stand, slot, strict=True)):
            name = f"{SLOT_NAMES[s]}#{self.mounts[i]}"
            self.mounting[i][k] = name
            self.notebooks[i].installed[name] = gauges[r].to_gauges()[0]

    def _sync(self, rows: np.ndarray) -> None:
        """Hand the backend the gauges of every mounted stand of ``rows``."""
        self.backend.set_gauges(rows, self.gauges[rows], self.slot[rows] >= 0)

    def _look(self, rows: np.ndarray) -> Sight:
        if not len(rows):
            stands = self.settings.stands
            return Sight(np.zeros((0, stands)), np.zeros((0, stands), dtype=bool),
                         np.zeros((0, len(PAIR_NAMES)), dtype=bool), np.zeros((0, 3)))
        if len(rows) == self.size:  # every episode: no copies
            sight = self.backend.look(rows, self.require(), self.gauges, self.rho, self.tcp,
                                      self.engaged)
        else:
            sight = self.backend.look(rows, self.require()[rows], self.gauges[rows],
                                      self.rho[rows], self.tcp[rows], self.engaged[rows])
        self.tcp[rows] = sight.tcp
        return sight

    def _read(self, rows: np.ndarray, pending: np.ndarray, sight: Sight) -> np.ndarray:
        """Read every engaged, working gauge (and the tracker) of ``rows``: noisy values per
        stand, NaN where there is none; every reading goes to the notebooks.  ``pending``:
        the seconds of the step so far (the readings are written at its end)."""
        settings = self.settings
        gauges = self.gauges if len(rows) == self.size else self.gauges[rows]
        mounted = self.slot[rows] >= 0
        ideal = readings_from_distances(gauges, sight.t)
        good = status_of(gauges, sight.t) == Status.VALID
        draws = np.zeros(ideal.shape)
        counts, full = mounted.sum(axis=1).tolist(), mounted.all(axis=1).tolist()
        for r, i in enumerate(rows.tolist()):
            # A lone lab draws one number per mounted gauge, then the tracker's three.
            stream = self.streams[i]
            drawn = settings.noise.draws(stream, (counts[r],))  # type: ignore[arg-type]
            if full[r]:
                draws[r] = drawn
            else:
                draws[r, mounted[r]] = drawn
            if settings.tracker:
                noise = stream.normal(0.0, settings.tracker_sigma, 3)  # type: ignore[union-attr]
                self.tracker_reading[i] = (self.tracker_rotation[i] @ sight.tcp[r]
                                           + self.tracker_position[i] + noise)
        noisy = settings.noise.applied(ideal, draws)
        valid = good & mounted & self.engaged[rows] & ~self.faulted[rows]
        values = np.where(valid, noisy, np.nan)
        # The notebooks, written from plain lists (one Record per reading).
        index, rho = rows.tolist(), [tuple(p) for p in self.rho[rows].tolist()]
        steps, stamps = self.steps[rows].tolist(), (self.time[rows] + pending).tolist()
        read, slots = values.tolist(), self.slot[rows].tolist()
        for r, k in zip(*(part.tolist() for part in np.nonzero(valid)), strict=True):
            i = index[r]
            self.notebooks[i].records.append(Record(SLOTS[slots[r][k]], self.mounting[i][k],
                                                    rho[r], read[r][k], steps[r], stamps[r]))
        if settings.tracker:
            tracker = self.tracker_reading[rows].tolist()
            for r, i in enumerate(index):
                self.notebooks[i].records.extend(
                    Record(TrackerAxis(c), f"tracker.{AXIS_NAMES[c]}", rho[r], tracker[r][c],
                           steps[r], stamps[r]) for c in range(3))
        return values

    # -- rewards and observations --------------------------------------------------------------
    def _rewards(self, rows: np.ndarray, seconds: np.ndarray, ended: np.ndarray) -> np.ndarray:
        settings = self.settings
        if settings.reward == "time":
            return -seconds
        if settings.reward == "information":
            # Each notebook sums its own information, step by step (a loop over episodes).
            gains = np.array([self.notebooks[i].update_logdet() for i in rows])
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(seconds > 0, gains / seconds, 0.0)
        reward = -settings.time_weight * seconds / 3600.0
        for r in np.flatnonzero(ended):
            reward[r] -= self.final_tcp_rigid_mm(int(rows[r])) / ACCURACY_UNIT_MM
        return reward

    def final_tcp_rigid_mm(self, row: int) -> float:
        """TCP error RMS after the best-fit rigid motion of the machine the estimator makes
        of episode ``row``'s records (scoring against the truth)."""
        truth = self.require()[row]
        try:
            estimate = self.settings.estimator(self.notebooks[row].records,  # type: ignore[misc]
                                               self.settings.noise.effective_sigma)
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            estimate = MachineParams(design=truth.design)
        return score(estimate, truth).tcp_after.rigid.rms

    def observation(self, rows: np.ndarray, values: np.ndarray,
                    fresh: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Observation rows of episodes ``rows`` whose gauges read ``values`` (NaN: none);
        ``fresh``: which of them read (and so read the tracker), default all."""
        fresh = np.ones(len(rows), dtype=bool) if fresh is None else fresh
        tracked = fresh & self.settings.tracker
        valid = np.isfinite(values)
        slot = self.slot[rows]
        return {
            "gauges": np.where(valid, values, 0.0),
            "valid": valid.astype(np.int8),
            "engaged": (self.engaged[rows] & ~self.faulted[rows]).astype(np.int8),
            "slot": np.where(slot >= 0, slot, len(SLOTS)).astype(np.int64),
            "mounting": self.count[rows].astype(np.float64),
            "joints": self.backend.encoders(rows, self.rho[rows]),
            "tracker": np.where(tracked[:, None], self.tracker_reading[rows], 0.0),
            "tracker_valid": tracked.astype(np.int8)[:, None],
            "time": self.time[rows][:, None].copy(),
        }

    def true_gauges(self, row: int) -> list[Gauge]:
        """Every installation of episode ``row``, in mounting order (scoring only)."""
        return list(self.notebooks[row].installed.values())


def assembled(machines: MachineParams, rho: np.ndarray) -> np.ndarray:
    """The TCP (R, 3) of each machine of a batch at its ``rho`` (R, 3); NaN rows where it
    cannot be assembled."""
    try:
        return direct(machines, rho)
    except UnreachableError:
        pass
    out = np.full((len(rho), 3), np.nan)
    for r in range(len(rho)):
        with contextlib.suppress(UnreachableError):
            out[r] = direct(machines[r], rho[r])
    return out


def _installed(machines: MachineParams, specs: list, travel: float, errors: np.ndarray
               ) -> GaugeArray:
    """Gauges of ``specs`` installed on each machine with ``errors`` (R, G, 2, 3), slid to
    mid-travel and zeroed at Zero; ``ValueError`` when one misses its bar there."""
    gauges = install_array(specs, machines, travel=travel, errors=errors)
    return gauges.zeroed(ExactMachine(machines, gauges).gauge_distances())


def _unmounted(shape: tuple[int, int], travel: float) -> GaugeArray:
    """Gauges of stands that are not mounted: no ray (NaN), so nothing reads or presses."""
    return GaugeArray(origin=np.full((*shape, 3), np.nan), direction=np.full((*shape, 3), np.nan),
                      sign=np.ones(shape), travel=travel, zero=DEFAULT_TRAVEL / 2,
                      leg=SLOTS[0].leg, axis=SLOTS[0].axis, at=SLOTS[0].at)


def _with_gauges(array: GaugeArray, rows: np.ndarray, columns: np.ndarray, new: GaugeArray
                 ) -> GaugeArray:
    """A copy of ``array`` (E, S) with the gauges at ``[rows, columns]`` replaced by ``new``
    (of the indexed shape, or that shape with singleton axes)."""
    out = {}
    for f in fields(array):
        value = np.array(getattr(array, f.name))
        target = value[rows, columns]
        value[rows, columns] = np.reshape(getattr(new, f.name), target.shape)
        out[f.name] = value
    return GaugeArray(**out)


def _with_rows(machines: MachineParams, rows: np.ndarray, new: MachineParams) -> MachineParams:
    vector = machines.to_vector()
    vector[rows] = new.to_vector()
    return MachineParams.from_vector(vector, machines.design)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (a normalised normal quaternion)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
