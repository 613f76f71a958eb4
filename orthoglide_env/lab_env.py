"""The lab as a Gymnasium environment: an episode is a whole calibration experiment.

Where ``OrthoglideCalibration-v0`` only moves the machine, ``OrthoglideLab-v0`` lets an
agent do what a technician does: move and read, lift and engage gauges, re-mount a stand
at another slot, read a laser tracker, and say when it is done, each at the cost of the
lab's time table (:mod:`orthoglide_env.lab`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .backend import ExactMachine, MachineBackend
from .env import check_seed
from .gauges import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    DEFAULT_TRAVEL,
    NOISE_FLOOR,
    Gauge,
    Status,
    check_noise,
    exact_ray_distances,
    install,
    pressed_past_travel,
    readings_from_distances,
    status_of,
    zero_gauges,
)
from .geometry import (
    AXIS_NAMES,
    DEFAULT_PRESET,
    ERROR_NAMES,
    RHO_MAX,
    RHO_MIN,
    MachineParams,
    check_rho,
    check_validity,
    get_preset,
)
from .kinematics import UnreachableError, direct
from .lab import (
    OP_NAMES,
    PAPER_SLOTS,
    SLOT_NAMES,
    SLOTS,
    TIME,
    TRACKER_DISTANCE,
    TRACKER_SIGMA,
    Op,
)
from .reading_model import (
    Design,
    ParameterSpace,
    Spec,
    TrackerAxis,
    default_scales,
    jacobian,
    station_of,
)
from .scoring import predicted_tcp_frames, score

REWARDS: tuple[str, ...] = ("time", "accuracy", "information")
#: The accuracy reward counts the final TCP error (after the best-fit rigid motion) in
#: units of this many mm, and time in hours: -error/unit - time_weight * hours.
ACCURACY_UNIT_MM: float = 0.01
ENCODER_MARGIN: float = 1.0


@dataclass(frozen=True)
class Record:
    """One reading the lab wrote down: which instrument, which mounting, where, what."""

    spec: Spec  # a gauge's slot, or one coordinate of the tracker
    mounting: str
    rho: tuple[float, float, float]
    reading: float
    step: int
    time_s: float  # lab time when it was read


@dataclass
class Stand:
    """A gauge stand: where it is mounted, whether its plunger is down, its installation."""

    slot: int = -1  # index in SLOTS, -1: not mounted
    engaged: bool = False
    faulted: bool = False  # pushed past its travel: reads nothing until re-mounted
    mounting: str = ""
    gauge: Gauge | None = None
    count: int = 0  # how many times this stand was mounted


Estimator = Callable[[list[Record], float], MachineParams]


class OrthoglideLabEnv(gym.Env):
    """A calibration lab around a virtual Orthoglide: gauge stands, a tracker, a clock.

    Each episode draws a machine (or takes one from ``reset(options={"machine": ...})``)
    and starts at the Zero posture with ``stands`` gauge stands mounted at the paper's
    slots (mid-leg, both axes of each leg; installed with the preset's errors, zeroed at
    Zero), plunger down.  The agent then works until it stops or the time budget runs out.

    Action space (``Dict``)
    -----------------------
    =====  ===========================  =====================================  ==========
    key    space                        meaning                                used by
    =====  ===========================  =====================================  ==========
    op     Discrete(5)                  0 move, 1 lift, 2 engage, 3 re-mount,  every step
                                        4 stop (:class:`~orthoglide_env.lab.Op`)
    rho    Box([-100, 60] mm, (3,))     joint targets, control coordinates     move
    stand  Discrete(stands)             which stand                            lift, engage,
                                                                               re-mount
    slot   Discrete(len(SLOTS))         where to (:data:`~orthoglide_env.lab.  re-mount
                                        SLOTS`, names in ``SLOT_NAMES``)
    =====  ===========================  =====================================  ==========

    ``move`` drives to ``rho``, settles and reads every engaged gauge and the tracker.
    A slot is a place on a bar, on a carriage (across its drive) or on a face of the
    platform (:data:`~orthoglide_env.lab.SLOTS`); a platform gauge reads the platform's
    displacement, so it allows moves toward its stand only within its travel: lift it
    before larger ones.
    ``lift`` raises a plunger by its lever: no reading, nothing can press it, and its zero
    is kept. ``engage`` lets it down again (a bar pressing it past its travel there is an
    overtravel). ``re-mount`` drives to Zero, moves the stand to the slot with new
    installation errors, sets the gauge at mid-travel and zeroes it, and reads at Zero
    (that reading opens the new mounting). An action outside its space raises
    ``ValueError`` and changes nothing.  A well-formed operation that cannot be done
    (lifting or engaging a stand that is not mounted, re-mounting onto a slot another stand
    holds, driving where the machine cannot assemble) is refused: it costs the 3 s of a
    lever flick, changes nothing else, and ``info["refused"]`` says why.

    Observation space (``Dict``)
    ----------------------------
    =============  ==================================  ====  ============================
    key            meaning                             unit  range
    =============  ==================================  ====  ============================
    gauges         reading of each stand's gauge        mm   [-travel, travel]
    valid          1 where that reading is valid        -    {0, 1}
    engaged        1 where the plunger is down          -    {0, 1}
    slot           slot index of each stand, or        -    {0 .. len(SLOTS)}
                   len(SLOTS) when not mounted
    mounting       how many times the stand was         -    [0, 1e6]
                   mounted (a new zero each time)
    joints         encoder readings                     mm   [-101, 61]
    tracker        reflector in the tracker's frame     mm   [-1e5, 1e5] (0 without one)
    tracker_valid  1 when the tracker read              -    {0, 1}
    time           seconds used so far                  s    [0, inf)
    =============  ==================================  ====  ============================

    A reading that is not valid is 0.0: use ``valid``.  Every reading is also written to
    ``records`` (the lab notebook: instrument, mounting, posture, value), which agents and
    estimators read; the machine's truth stays on ``true_machine`` for scoring only.

    Reward (``reward=`` at construction)
    ------------------------------------
    ============  ==============================================================
    mode          reward
    ============  ==============================================================
    time          minus the seconds of the step
    accuracy      minus ``time_weight`` per hour on every step; at the end, minus
                  the TCP error RMS after the best-fit rigid motion (over the
                  scoring grid) of the machine the ``estimator`` makes of the
                  episode's records, in units of 0.01 mm (the nominal machine's
                  error when the estimator fails)
    information   the gain in log det(I + F) of the step, per second of it, where F
                  is the information of the records about every parameter in units
                  of its a-priori size (the design's Bayesian D-criterion at the
                  nominal machine: combinations the records cannot see add nothing)
    ============  ==============================================================

    Termination and truncation
    --------------------------
    ``terminated`` on ``stop``, or when moving parts that must never meet touch
    (``info["collision"]``).  ``truncated`` once the time used reaches ``budget_s``.

    Info
    ----
    ``op``, ``step_time_s``, ``overtravel`` (stands pushed past their travel on this step),
    ``collision``, ``refused`` ("" or why the operation was refused); at the end also
    ``is_success`` (the predicted TCP error after the best-fit rigid motion, from the
    records' information at the nominal machine, is at most ``success_mm``) and
    ``predicted_tcp_rigid_mm``.

    Kwargs: ``errors`` (preset), ``gauge_sigma``, ``gauge_resolution`` (mm), ``backend``
    (``exact`` or ``pybullet``), ``stands`` (default 6), ``tracker`` (a laser tracker on
    the platform, read at every move), ``tracker_sigma`` (mm), ``budget_s``, ``reward``,
    ``estimator`` (for ``accuracy``: records and sigma to a ``MachineParams``, e.g.
    ``calibrators.lab.make_estimator()``), ``time_weight``, ``success_mm``, ``travel``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(
        self,
        errors: str = DEFAULT_PRESET,
        gauge_sigma: float = DEFAULT_SIGMA,
        gauge_resolution: float = DEFAULT_RESOLUTION,
        backend: str = "exact",
        stands: int = len(PAPER_SLOTS),
        tracker: bool = False,
        tracker_sigma: float = TRACKER_SIGMA,
        budget_s: float = 3600.0,
        reward: str = "time",
        estimator: Estimator | None = None,
        time_weight: float = 1.0,
        success_mm: float = 0.01,
        travel: float = DEFAULT_TRAVEL,
    ) -> None:
        self.preset = get_preset(errors)
        if backend not in ("exact", "pybullet"):
            raise ValueError(f"unknown backend '{backend}'; choose from ['exact', 'pybullet']")
        if reward not in REWARDS:
            raise ValueError(f"unknown reward '{reward}'; choose from {list(REWARDS)}")
        if reward == "accuracy" and estimator is None:
            raise ValueError("reward 'accuracy' needs an estimator: records -> machine, e.g. "
                             "calibrators.lab.make_estimator()")
        if not 1 <= int(stands) <= len(SLOTS):
            raise ValueError(f"stands must be between 1 and {len(SLOTS)}, got {stands}")
        for name, value in (("budget_s", budget_s), ("success_mm", success_mm),
                            ("tracker_sigma", tracker_sigma), ("travel", travel)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if not (np.isfinite(time_weight) and time_weight >= 0):
            raise ValueError(f"time_weight must be a number >= 0, got {time_weight}")
        self.noise = check_noise(gauge_sigma, gauge_resolution, travel)
        self.backend_name, self.n_stands, self.tracker = backend, int(stands), bool(tracker)
        self.tracker_sigma, self.budget_s, self.reward_mode = tracker_sigma, budget_s, reward
        self.estimator, self.time_weight, self.success_mm = estimator, time_weight, success_mm
        self.travel = float(travel)
        n = self.n_stands
        self.action_space = spaces.Dict({
            "op": spaces.Discrete(len(Op)),
            "rho": spaces.Box(RHO_MIN, RHO_MAX, shape=(3,), dtype=np.float64),
            "stand": spaces.Discrete(n),
            "slot": spaces.Discrete(len(SLOTS)),
        })
        self.observation_space = spaces.Dict({
            "gauges": spaces.Box(-self.travel, self.travel, shape=(n,), dtype=np.float64),
            "valid": spaces.MultiBinary(n),
            "engaged": spaces.MultiBinary(n),
            "slot": spaces.MultiDiscrete([len(SLOTS) + 1] * n),
            "mounting": spaces.Box(0.0, 1e6, shape=(n,), dtype=np.float64),
            "joints": spaces.Box(RHO_MIN - ENCODER_MARGIN, RHO_MAX + ENCODER_MARGIN, shape=(3,),
                                 dtype=np.float64),
            "tracker": spaces.Box(-1e5, 1e5, shape=(3,), dtype=np.float64),
            "tracker_valid": spaces.MultiBinary(1),
            "time": spaces.Box(0.0, budget_s + self._longest_step(), shape=(1,),
                               dtype=np.float64),
        })
        self._machine: MachineBackend | None = None
        self.records: list[Record] = []

    def _longest_step(self) -> float:
        """The most one operation can cost (a re-mount from the far corner, the tracker, and
        every stand pushed past its travel): the clock never passes budget + this."""
        far = TIME.move(np.full(3, RHO_MIN), np.full(3, RHO_MAX))
        return far + TIME.remount_s + TIME.tracker_point_s + TIME.overtravel_s * self.n_stands

    # -- ground truth, for the scorer only -------------------------------------------------
    @property
    def true_machine(self) -> MachineParams:
        return self._require().machine

    @property
    def true_gauges(self) -> list[Gauge]:
        """Every installation of the episode, in mounting order (scoring only)."""
        return list(self._installed.values())

    @property
    def true_tracker_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """The tracker station's rotation and position (scoring only)."""
        return self._tracker_rotation, self._tracker_position

    # -- Gymnasium API --------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        # Every option is checked before anything changes: a refused reset leaves the
        # episode (and its random stream) as it was.
        check_seed(seed)
        if not isinstance(options, dict | None):
            raise ValueError("reset options must be a dict")
        options = dict(options or {})
        unknown = sorted(set(options) - {"machine"})
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: machine")
        given = options.get("machine")
        if isinstance(given, dict):
            given = MachineParams.from_dict(given)
        elif isinstance(given, MachineParams):
            given = check_validity(given)
        elif given is not None:
            raise ValueError("reset option 'machine' must be a dict in the machine file schema "
                             "or a MachineParams")
        super().reset(seed=seed)
        machine = self.preset.sample(self.np_random) if given is None else given
        rotation = _random_rotation(self.np_random)
        direction = self.np_random.normal(size=3)
        position = TRACKER_DISTANCE * direction / np.linalg.norm(direction)
        if self._machine is not None:
            self._machine.close()
        self._machine = self._build(machine)
        self._tracker_rotation, self._tracker_position = rotation, position
        self._rho = np.zeros(3)
        self._time = 0.0
        self._pending = 0.0
        self._steps = 0
        self._mounts = 0
        self._installed: dict[str, Gauge] = {}
        self._info_sums: dict[str, tuple[int, Any, Any, tuple[str, ...]]] = {}
        self._informed = 0  # records already in the information sums
        self._logdet = 0.0
        self.records = []
        self._stands = [Stand() for _ in range(self.n_stands)]
        for k, slot in enumerate(PAPER_SLOTS[: self.n_stands]):
            self._mount(k, slot, name=SLOT_NAMES[slot])
        self._sync_gauges()
        reading = self._read()
        return self._observation(reading), self._info("reset", 0.0, [], "")

    def step(self, action: dict[str, Any]
             ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        machine = self._require()
        op, rho, stand, slot = self._check_action(action)
        overtravel: list[str] = []
        reading = None
        refused = self._refusal(op, rho, stand, slot)
        if refused:
            # The technician sees it cannot be done: a moment lost, nothing changed.
            seconds = TIME.lift_s
        elif op == Op.MOVE:
            seconds = TIME.move(self._rho, rho) + (TIME.tracker_point_s if self.tracker else 0.0)
            machine.move(rho)
            self._rho = rho
        elif op in (Op.LIFT, Op.ENGAGE):
            seconds = TIME.lift_s
            self._stands[stand].engaged = op == Op.ENGAGE
        elif op == Op.REMOUNT:
            seconds = TIME.move(self._rho, np.zeros(3)) + TIME.remount_s
            machine.move(np.zeros(3))
            self._rho = np.zeros(3)
            self._mount(stand, slot)
            self._sync_gauges()
        else:
            seconds = 0.0
        if not refused and op in (Op.MOVE, Op.ENGAGE, Op.REMOUNT):
            overtravel = self._press()
            seconds += TIME.overtravel_s * len(overtravel)
        if not refused and op in (Op.MOVE, Op.REMOUNT):
            self._pending = seconds
            reading = self._read()
        self._time += seconds
        self._steps += 1
        collision = ", ".join(machine.collisions()) if op in (Op.MOVE, Op.REMOUNT) else ""
        terminated = (op == Op.STOP and not refused) or bool(collision)
        truncated = not terminated and self._time >= self.budget_s
        reward = self._reward(seconds, terminated or truncated)
        info = self._info(OP_NAMES[op], seconds, overtravel, collision)
        info["refused"] = refused
        if terminated or truncated:
            predicted = self.predicted_tcp_rigid_mm()
            info.update(is_success=bool(predicted <= self.success_mm),
                        predicted_tcp_rigid_mm=predicted)
        return self._observation(reading), reward, terminated, truncated, info

    def _refusal(self, op: Op, rho: np.ndarray, stand: int, slot: int) -> str:
        """Why a well-formed operation cannot be done here ("" when it can): a stand that
        is not mounted cannot be lifted or engaged, a slot holds one stand, and the
        machine cannot be driven where it cannot assemble."""
        target = self._stands[stand]
        if op in (Op.LIFT, Op.ENGAGE) and target.gauge is None:
            return f"stand {stand} is not mounted"
        if op == Op.REMOUNT and any(s.slot == slot for k, s in enumerate(self._stands)
                                    if k != stand):
            return f"slot {SLOT_NAMES[slot]} already holds a stand"
        if op == Op.MOVE:
            try:
                direct(self._require().machine, rho)
            except UnreachableError:
                return f"the machine cannot assemble at rho = {rho.tolist()}"
        return ""

    def close(self) -> None:
        if self._machine is not None:
            self._machine.close()
            self._machine = None

    # -- the lab's bookkeeping ----------------------------------------------------------------
    def _build(self, machine: MachineParams) -> MachineBackend:
        if self.backend_name == "exact":
            return ExactMachine(machine, [])
        from .machine import OrthoglideMachine

        return OrthoglideMachine(machine, [])

    def _require(self) -> MachineBackend:
        if self._machine is None:
            raise RuntimeError("call reset() before using the environment")
        return self._machine

    def _mount(self, stand: int, slot: int, name: str = "") -> None:
        """Install stand ``stand`` at ``slot`` on the true machine (at Zero) with the
        preset's installation errors, slid to mid-travel and zeroed."""
        machine = self._require().machine
        gauge = install([SLOTS[slot]], machine, travel=self.travel, preset=self.preset,
                        rng=self.np_random)[0]
        t = exact_ray_distances(machine, [gauge], np.zeros(3))
        if not np.isfinite(t).all():
            raise ValueError(f"slot {SLOT_NAMES[slot]} cannot be reached on this machine")
        gauge = zero_gauges([gauge], t)[0]
        self._mounts += 1
        mounting = name or f"{SLOT_NAMES[slot]}#{self._mounts}"
        count = self._stands[stand].count + 1
        self._stands[stand] = Stand(slot, True, False, mounting, gauge, count)
        self._installed[mounting] = gauge

    def _sync_gauges(self) -> None:
        """Hand the machine the gauges of every mounted stand (the simulator reads them)."""
        self._require().set_gauges([s.gauge for s in self._stands if s.gauge is not None])

    def _mounted(self) -> list[int]:
        return [k for k, s in enumerate(self._stands) if s.gauge is not None]

    def _press(self) -> list[str]:
        """Stands whose engaged plunger a bar now pushes past its travel: they fault."""
        machine = self._require()
        mounted = self._mounted()
        if not mounted:
            return []
        pressed = pressed_past_travel(machine.gauges, *machine.target_boxes())
        faulted = []
        for k, p in zip(mounted, pressed, strict=True):
            stand = self._stands[k]
            if p and stand.engaged and not stand.faulted:
                stand.faulted = True
                faulted.append(f"stand {k} ({stand.mounting})")
        return faulted

    def _read(self) -> np.ndarray:
        """Read every engaged, working gauge (and the tracker): noisy values per stand, NaN
        where there is none; every reading goes to ``records``."""
        machine = self._require()
        values = np.full(self.n_stands, np.nan)
        mounted = self._mounted()
        if mounted:
            t = machine.gauge_distances()
            ideal = readings_from_distances(machine.gauges, t)
            ok = status_of(machine.gauges, t) == Status.VALID
            noisy = self.noise.apply(ideal, self.np_random)
            for k, value, good in zip(mounted, noisy, ok, strict=True):
                stand = self._stands[k]
                if good and stand.engaged and not stand.faulted:
                    values[k] = value
                    self._record(SLOTS[stand.slot], stand.mounting, value)
        if self.tracker:
            point = (self._tracker_rotation @ machine.tcp() + self._tracker_position
                     + self.np_random.normal(0.0, self.tracker_sigma, 3))
            self._tracker_reading = point
            for c in range(3):
                self._record(TrackerAxis(c), f"tracker.{AXIS_NAMES[c]}", point[c])
        return values

    def _record(self, spec: Spec, mounting: str, value: float) -> None:
        self.records.append(Record(spec, mounting, tuple(float(v) for v in self._rho),
                                   float(value), self._steps, self._time + self._pending))

    # -- rewards --------------------------------------------------------------------------------
    def _reward(self, seconds: float, done: bool) -> float:
        if self.reward_mode == "time":
            return -seconds
        if self.reward_mode == "information":
            gain = self._update_logdet()
            return gain / seconds if seconds > 0 else 0.0
        reward = -self.time_weight * seconds / 3600.0
        if done:
            reward -= self.final_tcp_rigid_mm() / ACCURACY_UNIT_MM
        return reward

    def final_tcp_rigid_mm(self) -> float:
        """TCP error RMS after the best-fit rigid motion of the machine the episode's
        estimator makes of its records (scoring against the truth)."""
        truth = self.true_machine
        try:
            estimate = self.estimator(self.records, self.noise.effective_sigma)
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            estimate = MachineParams()
        return score(estimate, truth).tcp_after.rigid.rms

    def _add_information(self, records: list[Record]) -> None:
        """Add the records' rows of the Jacobian (at the nominal machine, per unit of each
        parameter's scale, per unit of noise; one batched call) to their mountings' sums:
        the information of a mounting, its zero eliminated, is ``S2 - S1 S1^T / n``."""
        design = Design.of([r.mounting for r in records], [r.spec for r in records],
                           np.array([r.rho for r in records]))
        space = design.space
        rows = jacobian(np.zeros(len(space)), design, np.ones(len(space), bool),
                        default_scales(space))
        gauge_sigma = max(self.noise.effective_sigma, NOISE_FLOOR)
        for record, row, m in zip(records, rows, design.mounting, strict=True):
            sigma = self.tracker_sigma if isinstance(record.spec, TrackerAxis) else gauge_sigma
            # The mounting's own columns: the machine's errors and its instrument's.
            mine = _mounting_columns(space, m)
            names = tuple(space.names[c] for c in mine)
            row = row[mine] / sigma
            n, s1, s2, _ = self._info_sums.get(record.mounting, (0, 0.0, 0.0, names))
            self._info_sums[record.mounting] = (n + 1, s1 + row, s2 + np.outer(row, row),
                                                names)

    def information(self) -> tuple[np.ndarray, list[str]]:
        """The records' information about every parameter they involve, in units of each
        parameter's scale (see ``information`` reward), and the parameters' names."""
        if self._informed < len(self.records):
            self._add_information(self.records[self._informed:])
        self._informed = len(self.records)
        names = list(ERROR_NAMES)
        for _, _, _, mine in self._info_sums.values():
            names += [n for n in mine if n not in names]
        info = np.zeros((len(names), len(names)))
        for n, s1, s2, mine in self._info_sums.values():
            idx = [names.index(x) for x in mine]
            info[np.ix_(idx, idx)] += s2 - np.outer(s1, s1) / n
        return info, names

    def _update_logdet(self) -> float:
        info, _ = self.information()
        logdet = float(np.linalg.slogdet(np.eye(len(info)) + info)[1])
        gain, self._logdet = logdet - self._logdet, logdet
        return gain

    def predicted_tcp_rigid_mm(self) -> float:
        """TCP error RMS after the best-fit rigid motion that the records' information
        predicts (at the nominal machine, a priori sizes from the realistic preset)."""
        info, names = self.information()
        space = ParameterSpace()
        scale = np.concatenate([default_scales(space), np.ones(len(names) - len(ERROR_NAMES))])
        posterior = np.linalg.inv(np.eye(len(info)) + info)[:27, :27]
        covariance = posterior * np.outer(scale[:27], scale[:27])
        return predicted_tcp_frames(MachineParams(), covariance).rigid.rms

    # -- actions and observations ------------------------------------------------------------
    def _check_action(self, action: Any) -> tuple[Op, np.ndarray, int, int]:
        if not isinstance(action, dict) or set(action) != {"op", "rho", "stand", "slot"}:
            raise ValueError("action must be a dict with keys op, rho, stand, slot")
        op = _integer(action["op"], "op", len(Op))
        stand = _integer(action["stand"], "stand", self.n_stands)
        slot = _integer(action["slot"], "slot", len(SLOTS))
        rho = action["rho"]
        if op == Op.MOVE:
            try:
                rho = np.array(rho, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"action rho must be 3 numbers (mm), got {rho!r}") from None
            if rho.shape != (3,):
                raise ValueError(f"action rho must have shape (3,), got {rho.shape}")
            rho = check_rho(rho)
        return Op(op), rho, stand, slot

    def _observation(self, reading: np.ndarray | None) -> dict[str, np.ndarray]:
        values = np.full(self.n_stands, np.nan) if reading is None else reading
        valid = np.isfinite(values)
        tracker = getattr(self, "_tracker_reading", np.zeros(3)) if self.tracker else np.zeros(3)
        fresh = reading is not None and self.tracker
        return {
            "gauges": np.where(valid, values, 0.0),
            "valid": valid.astype(np.int8),
            "engaged": np.array([s.engaged and not s.faulted for s in self._stands], np.int8),
            "slot": np.array([s.slot if s.slot >= 0 else len(SLOTS) for s in self._stands],
                             dtype=np.int64),
            "mounting": np.array([float(s.count) for s in self._stands]),
            "joints": self._require().encoders().astype(np.float64),
            "tracker": np.asarray(tracker if fresh else np.zeros(3), dtype=np.float64),
            "tracker_valid": np.array([int(fresh)], dtype=np.int8),
            "time": np.array([self._time]),
        }

    def _info(self, op: str, seconds: float, overtravel: list[str], collision: str
              ) -> dict[str, Any]:
        return {"op": op, "step_time_s": seconds, "overtravel": overtravel,
                "collision": collision}


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


def _integer(value: Any, name: str, size: int) -> int:
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer) or (
            not 0 <= int(value) < size):
        raise ValueError(f"action {name} must be an integer in [0, {size}), got {value!r}")
    return int(value)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (a normalised normal quaternion)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


