"""The native vector env of ``OrthoglideLab-v0``: N calibration labs stepped together.

``gymnasium.make_vec("OrthoglideLab-v0", num_envs=N)`` (the registered
``vector_entry_point``) builds it.  It runs the lab's rules (:mod:`orthoglide_env.lab.engine`,
the code the single lab env runs as a batch of one) on N episodes of the exact backend in
the same array operations; only what is personal to an episode stays one per env: its
random stream (env ``i`` seeded with ``seed + i`` draws what a single lab so seeded
draws, in the same order), its notebook of :class:`~orthoglide_env.envs.lab.Record`
objects, and, with the ``information`` reward, its information sums.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from orthoglide_env.envs.calibration_vector import (
    RESET_MASK,
    SeededVectorEnv,
    check_autoreset_mode,
    check_num_envs,
)
from orthoglide_env.envs.lab import reset_machine
from orthoglide_env.instruments.gauges import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    Gauge,
    GaugeNoise,
)
from orthoglide_env.lab.engine import (
    Estimator,
    ExactMachines,
    LabBatch,
    LabSettings,
    Record,
    StepResult,
    check_actions,
)
from orthoglide_env.lab.operations import OP_NAMES, PAPER_SLOTS, TRACKER_SIGMA, Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import DEFAULT_PRESET, MachineParams

#: Info keys of a lab step, and the dtype of their vector form (as ``SyncVectorEnv``
#: builds it from the single lab's values: text and lists in object arrays).
INFO_DTYPES: dict[str, Any] = {
    "op": object, "step_time_s": np.float64, "overtravel": object, "collision": object,
    "refused": object, "is_success": np.bool_, "predicted_tcp_rigid_mm": np.float64,
}


class OrthoglideLabVectorEnv(SeededVectorEnv):
    """``num_envs`` calibration labs (``OrthoglideLab-v0``) on the exact backend, stepped
    together.

    Env ``i`` behaves exactly as one ``gym.make("OrthoglideLab-v0", ...)`` reset with seed
    ``seed + i`` inside a ``SyncVectorEnv`` with the same ``autoreset_mode``: the same
    observations, rewards, terminations, truncations, infos and notebooks, bit for bit.
    The constructor takes the single lab's arguments with the same rules, plus
    ``num_envs`` and ``autoreset_mode``; ``backend="pybullet"`` raises ``ValueError`` (use
    ``vectorization_mode="sync"`` or ``"async"`` for simulated machines).

    Spaces are the single lab's, batched: the action is a dict of arrays, ``op`` (N,),
    ``rho`` (N, 3), ``stand`` (N,), ``slot`` (N,); each observation key gains a first axis
    of N.  An action one env's lab would reject (outside its space) raises ``ValueError``
    naming the env and no env steps; a refused operation is refused in its env only.
    The action row of an env that autoresets on this step is not used.

    Autoreset (``autoreset_mode``, Gymnasium's): ``NEXT_STEP`` (default) resets an ended
    env on its next step, which returns its first observation, reward 0 and both flags
    False; ``SAME_STEP`` resets it at once and returns the ended episode's last
    observation and info in ``info["final_obs"]`` and ``info["final_info"]``;
    ``DISABLED`` leaves it to ``reset(options={"reset_mask": ...})`` and refuses to step
    an ended env (``RuntimeError``).  An autoreset draws a machine from the preset.

    Reset: ``seed`` None (each env keeps its stream), an int (env ``i`` gets ``seed + i``)
    or a list of N ints or None; ``options``: the single lab's ``machine`` (for every env
    reset) and ``reset_mask`` (a boolean array (N,): only those envs reset; the first
    reset resets all).  Infos: Gymnasium's vector form of the single lab's info (an array
    and a ``_key`` mask per key, :data:`INFO_DTYPES`).

    Per env, for agents and estimators: ``records[i]`` (the notebook), ``sub_env(i)`` (a
    read-only view of env ``i`` as an agent sees a lone lab); for scoring only:
    ``true_machines`` (a :class:`MachineParams` batch (N,)), ``true_gauges(i)``,
    ``true_tracker_frames``.  With the ``information`` reward each env sums its own
    information at every step (a loop over envs); at an episode's end the predicted error
    of ``info["predicted_tcp_rigid_mm"]`` is computed once per distinct design.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [],
                                          "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
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
        travel: float | None = None,
        design: MachineDesign | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
    ) -> None:
        if backend == "pybullet":
            raise ValueError("the native lab vector env runs backend='exact' only; for "
                             "PyBullet machines use vectorization_mode='sync' or 'async'")
        self.num_envs = check_num_envs(num_envs)
        self.autoreset_mode = check_autoreset_mode(autoreset_mode)
        self.settings = LabSettings.check(errors, gauge_sigma, gauge_resolution, backend, stands,
                                          tracker, tracker_sigma, budget_s, reward, estimator,
                                          time_weight, success_mm, travel, design)
        self.design = self.settings.design
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = None
        self.single_action_space, self.single_observation_space = self.settings.spaces()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._init_streams()
        self._batch = LabBatch(self.settings, self.num_envs, ExactMachines())
        self._batch.streams = self._streams  # the batch draws from the envs' streams
        self._ended = np.zeros(self.num_envs, dtype=bool)
        self._obs = {key: np.zeros(space.shape, space.dtype)
                     for key, space in self.observation_space.items()}

    @property
    def _started(self) -> bool:
        return self._batch.machines is not None

    # -- per env: notebooks, settings, truth --------------------------------------------------
    @property
    def noise(self) -> GaugeNoise:
        return self.settings.noise

    @property
    def records(self) -> list[list[Record]]:
        """Every env's notebook (its records, in order)."""
        return [book.records for book in self._batch.notebooks]

    def sub_env(self, i: int) -> SubLab:
        """Env ``i`` as an agent sees a lone lab (see :class:`SubLab`)."""
        return SubLab(self, i)

    @property
    def true_machines(self) -> MachineParams:
        self._require()
        return self._batch.require()

    def true_gauges(self, i: int) -> list[Gauge]:
        """Every installation of env ``i``'s episode, in mounting order (scoring only)."""
        self._require()
        return self._batch.true_gauges(i)

    @property
    def true_tracker_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Every env's tracker rotation (N, 3, 3) and position (N, 3) (scoring only)."""
        self._require()
        return self._batch.tracker_rotation.copy(), self._batch.tracker_position.copy()

    # -- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        seeds = self._seed_list(seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"reset options must be a dict or None, got {options!r}")
        options = dict(options or {})
        mask = self._reset_mask(options.pop(RESET_MASK, None))
        machine = reset_machine(options, self.design)
        rows = np.flatnonzero(mask)
        obs = self._copy_obs()
        self._start(rows, [seeds[i] for i in rows], machine, obs)
        self._obs = obs
        self._ended[rows] = False
        info: dict[str, Any] = {}
        _add_reset_infos(info, self.num_envs, rows)
        return self._copy_obs(), info

    def step(self, actions: dict[str, Any]
             ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._require()
        n = self.num_envs
        if self.autoreset_mode == AutoresetMode.DISABLED and self._ended.any():
            raise RuntimeError(f"env(s) {np.flatnonzero(self._ended).tolist()} ended: reset "
                               "them (options={'reset_mask': ...}) before stepping again")
        resetting = self._ended if self.autoreset_mode == AutoresetMode.NEXT_STEP else (
            np.zeros(n, dtype=bool))
        op, rho, stand, slot = check_actions(actions, (n,), self.settings.stands,
                                             rows=~resetting, design=self.design)
        rows = np.flatnonzero(~resetting)
        # Only a re-mount can fail once the actions are checked (a slot its machine cannot
        # reach): then no env has stepped and no stream has moved.
        saved = self._saved_streams(rows[op[rows] == Op.REMOUNT])
        try:
            result = self._batch.step(rows, op[rows], rho[rows], stand[rows], slot[rows])
        except BaseException:
            self._restore_streams(saved)
            raise
        obs = self._copy_obs()
        for key, value in result.obs.items():
            obs[key][rows] = value
        reward, terminated, truncated = np.zeros(n), np.zeros(n, bool), np.zeros(n, bool)
        reward[rows], terminated[rows], truncated[rows] = (result.reward, result.terminated,
                                                           result.truncated)
        ending = (terminated | truncated) if self.autoreset_mode == AutoresetMode.SAME_STEP \
            else np.zeros(n, dtype=bool)
        # An env that resets on this step shows its reset's info (SyncVectorEnv's way).
        info: dict[str, Any] = {}
        _add_step_infos(info, n, rows, result, only=~ending[rows])
        if ending.any():
            info["final_obs"] = np.full(n, None, dtype=object)
            for i in np.flatnonzero(ending):
                info["final_obs"][i] = {key: value[i].copy() for key, value in obs.items()}
            info["_final_obs"] = ending.copy()
            final: dict[str, Any] = {}
            _add_step_infos(final, n, rows, result, only=ending[rows])
            info["final_info"], info["_final_info"] = final, ending.copy()
        renew = np.flatnonzero(resetting | ending)
        self._start(renew, [None] * len(renew), None, obs)
        _add_reset_infos(info, n, renew)
        self._obs = obs
        self._ended = (terminated | truncated) & ~ending
        return self._copy_obs(), reward, terminated, truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        self._batch.backend.close()

    # -- helpers ------------------------------------------------------------------------------
    def _start(self, rows: np.ndarray, seeds: list[int | None], machine: MachineParams | None,
               obs: dict[str, np.ndarray]) -> None:
        """New episodes for envs ``rows``; their first observation goes into ``obs``.  A
        failure leaves every env, random streams included, as it was."""
        if not len(rows):
            return
        saved = self._saved_streams(rows)
        streams, used = self._new_streams(rows, seeds)
        try:
            first = self._batch.reset(rows, streams, machine)
        except BaseException:
            self._restore_streams(saved)
            raise
        self._keep_streams(rows, streams, used)
        for key, value in first.items():
            obs[key][rows] = value

    def _require(self) -> None:
        if not self._started:
            raise RuntimeError("call reset() before using the environment")

    def _copy_obs(self) -> dict[str, np.ndarray]:
        return {key: value.copy() for key, value in self._obs.items()}


class SubLab:
    """One env of a lab vector env as an agent sees a lone lab: ``unwrapped`` (itself),
    the notebook ``records``, the ``noise``, the machines' ``design`` and the lab's settings
    and spaces; no truth."""

    def __init__(self, envs: OrthoglideLabVectorEnv, index: int) -> None:
        self._envs, self.index = envs, index
        settings = envs.settings
        self.noise, self.n_stands, self.tracker = settings.noise, settings.stands, settings.tracker
        self.budget_s, self.travel = settings.budget_s, settings.travel
        self.design = settings.design
        self.action_space: spaces.Dict = envs.single_action_space
        self.observation_space: spaces.Dict = envs.single_observation_space

    @property
    def unwrapped(self) -> SubLab:
        return self

    @property
    def records(self) -> list[Record]:
        return self._envs.records[self.index]


def _add(info: dict[str, Any], n: int, key: str, rows: np.ndarray, values: Sequence) -> None:
    """Put ``values`` of envs ``rows`` under ``key`` of a vector info, with its mask."""
    if not len(rows):
        return
    dtype = INFO_DTYPES[key]
    if key not in info:
        info[key] = (np.full(n, None, dtype=object) if dtype is object
                     else np.zeros(n, dtype=dtype))
        info[f"_{key}"] = np.zeros(n, dtype=bool)
    if dtype is object:
        for i, value in zip(rows, values, strict=True):
            info[key][i] = value
    else:
        info[key][rows] = values
    info[f"_{key}"][rows] = True


def _add_reset_infos(info: dict[str, Any], n: int, rows: np.ndarray) -> None:
    """The single lab's reset info of envs ``rows`` (replacing what they had)."""
    for key, value in (("op", "reset"), ("step_time_s", 0.0), ("collision", "")):
        _add(info, n, key, rows, [value] * len(rows))
    _add(info, n, "overtravel", rows, [[] for _ in rows])


def _add_step_infos(info: dict[str, Any], n: int, rows: np.ndarray, result: StepResult,
                    only: np.ndarray | None = None) -> None:
    """The single lab's step info of envs ``rows`` (those of ``only``, if given)."""
    keep = np.ones(len(rows), dtype=bool) if only is None else only
    mine = rows[keep]
    _add(info, n, "op", mine, [OP_NAMES[k] for k in result.op[keep]])
    _add(info, n, "step_time_s", mine, result.seconds[keep])
    for key in ("overtravel", "collision", "refused"):
        values = getattr(result, key)
        _add(info, n, key, mine, [values[r] for r in np.flatnonzero(keep)])
    ended = keep & (result.terminated | result.truncated)
    _add(info, n, "is_success", rows[ended], result.success[ended])
    _add(info, n, "predicted_tcp_rigid_mm", rows[ended], result.predicted[ended])
