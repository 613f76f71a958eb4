"""What both envs share: a lone episode of the lab engine (:class:`EngineEnv`), its reset
options and seeds, and the :class:`Face` each env's native vector env shares with it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from orthoglide_env.instruments.gauges import Gauge
from orthoglide_env.instruments.slots import GaugeSpec
from orthoglide_env.lab.engine import LabBatch, StepResult
from orthoglide_env.lab.machines import ExactMachines, SimulatedMachine
from orthoglide_env.lab.settings import LabSettings, render_modes
from orthoglide_env.lab.spec import RENDER_MODES, Layout
from orthoglide_env.model.errors import MachineParams, check_validity
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import read_machine
from orthoglide_env.world.truth import World

#: The one episode of a lone env, in its batch.
ROW = np.zeros(1, dtype=np.intp)


def check_seed(seed: Any) -> None:
    """Gymnasium's rule (None or an int >= 0), with booleans refused and a ValueError."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise ValueError(f"reset seed must be None or an integer >= 0, got {seed!r}")


def reset_options(options: Any, settings: LabSettings, layouts: bool = False
                  ) -> tuple[MachineParams | None, World | None, tuple[GaugeSpec, ...] | None]:
    """The checked reset options: the given machine of the lab's design (None: draw one),
    its world (None: draw one, when the conditions have effects) and, where the env takes
    a ``gauges`` option (``layouts``), the layout (None: the constructor's)."""
    allowed = ("machine", "gauges") if layouts else ("machine",)
    if options is None:
        options = {}
    if not isinstance(options, Mapping):
        raise ValueError(f"reset options must be a dict or None, got {options!r}")
    unknown = [key for key in options if key not in allowed]
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; allowed: {', '.join(allowed)}")
    layout = Layout().check("reset option 'gauges'", options.get("gauges"))
    if layout is not None and len(layout) != settings.stands:
        raise ValueError(f"reset option 'gauges': this env observes {settings.stands} gauges; "
                         f"a layout of {len(layout)} needs an env built with gauges=[...] of "
                         "that size")
    return (*_machine_option(options.get("machine"), settings), layout)


def _machine_option(value: Any, settings: LabSettings
                    ) -> tuple[MachineParams | None, World | None]:
    """The ``machine`` reset option and its world.  None, like leaving the key out, draws a
    machine from the preset (as ``seed=None`` and ``options=None`` mean "nothing given" in
    Gymnasium); anything else must be a dict in the machine file schema (a machine of the
    lab's design unless it names its own, with a ``world`` drawn under the lab's
    conditions or none) or a ``MachineParams`` of the lab's design, inside the design's
    validity range."""
    design = settings.design
    if value is None:
        return None, None
    try:
        if isinstance(value, MachineParams):
            if value.design != design:
                raise ValueError("the machine's design is not the lab's (give the env its "
                                 "design: gym.make(..., design=...))")
            return check_validity(value), None
        if isinstance(value, dict):
            machine, world = read_machine(value, design=design)
            return machine, _world_option(world, settings)
    except ValueError as exc:
        raise ValueError(f"reset option 'machine': {exc}") from None
    raise ValueError("reset option 'machine' must be a dict in the machine file schema, a "
                     "MachineParams or None (draw one from the preset), got "
                     f"{type(value).__name__} {value!r}")


def _drawn(conditions: Conditions) -> tuple:
    """What of ``conditions`` a world's truth depends on: not the thermometer's error, which
    the lab draws (files written before the thermometer existed do not name it)."""
    return (conditions.name, tuple(e for e in conditions.effects if e != "thermometer"),
            conditions.indicator)


def _world_option(world: World | None, settings: LabSettings) -> World | None:
    """A machine file's world, if this lab can replay it: drawn under its conditions, for
    as many stands."""
    if world is None:
        return None
    if _drawn(world.conditions) != _drawn(settings.conditions):
        raise ValueError(f"its world was drawn under the conditions "
                         f"{world.conditions.label!r}; this lab's are "
                         f"{settings.conditions.label!r} (build it with conditions="
                         f"{world.conditions.to_dict()})")
    if world.dial_range.shape[1] != settings.stands:
        raise ValueError(f"its world has {world.dial_range.shape[1]} stands; this lab has "
                         f"{settings.stands}")
    return world


class Face:
    """What a face of the engine (``OrthoglideLab-v0``'s, ``OrthoglideCalibration-v0``'s)
    says, the same for its lone env (:class:`EngineEnv`) and its native vector env: how
    its actions are checked and how its infos look; ``gauges`` reset options are taken
    where :attr:`LAYOUT_OPTION` is true."""

    LAYOUT_OPTION: ClassVar[bool] = False
    settings: LabSettings
    #: Each env's gauge layout in this episode.
    gauge_layouts: list[tuple[GaugeSpec, ...]]
    _batch: LabBatch

    def _actions(self, actions: Any, shape: tuple[int, ...], used: np.ndarray | None
                 ) -> tuple[np.ndarray, ...]:
        """``op``, ``rho``, ``stand``, ``slot`` (each of ``shape``: ``()`` for a lone env,
        ``(N,)`` for N) of the checked ``actions`` of the envs ``used`` (None: all), and
        where the face's action has it, whether each move reads the laser
        (``OrthoglideLab-v4``), or ``ValueError``."""
        raise NotImplementedError

    def _step_info(self, result: StepResult, r: int, i: int) -> dict[str, Any]:
        """The single env's info of row ``r`` of ``result``, env ``i``'s step."""
        raise NotImplementedError

    def _step_columns(self, result: StepResult, rows: np.ndarray
                      ) -> dict[str, list[Any]] | None:
        """The infos of ``result``'s ``rows`` (:meth:`_step_info` of each) key by key, one
        list of values per key in the order of ``rows``, when they are flat and have the
        same keys; None where they are not, or to build each env's dict."""
        return None

    def _reset_info(self, i: int) -> dict[str, Any]:
        """The single env's info of env ``i``'s reset."""
        raise NotImplementedError

    def _reset_options(self, options: Any
                       ) -> tuple[MachineParams | None, World | None,
                                  tuple[GaugeSpec, ...] | None]:
        return reset_options(options, self.settings, self.LAYOUT_OPTION)


class EngineEnv(Face, gym.Env):
    """One episode of the lab engine with ``settings`` and a face's spaces.

    A refused reset changes nothing: the episode before it goes on (machine, gauges,
    posture and random stream), or, before the first good reset, every ``step`` still
    raises ``RuntimeError``."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": list(RENDER_MODES), "render_fps": 4}

    def _start_engine(self, settings: LabSettings,
                      spaces: tuple[gym.spaces.Space, gym.spaces.Dict]) -> None:
        self.settings = settings
        self.render_mode = settings.render_mode
        # What this instance can draw: the class lists every mode for gym.make; the exact
        # backend draws nothing and a window needs a display.
        self.metadata = {**self.metadata, "render_modes": render_modes(settings.backend)}
        self.action_space, self.observation_space = spaces
        machines = (ExactMachines() if settings.backend == "exact" else
                    SimulatedMachine(settings.motion, gui=settings.render_mode == "human"))
        self._batch = LabBatch(settings, 1, machines)
        self.gauge_layouts = [settings.layout]
        self._started = False

    # -- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        # Every option is checked before anything changes: a refused reset leaves the
        # episode (and its random stream) as it was.
        check_seed(seed)
        machine, world, layout = self._reset_options(options)
        rng = self._np_random
        saved = (rng, None if rng is None else rng.bit_generator.state, self._np_random_seed)
        super().reset(seed=seed)
        try:
            obs = self._batch.reset(ROW, [self.np_random], machine, layout, world)
        except BaseException:
            self._np_random, self._np_random_seed = saved[0], saved[2]
            if saved[0] is not None:
                saved[0].bit_generator.state = saved[1]
            raise
        self._started = True
        self.gauge_layouts[0] = self.settings.layout if layout is None else layout
        return self._row(obs), self._reset_info(0)

    def step(self, action: Any
             ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        self._require()
        result = self._batch.step(ROW, *(part[None] for part in self._actions(action, (), None)))
        return (self._row(result.obs), float(result.reward[0]), bool(result.terminated[0]),
                bool(result.truncated[0]), self._step_info(result, 0, 0))

    def _row(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """This env's observation: its keys of the engine's, the lone episode's row."""
        return {key: value[0] for key, value in obs.items()
                if key in self.observation_space.spaces}

    # -- ground truth, for the scorer only --------------------------------------------------
    @property
    def true_machine(self) -> MachineParams:
        return self._require()[0]

    @property
    def true_world(self) -> World | None:
        """The machine's drawn world beyond its geometry (None under ideal conditions)."""
        self._require()
        world = self._batch.world
        return None if world is None else world[0]

    @property
    def true_faults(self) -> list[dict[str, Any]]:
        """The faults that happened so far in this episode (their ``FaultEvent.to_dict``;
        empty in a lab without faults): the truth, for scoring only."""
        self._require()
        faults = self._batch.faults
        return [] if faults is None else [e.to_dict() for e in faults.log[0]]

    @property
    def true_gauges(self) -> list[Gauge]:
        """Every installation of the episode, in mounting order (scoring only)."""
        self._require()
        return self._batch.true_gauges(0)

    def tcp(self) -> np.ndarray:
        """The true TCP (mm), as the machine shows it (scoring and fidelity checks only)."""
        self._require()
        return self._batch.true_tcp(0)

    @property
    def simulated_machine(self) -> Any:
        """The PyBullet machine of the episode (``backend='pybullet'``; fidelity checks)."""
        self._require()
        machine = getattr(self._batch.backend, "machine", None)
        if machine is None:
            raise ValueError("the exact backend has no simulated machine")
        return machine

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            self._require()
            return self._batch.backend.render()
        return None

    def close(self) -> None:
        self._batch.backend.close()

    def _require(self) -> MachineParams:
        if not self._started:
            raise RuntimeError("call reset() before using the environment")
        return self._batch.require()
