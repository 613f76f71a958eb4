"""The native vector env of ``OrthoglideCalibration-v0``: N machines in one numpy pass.

``gymnasium.make_vec("OrthoglideCalibration-v0", num_envs=N,
vectorization_mode="vector_entry_point", backend="exact")`` builds it.  It computes what N
separate envs compute, the same numbers to the last bit, with every machine of the batch
in the same array operations (:mod:`orthoglide_env.instruments.gauges`,
:mod:`orthoglide_env.model.collisions`
and :mod:`orthoglide_env.envs.task` work on batches); only the random streams stay one per env,
so that env ``i`` seeded with ``seed + i`` draws what a single env seeded so draws.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from orthoglide_env.envs.backend import ExactMachine
from orthoglide_env.envs.calibration import (
    STATUS_LABELS,
    EnvSettings,
    check_actions,
    check_seed,
    collision_label,
    observation,
    overtravel_names,
    reset_options,
)
from orthoglide_env.envs.task import CalibrationTask, Reading
from orthoglide_env.instruments.gauges import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    DEFAULT_TRAVEL,
    GaugeArray,
    GaugeSpec,
    install_array,
    installation_errors,
    zero_gauges,
)
from orthoglide_env.model.errors import DEFAULT_PRESET, MachineParams
from orthoglide_env.model.kinematics import UnreachableError, direct

#: What ``options["reset_mask"]`` must be, as Gymnasium's vector envs take it.
RESET_MASK = "reset_mask"


def check_num_envs(num_envs: Any) -> int:
    """``num_envs`` as a positive int, or ``ValueError``."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, numbers.Integral) or (
        num_envs < 1
    ):
        raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
    return int(num_envs)


def check_autoreset_mode(mode: str | AutoresetMode) -> AutoresetMode:
    """Gymnasium's autoreset mode named by ``mode``, or ``ValueError``."""
    try:
        return AutoresetMode(mode)
    except ValueError:
        raise ValueError(f"unknown autoreset_mode {mode!r}; choose from "
                         f"{[m.value for m in AutoresetMode]}") from None


class SeededVectorEnv(VectorEnv):
    """What the native vector envs share: one random stream per env, spread and seeded as
    ``SyncVectorEnv`` seeds its envs, saved and restored around a failed reset, and
    Gymnasium's reset mask.  A subclass sets ``num_envs`` and calls :meth:`_init_streams`,
    and says with :attr:`_started` whether every env has been reset."""

    num_envs: int

    def _init_streams(self) -> None:
        self._streams: list[np.random.Generator | None] = [None] * self.num_envs
        self._seeds: list[int | None] = [None] * self.num_envs

    @property
    def _started(self) -> bool:
        raise NotImplementedError

    @property
    def np_random(self) -> tuple[np.random.Generator, ...]:  # type: ignore[override]
        """Every env's random stream (as ``SyncVectorEnv.np_random``)."""
        return tuple(self._stream(i) for i in range(self.num_envs))

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:  # type: ignore[override]
        """The seed of every env's random stream."""
        for i in range(self.num_envs):
            self._stream(i)  # a stream not yet drawn gets its random seed here
        return tuple(self._seeds)

    def _stream(self, i: int) -> np.random.Generator:
        """Env ``i``'s random stream; like ``gym.Env.np_random`` it is seeded at random when
        first needed without a seed."""
        stream = self._streams[i]
        if stream is None:
            stream, self._seeds[i] = seeding.np_random()
            self._streams[i] = stream
        return stream

    def _new_streams(self, rows: np.ndarray, seeds: list[int | None]
                     ) -> tuple[list[np.random.Generator], list[int | None]]:
        """The streams the envs ``rows`` reset with: a new one per seed given, else their
        own; and their seeds.  Nothing is stored (see :meth:`_keep_streams`)."""
        streams, used = [], []
        for i, seed in zip(rows, seeds, strict=True):
            if seed is None:
                streams.append(self._stream(int(i)))
                used.append(self._seeds[i])
            else:
                stream, value = seeding.np_random(seed)
                streams.append(stream)
                used.append(value)
        return streams, used

    def _keep_streams(self, rows: np.ndarray, streams: list[np.random.Generator],
                      seeds: list[int | None]) -> None:
        for i, stream, seed in zip(rows, streams, seeds, strict=True):
            self._streams[i], self._seeds[i] = stream, seed

    def _saved_streams(self, rows: np.ndarray) -> list[tuple[int, np.random.Generator | None,
                                                             dict | None, int | None]]:
        """The streams of envs ``rows`` as they stand, for :meth:`_restore_streams`."""
        return [(int(i), self._streams[i],
                 None if self._streams[i] is None else self._streams[i].bit_generator.state,
                 self._seeds[i]) for i in rows]

    def _restore_streams(self, saved: list) -> None:
        for i, stream, state, seed in saved:
            self._streams[i], self._seeds[i] = stream, seed
            if stream is not None:
                stream.bit_generator.state = state

    def _seed_list(self, seed: Any) -> list[int | None]:
        """One seed per env from ``reset``'s ``seed`` (as ``SyncVectorEnv`` spreads it)."""
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, int) and not isinstance(seed, bool):
            check_seed(seed)
            return [seed + i for i in range(self.num_envs)]
        if not isinstance(seed, list | tuple) or len(seed) != self.num_envs:
            raise ValueError(f"reset seed must be None, an integer >= 0 or a list of "
                             f"{self.num_envs} such values, got {seed!r}")
        for value in seed:
            check_seed(value)
        return list(seed)

    def _reset_mask(self, mask: Any) -> np.ndarray:
        """Which envs a reset resets: all, or ``options["reset_mask"]``."""
        if mask is None:
            return np.ones(self.num_envs, dtype=bool)
        if not (isinstance(mask, np.ndarray) and mask.dtype == np.bool_
                and mask.shape == (self.num_envs,) and mask.any()):
            raise ValueError(f"reset option 'reset_mask' must be a numpy boolean array of "
                             f"shape ({self.num_envs},) with at least one True, got {mask!r}")
        if not self._started and not mask.all():
            raise RuntimeError("call reset() for every env before resetting a few")
        return mask


class OrthoglideCalibrationVectorEnv(SeededVectorEnv):
    """``num_envs`` calibration experiments on virtual Orthoglides, stepped together.

    Env ``i`` behaves exactly as one
    :class:`~orthoglide_env.envs.calibration.OrthoglideCalibrationEnv`
    (``gym.make("OrthoglideCalibration-v0", backend="exact", ...)``) reset with seed
    ``seed + i``, inside a ``SyncVectorEnv`` with the same ``autoreset_mode``: the same
    observations, rewards, terminations, truncations and infos, bit for bit.  Only the
    ``exact`` backend is batched: ``backend="pybullet"`` raises ``ValueError`` (use
    ``vectorization_mode="sync"`` or ``"async"`` for simulated machines).  The constructor
    takes the single env's arguments (``errors``, ``gauge_sigma``, ``gauge_resolution``,
    ``motion``, ``gauges``, ``travel``, ``max_episode_steps``, ``clip_actions``) with the
    same rules, plus ``num_envs`` and ``autoreset_mode``.

    Action space
    ------------
    ========  ======================================  ====  ==========
    index     meaning                                 unit  range
    ========  ======================================  ====  ==========
    [i, 0:3]  env i's target control coordinates rho  mm    [-100, 60]
    ========  ======================================  ====  ==========

    A target that one env would refuse (outside the joint limits, not finite, not real
    numbers, wrong shape, or a posture that env's machine cannot be assembled in) raises
    ``ValueError`` naming the env, and no env moves (``SyncVectorEnv`` would have stepped
    the envs before it).  The row of an env that autoresets on this step is not used.

    Observation space (``Dict``)
    ----------------------------
    ======  ===========================================  ====  =================
    key     meaning                                      unit  range
    ======  ===========================================  ====  =================
    gauges  (N, G) readings, in each env's layout order  mm    [-travel, travel]
    valid   (N, G) 1 where the gauge touches its bar     -     {0, 1}
    joints  (N, 3) encoder readings                      mm    [-101, 61]
    ======  ===========================================  ====  =================

    A gauge that is not valid reads 0.0: use ``valid``.

    Reward
    ------
    ===============  =============================================  =======
    term             when                                           seconds
    ===============  =============================================  =======
    travel           every step: ``max |delta rho| / DRIVE_SPEED``  >= 0
    settle and read  every step                                     5
    overtravel       per gauge pushed past its travel on this move  120
    ===============  =============================================  =======

    The reward is minus the sum (:mod:`orthoglide_env.envs.task`), and 0.0 on the step on
    which an env autoresets (``next-step`` mode).

    Termination and autoreset
    -------------------------
    ==========  ==========================================================================
    flag        when
    ==========  ==========================================================================
    terminated  moving parts that must never meet touch (``info["collision"]`` names them)
    truncated   ``max_episode_steps`` steps since the env's reset (500 from ``make_vec``)
    ==========  ==========================================================================

    ``autoreset_mode`` (``metadata["autoreset_mode"]``) is Gymnasium's: ``NEXT_STEP``
    (default) resets an ended env on its next ``step``, which returns its first
    observation with reward 0 and both flags False; ``SAME_STEP`` resets it at once and
    returns the last observation and info in ``info["final_obs"]``, ``info["final_info"]``;
    ``DISABLED`` leaves it to ``reset(options={"reset_mask": ...})`` and refuses to step an
    ended env (``RuntimeError``).  An autoreset draws a machine from the preset with the
    env's default gauge layout.

    Reset
    -----
    ``seed``: None (each env keeps its random stream), an int (env ``i`` gets ``seed + i``)
    or a list of N ints or None.  ``options``: the single env's ``machine`` and ``gauges``,
    applied to every env reset, and ``reset_mask``, a boolean array of shape (N,) with at
    least one True: only those envs are reset (the others keep their episode; their rows
    of the returned observation are their last ones, and their info is absent).  The
    first reset must reset every env.  A refused reset raises ``ValueError`` and changes
    nothing, random streams included.

    Info
    ----
    Gymnasium's vector form of the single env's info: for each key (``gauge_names``,
    ``status``, ``overtravel``, ``step_time_s``, ``collision``) an array over the envs
    (objects for lists and text, float64 for the time) and a boolean mask ``_key`` of the
    envs that have it.  Only deterministic values.

    Ground truth for scoring: ``true_machines`` (a :class:`MachineParams` batch of shape
    (N,)), ``true_gauges`` (one list of gauges per env); ``gauge_layouts``, ``gauge_noise``
    and ``travel`` are public as on the single env.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [],
                                          "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        errors: str = DEFAULT_PRESET,
        gauge_sigma: float = DEFAULT_SIGMA,
        gauge_resolution: float = DEFAULT_RESOLUTION,
        motion: str = "quasi-static",
        backend: str = "pybullet",
        gauges: list[str] | tuple[GaugeSpec, ...] | None = None,
        travel: float = DEFAULT_TRAVEL,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        clip_actions: bool = False,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
    ) -> None:
        if backend == "pybullet":
            raise ValueError("the native vector env runs backend='exact' only; for PyBullet "
                             "machines use vectorization_mode='sync' or 'async'")
        num_envs = check_num_envs(num_envs)
        self.autoreset_mode = check_autoreset_mode(autoreset_mode)
        settings = EnvSettings.check(
            errors=errors, gauge_sigma=gauge_sigma, gauge_resolution=gauge_resolution,
            motion=motion, backend=backend, gauges=gauges, travel=travel,
            max_episode_steps=max_episode_steps, render_mode=render_mode,
            clip_actions=clip_actions,
        )
        self.settings = settings
        self.num_envs = int(num_envs)
        self.preset = settings.preset
        self.gauge_noise = settings.gauge_noise
        self.travel = settings.travel
        self.clip_actions = settings.clip_actions
        self.max_episode_steps = settings.max_episode_steps
        self.render_mode = None
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.task = CalibrationTask(self.gauge_noise)
        self.single_action_space, self.single_observation_space = settings.spaces()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        n, g = self.num_envs, len(settings.layout)
        self._init_streams()
        self._machines: MachineParams | None = None
        self._gauges: GaugeArray | None = None
        self.gauge_layouts: list[tuple[GaugeSpec, ...]] = [settings.layout] * n
        self._names = [[s.slot for s in settings.layout]] * n
        self._rho = np.zeros((n, 3))
        self._steps = np.zeros(n, dtype=np.int64)
        self._pressed = np.zeros((n, g), dtype=bool)
        self._ended = np.zeros(n, dtype=bool)
        self._obs = {key: np.zeros(space.shape, space.dtype)
                     for key, space in self.observation_space.items()}

    # -- ground truth, for the scorer only --------------------------------------------------
    @property
    def true_machines(self) -> MachineParams:
        return self._require_episodes()[0]

    @property
    def true_gauges(self) -> list[list]:
        gauges = self._require_episodes()[1]
        return [gauges[i].to_gauges() for i in range(self.num_envs)]

    @property
    def _started(self) -> bool:
        return self._machines is not None

    # -- Gymnasium API --------------------------------------------------------------------------
    def reset(
        self, *, seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        seeds = self._seed_list(seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"reset options must be a dict or None, got {options!r}")
        options = dict(options or {})
        mask = self._reset_mask(options.pop(RESET_MASK, None))
        machine, layout = reset_options(options, self.settings.layout)
        rows = np.flatnonzero(mask)
        saved = self._saved_streams(rows)
        try:
            fresh = self._new_episodes(rows, [seeds[i] for i in rows], machine, layout)
        except BaseException:
            self._restore_streams(saved)
            raise
        obs = {key: value.copy() for key, value in self._obs.items()}
        self._start(fresh, obs)
        self._obs = obs
        self._ended[rows] = False
        return _copy(obs), self._reset_info(fresh)

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        machines, gauges = self._require_episodes()
        n = self.num_envs
        if self.autoreset_mode == AutoresetMode.DISABLED and self._ended.any():
            raise RuntimeError(f"env(s) {np.flatnonzero(self._ended).tolist()} ended: reset "
                               "them (options={'reset_mask': ...}) before stepping again")
        resetting = self._ended if self.autoreset_mode == AutoresetMode.NEXT_STEP else (
            np.zeros(n, dtype=bool))
        stepping = ~resetting
        targets = check_actions(actions, (n, 3), self.clip_actions, rows=stepping)
        # An env that resets on this step stays where it is in the batched pass; its row is
        # replaced by its new episode's below.
        targets = np.where(resetting[:, None], self._rho, targets)
        moved = self._move(machines, gauges, targets)
        steps = self._steps + 1
        terminated = moved.crashed.any(axis=-1) & stepping
        truncated = stepping & (np.zeros(n, dtype=bool) if self.max_episode_steps is None
                                else steps >= self.max_episode_steps)
        ending = (terminated | truncated) if self.autoreset_mode == AutoresetMode.SAME_STEP \
            else np.zeros(n, dtype=bool)
        renew = np.flatnonzero(resetting | ending)
        draws = np.zeros((n, gauges.count))
        saved = self._saved_streams(renew)
        try:
            # Per stream, a step's noise comes before the next episode's draws.
            for i in np.flatnonzero(ending):
                draws[i] = self.gauge_noise.draws(self._stream(i), (gauges.count,))
            fresh = self._new_episodes(renew, [None] * len(renew), None, self.settings.layout)
        except BaseException:
            self._restore_streams(saved)
            raise
        for i in np.flatnonzero(stepping & ~ending):
            draws[i] = self.gauge_noise.draws(self._stream(i), (gauges.count,))
        reading = self.task.reading(gauges, moved.t, targets, draws)
        obs = observation(reading)
        reward = -moved.step_time
        info = self._infos(stepping, self._names, STATUS_LABELS[reading.status].tolist(),
                           self._overtravels(moved.new), moved.step_time,
                           self._collisions(moved.crashed))
        if ending.any():
            info["final_obs"] = np.full(n, None, dtype=object)
            for i in np.flatnonzero(ending):
                info["final_obs"][i] = {key: value[i].copy() for key, value in obs.items()}
            info["_final_obs"] = ending.copy()
            info["final_info"] = self._infos(ending, self._names, info["status"],
                                             info["overtravel"], info["step_time_s"],
                                             info["collision"])
            info["_final_info"] = ending.copy()
        self._rho, self._steps, self._pressed = targets, steps, moved.pressed
        self._start(fresh, obs)
        reward[resetting] = 0.0
        if len(renew):
            # SyncVectorEnv's info of an env that resets on this step is its reset's info.
            reset_info = self._reset_info(fresh)
            for key in ("gauge_names", "status", "overtravel", "step_time_s", "collision"):
                info[key][renew] = reset_info[key][renew]
                info[f"_{key}"] |= reset_info[f"_{key}"]
        self._obs = obs
        self._ended = (terminated | truncated) & ~ending
        return _copy(obs), reward, terminated, truncated, info

    # -- the batched pass -----------------------------------------------------------------------
    def _move(self, machines: MachineParams, gauges: GaugeArray, targets: np.ndarray) -> _Moved:
        """Every machine at its target: gauge distances, overtravels, step times and
        collisions; no random draw, nothing stored."""
        try:
            built = ExactMachine(machines, gauges, targets)
        except UnreachableError:
            env = _first_unreachable(machines, targets)
            try:
                direct(machines[env], targets[env])
            except UnreachableError as exc:
                raise ValueError(f"action of env {env} {targets[env].tolist()} mm: {exc} on "
                                 "this machine; no env moves") from None
            raise
        pressed = self.task.pressed(built)
        new = self.task.new_overtravels(self._pressed, pressed)
        return _Moved(t=built.gauge_distances(), pressed=pressed, new=new,
                      step_time=self.task.step_time(self._rho, targets, new),
                      crashed=built.collision_mask())

    def _new_episodes(self, rows: np.ndarray, seeds: list[int | None],
                      machine: MachineParams | None, layout: tuple[GaugeSpec, ...]) -> _Fresh:
        """New episodes for envs ``rows``, drawn as each env's single counterpart draws its
        own (machine, gauge installation, first reading's noise): nothing is stored, but
        the streams of existing envs advance (the caller restores them on failure)."""
        streams, seeds_used = self._new_streams(rows, seeds)
        if not len(rows):
            return _Fresh(rows, streams, seeds_used, None, None, layout, None, None)
        machines = MachineParams.stack([machine if machine is not None
                                        else self.preset.sample(s) for s in streams])
        errors = np.stack([installation_errors(len(layout), self.preset, s) for s in streams])
        gauges = install_array(layout, machines, travel=self.travel, errors=errors)
        built = ExactMachine(machines, gauges)
        t_zero = built.gauge_distances()
        missed = np.flatnonzero(np.isnan(t_zero).any(axis=-1))
        if len(missed):
            try:
                gauges[missed[0]].zeroed(t_zero[missed[0]])
            except ValueError as exc:
                raise ValueError(f"env {rows[missed[0]]}: {exc}") from None
        gauges = zero_gauges(gauges, t_zero)
        built.set_gauges(gauges)
        draws = np.stack([self.gauge_noise.draws(s, (len(layout),)) for s in streams])
        reading = self.task.reading(gauges, built.gauge_distances(), built.encoders(), draws)
        return _Fresh(rows, streams, seeds_used, machines, gauges, layout, reading,
                      self.task.pressed(built))

    def _start(self, fresh: _Fresh, obs: dict[str, np.ndarray]) -> None:
        """Store the new episodes of ``fresh`` and write their first observation into
        ``obs``."""
        rows = fresh.rows
        if not len(rows):
            return
        self._keep_streams(rows, fresh.streams, fresh.seeds)
        if len(rows) == self.num_envs:
            machines, gauges = fresh.machines, fresh.gauges
        else:
            vector = self._machines.to_vector()
            vector[rows] = fresh.machines.to_vector()
            machines = MachineParams.from_vector(vector)
            gauges = self._require_episodes()[1].with_rows(rows, fresh.gauges)
        self._machines, self._gauges = machines, gauges
        names = [s.slot for s in fresh.layout]
        self.gauge_layouts = list(self.gauge_layouts)
        self._names = list(self._names)
        for i in rows:
            self.gauge_layouts[i], self._names[i] = fresh.layout, names
        self._rho[rows] = 0.0
        self._steps[rows] = 0
        self._pressed[rows] = fresh.pressed
        for key, value in observation(fresh.reading).items():
            obs[key][rows] = value

    # -- helpers --------------------------------------------------------------------------------
    def _require_episodes(self) -> tuple[MachineParams, GaugeArray]:
        if self._machines is None or self._gauges is None:
            raise RuntimeError("call reset() before using the environment")
        return self._machines, self._gauges

    def _infos(self, present: np.ndarray, names: list[list[str]], status: Sequence,
               overtravel: Sequence, step_time: np.ndarray, collision: Sequence
               ) -> dict[str, Any]:
        """The vector info (as ``VectorEnv._add_info`` builds it from each env's
        :func:`~orthoglide_env.envs.calibration.step_info`) of the envs ``present``: list and text
        values
        in object arrays (None elsewhere), the time in a float64 array (0 elsewhere), and a
        mask per key."""
        info: dict[str, Any] = {}
        # Each env's own list of names, so that changing one changes nothing else.
        names = [list(v) for v in names]
        for key, values in (("gauge_names", names), ("status", status),
                            ("overtravel", overtravel), ("collision", collision)):
            info[key] = np.fromiter((v if p else None for v, p in zip(values, present,
                                                                      strict=True)),
                                    dtype=object, count=self.num_envs)
            info[f"_{key}"] = present.copy()
        info["step_time_s"] = np.where(present, step_time, 0.0).astype(np.float64)
        info["_step_time_s"] = present.copy()
        return info

    def _overtravels(self, new: np.ndarray) -> list[list[str]]:
        """Each env's gauges that went into overtravel on this step."""
        out: list[list[str]] = [[] for _ in range(self.num_envs)]
        for i in np.flatnonzero(new.any(axis=-1)):
            out[i] = overtravel_names(self._names[i], new[i])
        return out

    def _collisions(self, crashed: np.ndarray) -> list[str]:
        """Each env's ``info["collision"]``."""
        out = [""] * self.num_envs
        for i in np.flatnonzero(crashed.any(axis=-1)):
            out[i] = collision_label(crashed[i])
        return out

    def _reset_info(self, fresh: _Fresh) -> dict[str, Any]:
        """The vector info of the envs that ``fresh`` starts (stored already)."""
        n = self.num_envs
        status: list = [None] * n
        if fresh.reading is not None:
            for i, labels in zip(fresh.rows, STATUS_LABELS[fresh.reading.status].tolist(),
                                 strict=True):
                status[i] = labels
        present = np.zeros(n, dtype=bool)
        present[fresh.rows] = True
        return self._infos(present, self._names, status, [[] for _ in range(n)], np.zeros(n),
                           [""] * n)


@dataclass(frozen=True)
class _Moved:
    """The batched pass of a step: what every machine shows at its target."""

    t: np.ndarray
    pressed: np.ndarray
    new: np.ndarray
    step_time: np.ndarray
    crashed: np.ndarray


@dataclass(frozen=True)
class _Fresh:
    """New episodes of some envs, built but not yet stored."""

    rows: np.ndarray
    streams: list[np.random.Generator]
    seeds: list[int | None]
    machines: MachineParams | None
    gauges: GaugeArray | None
    layout: tuple[GaugeSpec, ...]
    reading: Reading | None
    pressed: np.ndarray | None


def _first_unreachable(machines: MachineParams, targets: np.ndarray) -> int:
    """The first env whose machine cannot be assembled at its target."""
    for i in range(len(targets)):
        try:
            direct(machines[i], targets[i])
        except UnreachableError:
            return i
    return 0


def _copy(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A copy the caller may change without changing the env."""
    return {key: value.copy() for key, value in obs.items()}
