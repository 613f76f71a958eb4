"""The native vector env of ``OrthoglideLab-v0``: N calibration labs stepped together,
built by ``gymnasium.make_vec("OrthoglideLab-v0", num_envs=N)``."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from orthoglide_env.envs.lab import LabFace
from orthoglide_env.envs.vector import EngineVectorEnv
from orthoglide_env.instruments.dial import GaugeNoise
from orthoglide_env.instruments.gauges import Gauge
from orthoglide_env.lab.notebook import Record
from orthoglide_env.lab.settings import lab_settings, lab_spaces
from orthoglide_env.lab.spec import LAB_VECTOR, check_arguments, signature


class OrthoglideLabVectorEnv(LabFace, EngineVectorEnv):
    """``num_envs`` calibration labs (``OrthoglideLab-v0``, whose docstring is the spec) on
    the exact backend, stepped together as :class:`~orthoglide_env.envs.vector.
    EngineVectorEnv` says: env ``i`` is one ``gym.make("OrthoglideLab-v0", ...)`` reset
    with seed ``seed + i`` in a ``SyncVectorEnv``, bit for bit, notebooks included.

    Spaces are the single lab's, batched: the action is a dict of arrays, ``op`` (N,),
    ``rho`` (N, 3), ``stand`` (N,), ``slot`` (N,); each observation key gains a first axis
    of N.  An action one env's lab would reject (outside its space) raises ``ValueError``
    naming the env and no env steps; a refused operation is refused in its env only.
    Reset options: the single lab's ``machine``, and ``reset_mask``.

    Per env, for agents and estimators: ``records[i]`` (the notebook), ``sub_env(i)`` (a
    read-only view of env ``i`` as an agent sees a lone lab, ``slots`` included); for all
    of them, ``slots`` (the design's slot catalogue); for scoring only:
    ``true_machines`` (a :class:`MachineParams` batch (N,)), ``true_gauges(i)``,
    ``true_tracker_frames``.  With the ``information`` reward each env sums its own
    information at every step (a loop over envs); at an episode's end the predicted error
    of ``info["predicted_tcp_rigid_mm"]`` is computed once per distinct design.
    """

    __signature__ = signature(LAB_VECTOR)

    #: The lab's version (:class:`~orthoglide_env.envs.lab.OrthoglideLabEnv`'s history).
    version: int = 0

    def __init__(self, **kwargs: Any) -> None:
        args = check_arguments(LAB_VECTOR, kwargs)
        settings = lab_settings(args, self.version)
        self.design = settings.design
        self._start_engine(settings, args["num_envs"], args["autoreset_mode"],
                           lab_spaces(settings))

    # -- per env: notebooks, settings, truth --------------------------------------------------
    @property
    def noise(self) -> GaugeNoise:
        return self.settings.noise

    @property
    def records(self) -> list[list[Record]]:
        """Every env's notebook (its records, in order)."""
        return [book.records for book in self._batch.notebooks]

    def records_of(self, i: int) -> list[Record]:
        """Env ``i``'s notebook (its records, in order), without the others' list."""
        return self._batch.notebooks[i].records

    def sub_env(self, i: int) -> SubLab:
        """Env ``i`` as an agent sees a lone lab (see :class:`SubLab`)."""
        return SubLab(self, i)

    def true_gauges(self, i: int) -> list[Gauge]:
        """Every installation of env ``i``'s episode, in mounting order (scoring only)."""
        self._require()
        return self._batch.true_gauges(i)

    @property
    def true_tracker_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Every env's tracker rotation (N, 3, 3) and position (N, 3) (scoring only)."""
        self._require()
        return self._batch.tracker_rotation.copy(), self._batch.tracker_position.copy()


class SubLab:
    """One env of a lab vector env as an agent sees a lone lab: ``unwrapped`` (itself),
    the notebook ``records``, the ``noise`` and the lab's settings and spaces; no truth."""

    def __init__(self, envs: OrthoglideLabVectorEnv, index: int) -> None:
        self._envs, self.index = envs, index
        settings = envs.settings
        self.noise, self.n_stands, self.tracker = settings.noise, settings.stands, settings.tracker
        self.budget_s, self.travel = settings.budget_s, settings.travel
        self.design, self.slots = settings.design, settings.slots
        self.reference, self.instruments = settings.reference, settings.instruments
        self.conditions = settings.conditions
        self.action_space: spaces.Dict = envs.single_action_space
        self.observation_space: spaces.Dict = envs.single_observation_space

    @property
    def unwrapped(self) -> SubLab:
        return self

    @property
    def records(self) -> list[Record]:
        # Not ``records[index]``: every lab's notebook asked for is a list of them all,
        # once per machine of a chunk.
        return self._envs.records_of(self.index)


class OrthoglideLabV1VectorEnv(OrthoglideLabVectorEnv):
    """``OrthoglideLab-v1``'s native vector env: :class:`OrthoglideLabVectorEnv` with the
    interferometer in its spaces."""

    version = 1


class OrthoglideLabV2VectorEnv(OrthoglideLabVectorEnv):
    """``OrthoglideLab-v2``'s native vector env: :class:`OrthoglideLabVectorEnv` with the
    interferometer and the ballbar in its spaces."""

    version = 2


class OrthoglideLabV3VectorEnv(OrthoglideLabVectorEnv):
    """``OrthoglideLab-v3``'s native vector env: :class:`OrthoglideLabVectorEnv` with the
    interferometer, the ballbar and the step gauge in its spaces."""

    version = 3


class OrthoglideLabV4VectorEnv(OrthoglideLabVectorEnv):
    """``OrthoglideLab-v4``'s native vector env: :class:`OrthoglideLabV3VectorEnv`'s spaces
    and the action's ``laser`` key ((N,) of 0 or 1)."""

    version = 4
