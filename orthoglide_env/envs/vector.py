"""What both native vector envs share: N episodes of the lab engine stepped together
(:class:`EngineVectorEnv`)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from orthoglide_env.envs.base import Face, check_seed
from orthoglide_env.instruments.slots import GaugeSpec
from orthoglide_env.lab.engine import LabBatch, StepResult
from orthoglide_env.lab.machines import ExactMachines
from orthoglide_env.lab.operations import CODE
from orthoglide_env.lab.settings import LabSettings
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.world.truth import World

#: What ``options["reset_mask"]`` must be, as Gymnasium's vector envs take it.
RESET_MASK = "reset_mask"


class EngineVectorEnv(Face, VectorEnv):
    """``num_envs`` episodes of the lab engine on the exact backend, stepped together.

    Env ``i`` behaves exactly as one single env of the same arguments reset with seed
    ``seed + i`` inside a ``SyncVectorEnv`` with the same ``autoreset_mode``: the same
    observations, rewards, terminations, truncations and infos, bit for bit.  The
    constructor takes the single env's arguments with the same rules, plus ``num_envs``
    and ``autoreset_mode``; ``backend="pybullet"`` raises ``ValueError`` (use
    ``vectorization_mode="sync"`` or ``"async"`` for simulated machines).  An action one
    env would refuse raises ``ValueError`` naming the env, and no env steps; the action
    row of an env that autoresets on this step is not used.

    Autoreset (``autoreset_mode``, Gymnasium's, in ``metadata["autoreset_mode"]``):
    ``NEXT_STEP`` (default) resets an ended env on its next step, which returns its first
    observation, reward 0 and both flags False; ``SAME_STEP`` resets it at once and
    returns the ended episode's last observation and info in ``info["final_obs"]`` and
    ``info["final_info"]``; ``DISABLED`` leaves it to ``reset(options={"reset_mask":
    ...})`` and refuses to step an ended env (``RuntimeError``).  An autoreset draws a
    machine from the preset.

    Reset: ``seed`` None (each env keeps its stream), an int (env ``i`` gets ``seed + i``)
    or a list of N ints or None; ``options``: the single env's (for every env reset) and
    ``reset_mask``, a boolean array (N,) with at least one True: only those envs reset
    (the others keep their episode and last observation row, and have no info).  The
    first reset resets all.  A refused reset raises ``ValueError`` and changes nothing,
    random streams included.  Infos: each env's is the single env's, in Gymnasium's vector
    form (``VectorEnv._add_info``, as ``SyncVectorEnv`` builds it: an array and a ``_key``
    mask per key).

    A subclass, with its :class:`~orthoglide_env.envs.base.Face`, calls
    :meth:`_start_engine`."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [],
                                          "autoreset_mode": AutoresetMode.NEXT_STEP}

    def _start_engine(self, settings: LabSettings, num_envs: int,
                      autoreset_mode: AutoresetMode,
                      single_spaces: tuple[spaces.Space, spaces.Dict]) -> None:
        if settings.backend != "exact":
            raise ValueError("the native vector env runs backend='exact' only; for PyBullet "
                             "machines use vectorization_mode='sync' or 'async'")
        self.settings, self.num_envs, self.autoreset_mode = settings, num_envs, autoreset_mode
        self.metadata = {**self.metadata, "autoreset_mode": autoreset_mode}
        self.render_mode = None
        self.single_action_space, self.single_observation_space = single_spaces
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._streams: list[np.random.Generator | None] = [None] * num_envs
        self._seeds: list[int | None] = [None] * num_envs
        self._batch = LabBatch(settings, num_envs, ExactMachines())
        self._batch.streams = self._streams  # the batch draws from the envs' streams
        self.gauge_layouts = [settings.layout] * num_envs
        self._ended = np.zeros(num_envs, dtype=bool)
        self._obs = {key: np.zeros(space.shape, space.dtype)
                     for key, space in self.observation_space.items()}

    # -- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        seeds = self._seed_list(seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"reset options must be a dict or None, got {options!r}")
        options = dict(options or {})
        mask = self._reset_mask(options.pop(RESET_MASK, None))
        machine, world, layout = self._reset_options(options)
        rows = np.flatnonzero(mask)
        obs = self._copy_obs()
        self._start(rows, [seeds[i] for i in rows], machine, layout, obs, world)
        self._obs = obs
        self._ended[rows] = False
        info = self._add_infos({}, [self._reset_info(i) for i in rows], rows)
        return self._copy_obs(), info

    def step(self, actions: Any
             ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._require()
        n = self.num_envs
        if self.autoreset_mode == AutoresetMode.DISABLED and self._ended.any():
            raise RuntimeError(f"env(s) {np.flatnonzero(self._ended).tolist()} ended: reset "
                               "them (options={'reset_mask': ...}) before stepping again")
        resetting = self._ended if self.autoreset_mode == AutoresetMode.NEXT_STEP else (
            np.zeros(n, dtype=bool))
        parts = self._actions(actions, (n,), ~resetting)
        op = parts[0]
        rows = np.flatnonzero(~resetting)
        # Only a re-mount draws before it can fail (a slot its machine cannot reach): then
        # no env has stepped and no stream has moved.
        with self._streams_kept(rows[op[rows] == CODE.REMOUNT]):
            result = self._batch.step(rows, *(part[rows] for part in parts))
        obs = self._copy_obs()
        for key, value in result.obs.items():
            if key in obs:
                obs[key][rows] = value
        reward, terminated, truncated = np.zeros(n), np.zeros(n, bool), np.zeros(n, bool)
        reward[rows], terminated[rows], truncated[rows] = (result.reward, result.terminated,
                                                           result.truncated)
        ending = (terminated | truncated) if self.autoreset_mode == AutoresetMode.SAME_STEP \
            else np.zeros(n, dtype=bool)
        # An env that resets on this step shows its reset's info (SyncVectorEnv's way).
        last = ending[rows]
        info = self._step_infos(result, np.flatnonzero(~last), rows)
        final = self._step_infos(result, np.flatnonzero(last), rows)
        if ending.any():
            info["final_obs"] = np.full(n, None, dtype=object)
            for i in np.flatnonzero(ending):
                info["final_obs"][i] = {key: value[i].copy() for key, value in obs.items()}
            info["_final_obs"] = ending.copy()
            info["final_info"], info["_final_info"] = final, ending.copy()
        renew = np.flatnonzero(resetting | ending)
        self._start(renew, [None] * len(renew), None, None, obs)
        self._add_infos(info, [self._reset_info(i) for i in renew], renew)
        self._obs = obs
        self._ended = (terminated | truncated) & ~ending
        return self._copy_obs(), reward, terminated, truncated, info

    def _step_infos(self, result: StepResult, picked: np.ndarray, rows: np.ndarray
                    ) -> dict[str, Any]:
        """The vector infos of rows ``picked`` of ``result`` (a step of envs ``rows``): key
        by key from the face's columns where it gives them, else from each env's info."""
        envs = rows[picked]
        columns = self._step_columns(result, picked) if len(picked) else None
        if columns is None:
            return self._add_infos({}, [self._step_info(result, r, i)
                                        for r, i in zip(picked, envs, strict=True)], envs)
        return self._add_columns({}, columns, envs)

    def _add_infos(self, vector_infos: dict[str, Any], infos: Sequence[dict[str, Any]],
                   envs: np.ndarray) -> dict[str, Any]:
        """``_add_info`` of ``infos[k]`` for env ``envs[k]``, in turn: the same arrays and
        masks, made a key at a time when every info is flat with the same keys (a call per
        env and key cost a third of a step of 500 envs)."""
        if not infos:
            return vector_infos
        keys = infos[0].keys()
        nested = any(isinstance(v, dict) or k == "final_obs" for k, v in infos[0].items())
        if nested or any(d.keys() != keys for d in infos):
            for d, i in zip(infos, envs, strict=True):
                self._add_info(vector_infos, d, int(i))
            return vector_infos
        return self._add_columns(vector_infos, {key: [d[key] for d in infos] for key in keys},
                                 envs)

    def _add_columns(self, vector_infos: dict[str, Any], columns: dict[str, list[Any]],
                     envs: np.ndarray) -> dict[str, Any]:
        """:meth:`_add_infos` of flat infos with the same keys given key by key: each key's
        values for ``envs`` in turn."""
        for key, values in columns.items():
            if key not in vector_infos:  # Gymnasium's rule picks the array's type
                self._add_info(vector_infos, {key: values[0]}, int(envs[0]))
            array = vector_infos[key]
            if array.dtype == object:  # element by element: lists stay lists
                for i, v in zip(envs, values, strict=True):
                    array[i] = v
            else:
                array[envs] = values
            vector_infos[f"_{key}"][envs] = True
        return vector_infos

    def close_extras(self, **kwargs: Any) -> None:
        self._batch.backend.close()

    @property
    def true_machines(self) -> MachineParams:
        """Every env's machine, a batch (N,) (scoring only)."""
        return self._batch.require()

    @property
    def true_worlds(self) -> World | None:
        """Every env's world, a batch (N,) (None under ideal conditions; scoring only)."""
        self._batch.require()
        return self._batch.world

    def true_faults(self, i: int) -> list[dict[str, Any]]:
        """The faults that happened so far in env ``i``'s episode (empty in a lab without
        faults; scoring only)."""
        self._batch.require()
        faults = self._batch.faults
        return [] if faults is None else [e.to_dict() for e in faults.log[i]]

    # -- episodes and streams -----------------------------------------------------------------
    def _start(self, rows: np.ndarray, seeds: list[int | None], machine: MachineParams | None,
               layout: tuple[GaugeSpec, ...] | None, obs: dict[str, np.ndarray],
               world: World | None = None) -> None:
        """New episodes for envs ``rows``; their first observation goes into ``obs``.  A
        failure leaves every env, random streams included, as it was."""
        if not len(rows):
            return
        with self._streams_kept(rows):
            streams, used = self._new_streams(rows, seeds)
            new = self._batch.reset(rows, streams, machine, layout, world)
        for i, stream, value in zip(rows, streams, used, strict=True):
            self._streams[i], self._seeds[i] = stream, value
            self.gauge_layouts[i] = self.settings.layout if layout is None else layout
        for key, value in new.items():
            if key in obs:
                obs[key][rows] = value

    def _require(self) -> None:
        self._batch.require()

    def _copy_obs(self) -> dict[str, np.ndarray]:
        return {key: value.copy() for key, value in self._obs.items()}

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
        own; and their seeds.  Nothing is stored."""
        pairs = [seeding.np_random(seed) if seed is not None
                 else (self._stream(int(i)), self._seeds[i])
                 for i, seed in zip(rows, seeds, strict=True)]
        return [stream for stream, _ in pairs], [value for _, value in pairs]

    @contextlib.contextmanager
    def _streams_kept(self, rows: np.ndarray) -> Iterator[None]:
        """The streams (and seeds) of envs ``rows`` as they stand, put back if the block
        raises."""
        saved = [(int(i), self._streams[i],
                  None if self._streams[i] is None else self._streams[i].bit_generator.state,
                  self._seeds[i]) for i in rows]
        try:
            yield
        except BaseException:
            for i, stream, state, seed in saved:
                self._streams[i], self._seeds[i] = stream, seed
                if stream is not None:
                    stream.bit_generator.state = state
            raise

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
        if self._batch.machines is None and not mask.all():
            raise RuntimeError("call reset() for every env before resetting a few")
        return mask
