"""Gymnasium environment: one episode is one calibration experiment on one machine.

The pieces both envs use (this one and the vector env of
:mod:`orthoglide_env.envs.calibration_vector`)
live here as functions: the checks of constructor arguments, reset options, seeds and
actions, the spaces, the observation and the info.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from orthoglide_env.envs.backend import MOTION_MODES, ExactMachine, MachineBackend
from orthoglide_env.envs.task import CalibrationTask, Reading
from orthoglide_env.instruments.gauges import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    DEFAULT_TRAVEL,
    PAPER_LAYOUT,
    Gauge,
    GaugeNoise,
    GaugeSpec,
    Status,
    check_noise,
    install,
    layout_from_names,
    zero_gauges,
)
from orthoglide_env.model.collisions import collision_names
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import (
    DEFAULT_PRESET,
    ErrorPreset,
    MachineParams,
    check_rho,
    check_validity,
    get_preset,
)
from orthoglide_env.model.kinematics import UnreachableError
from orthoglide_env.sim.display import display_problem, require_display

if TYPE_CHECKING:  # PyBullet is imported only by the backend that needs it
    from orthoglide_env.sim.simulator import Simulator

BACKENDS: tuple[str, ...] = ("pybullet", "exact")
#: Encoders may read a hair outside the control limits after settling (solver residue
#: ~1e-9 mm); the observation box leaves this margin so an observation is always inside.
ENCODER_MARGIN: float = 1.0
RESET_OPTIONS: tuple[str, ...] = ("machine", "gauges")
#: How ``info["status"]`` names each :class:`~orthoglide_env.instruments.gauges.Status` code,
#: indexed
#: by the code.
STATUS_LABELS: np.ndarray = np.array([s.name.lower().replace("_", "-") for s in Status])
#: Render modes any instance may offer (an instance lists what it can draw here).
RENDER_MODES: tuple[str, ...] = ("rgb_array", "human")


class OrthoglideCalibrationEnv(gym.Env):
    """A calibration experiment on a virtual Orthoglide with dial gauges on its base.

    Each episode draws a machine (or takes one from ``reset(options={"machine": ...})``),
    installs the gauges on it at the Zero posture (with the preset's installation errors)
    and zeroes them there.  The agent commands joint targets; the machine moves, settles
    and the lab reads its gauges and encoders.

    Action space
    ------------
    ==========  ======================================  ==========  =========
    index       meaning                                 unit        range
    ==========  ======================================  ==========  =========
    0, 1, 2     target control coordinates rho_x/y/z    mm          [-100, 60]
    ==========  ======================================  ==========  =========

    A target outside the joint limits, NaN, inf, of the wrong shape or not made of real
    numbers (text, booleans, complex numbers) raises ``ValueError`` (a real controller
    refuses it) unless the env was built with ``clip_actions=True``, which clips finite
    targets into the limits.  So does a target at which this machine cannot be assembled
    (beyond the singularity near the (60, 60, 60) corner, on machines far from nominal):
    the machine stays where it was.

    Observation space (``Dict``)
    ----------------------------
    ==========  ====================================================  ======  ===============
    key         meaning                                               unit    range
    ==========  ====================================================  ======  ===============
    gauges      one reading per installed gauge, in the layout order  mm      [-travel, travel]
    valid       1 where the gauge touches its bar within travel       -       {0, 1}
    joints      encoder readings                                      mm      [-101, 61]
    ==========  ====================================================  ======  ===============

    A gauge that is not valid reads 0.0 (NaN is never inside a Box): use ``valid``.

    Reward
    ------
    Minus the seconds a real experiment spends on the step: travel at
    :data:`~orthoglide_env.envs.task.DRIVE_SPEED` mm/s (axes together), plus the settle-and-read
    dwell, plus :data:`~orthoglide_env.envs.task.OVERTRAVEL_PENALTY` for every gauge pushed past
    its travel toward its stand on this move.

    Overtravel: a bar that presses a gauge past its travel toward its stand (into the
    plunger or the gauge body, on the measuring face or not) makes that gauge's reading
    invalid, is named in ``info["overtravel"]`` on the move that causes it and costs the
    penalty.  With the paper's six gauges all installed, the Min postures do this to the
    other legs' gauges (the paper installs one leg's gauges at a time).

    Termination
    -----------
    ``terminated`` when moving parts that must never meet touch: parts of different legs
    (bars, couplers, carriages), or the platform and a bar or carriage;
    ``info["collision"]`` names the pairs (``"x_coupler/y_coupler, ..."``).  PyBullet's
    contact check and, on the exact backend, the separating-axis test of
    :mod:`orthoglide_env.model.collisions` decide it.  On the nominal and realistic machines the
    nearest such parts stay more than 5 mm apart over the whole joint cube, so this guards
    machines far from nominal (given through the ``machine`` reset option).  Both backends
    check the posture reached, not the path to it.  The base has no collision geometry.
    Truncation comes from ``max_episode_steps``.

    Reset options
    -------------
    ``machine``: the true machine, a dict in the machine file schema
    (:meth:`MachineParams.from_dict`) or a ``MachineParams``, inside
    the prototype's validity range; left out or ``None`` (as ``seed=None`` means "none
    given"): drawn from the ``errors`` preset with ``np_random``.  Anything
    else (a list, ``0``, ``""``, ``False``) raises ``ValueError``.  ``gauges``: the layout
    of this episode, names such as ``"x-leg/y"`` or ``"z/x@0.3"`` or ``GaugeSpec``
    objects (left out or ``None``: the constructor's); it must hold as many gauges as the
    constructor's ``gauges`` (the observation space is fixed), otherwise ``ValueError``.
    Installation errors are drawn from the preset with ``np_random``; the gauges are then
    set up at mid-travel and zeroed at the Zero posture.

    Refused input
    -------------
    A bad constructor argument, reset option, seed or action raises ``ValueError`` whose
    one-line message names the input and the rule.  A refused ``reset`` or ``step``
    changes nothing: the episode before it goes on (its machine, gauges, posture and
    random stream), or, before the first good reset, every ``step`` still raises
    ``RuntimeError``.

    Render modes
    ------------
    ``rgb_array`` (TinyRenderer, no window) and ``human`` (a PyBullet GUI window), on the
    ``pybullet`` backend only.  An instance's ``metadata["render_modes"]`` lists what it
    can draw here: nothing on the ``exact`` backend, and ``human`` only where a display
    is available; ``render_mode="human"`` without one raises ``ValueError`` (PyBullet's
    GUI would end the process).

    Public attributes for calibrators: ``gauge_layout`` (this episode's tuple of
    ``GaugeSpec``), ``gauge_noise`` (the spec sheet's sigma and resolution), ``travel``.

    Info
    ----
    ``gauge_names``, ``status`` (per gauge: valid, no-contact, overtravel, missed),
    ``overtravel`` (gauges that went into overtravel on this step), ``step_time_s``,
    ``collision`` (empty string when none).  Only deterministic values.

    Ground truth (``true_machine``, ``true_gauges``) is on the unwrapped env for scoring;
    agents must not read it.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": list(RENDER_MODES), "render_fps": 4}

    def __init__(
        self,
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
    ) -> None:
        settings = EnvSettings.check(
            errors=errors, gauge_sigma=gauge_sigma, gauge_resolution=gauge_resolution,
            motion=motion, backend=backend, gauges=gauges, travel=travel,
            max_episode_steps=max_episode_steps, render_mode=render_mode,
            clip_actions=clip_actions,
        )
        self.settings = settings
        self.preset = settings.preset
        self.gauge_noise = settings.gauge_noise
        self._default_layout = settings.layout
        self.gauge_layout = settings.layout
        self.travel = settings.travel
        self.motion = settings.motion
        self.backend_name = settings.backend
        self.render_mode = settings.render_mode
        # What this instance can draw: the class lists every mode for gym.make; the exact
        # backend draws nothing and a window needs a display.
        self.metadata = {**self.metadata, "render_modes": _render_modes(backend)}
        self.clip_actions = settings.clip_actions
        self.max_episode_steps = settings.max_episode_steps
        self.task = CalibrationTask(self.gauge_noise)
        self.action_space, self.observation_space = settings.spaces()
        self._machine: MachineBackend | None = None
        # The PyBullet client, made at the first reset and reused by every episode after.
        self._sim: Simulator | None = None
        self._rho = np.zeros(3)
        self._steps = 0
        self._pressed = np.zeros(len(self.gauge_layout), dtype=bool)

    # -- ground truth, for the scorer only --------------------------------------------------
    @property
    def true_machine(self) -> MachineParams:
        return self._require_machine().machine

    @property
    def true_gauges(self) -> list:
        return self._require_machine().gauges

    # -- Gymnasium API -----------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        check_seed(seed)
        machine, layout = reset_options(options, self._default_layout)
        saved = self._random_state()
        super().reset(seed=seed)
        try:
            episode = self._new_episode(machine, layout)
        except BaseException:
            # A refused reset leaves no trace: the previous episode (or none) goes on with
            # the random stream it had, and its machine, where the new one took its place
            # in the shared client.
            self._np_random, self._np_random_seed = saved[0], saved[2]
            if saved[0] is not None:
                saved[0].bit_generator.state = saved[1]
            self._revive()
            raise
        if self._machine is not None:
            self._machine.close()
        self._machine, self.gauge_layout = episode.machine, episode.layout
        self._rho = np.zeros(3)
        self._steps = 0
        self._pressed = episode.pressed
        names = [g.slot for g in self.gauge_layout]
        return observation(episode.reading), step_info(names, episode.reading.status, [], 0.0,
                                                       "")

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        machine = self._require_machine()
        target = check_actions(action, (3,), self.clip_actions)
        try:
            machine.move(target, self.motion)
        except UnreachableError as exc:
            raise ValueError(f"action {target.tolist()} mm: {exc} on this machine; it stays "
                             "where it was") from None
        reading = self.task.read(machine, self.np_random)
        pressed = self.task.pressed(machine)
        new = self.task.new_overtravels(self._pressed, pressed)
        step_time = float(self.task.step_time(self._rho, target, new))
        collision = collision_label(machine.collision_mask())
        self._rho, self._pressed = target, pressed
        self._steps += 1
        truncated = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        names = [g.slot for g in self.gauge_layout]
        return observation(reading), -step_time, bool(collision), truncated, step_info(
            names, reading.status, overtravel_names(names, new), step_time, collision
        )

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self._require_machine().render()  # type: ignore[attr-defined]
        return None

    def close(self) -> None:
        if self._machine is not None:
            self._machine.close()
            self._machine = None
        if self._sim is not None:
            self._sim.close()
            self._sim = None

    # -- helpers -------------------------------------------------------------------------------
    def _random_state(self) -> tuple[np.random.Generator | None, dict | None, int | None]:
        """The random stream as it stands: generator, its state and its seed."""
        rng = self._np_random
        return rng, (None if rng is None else rng.bit_generator.state), self._np_random_seed

    def _new_episode(self, machine: MachineParams | None,
                     layout: tuple[GaugeSpec, ...]) -> _Episode:
        """Build a whole episode (machine, installed and zeroed gauges, first reading)
        without touching the current one; nothing is left open when it fails."""
        if machine is None:
            machine = self.preset.sample(self.np_random)
        gauges = install(layout, machine, travel=self.travel, preset=self.preset,
                         rng=self.np_random)
        built = self._build(machine, gauges)
        try:
            built.set_gauges(zero_gauges(gauges, built.gauge_distances()))
            reading = self.task.read(built, self.np_random)
            pressed = self.task.pressed(built)
        except BaseException:
            built.close()
            raise
        return _Episode(built, layout, reading, pressed)

    def _build(self, machine: MachineParams, gauges: list[Gauge]) -> MachineBackend:
        if self.backend_name == "exact":
            return ExactMachine(machine, gauges)
        try:
            from orthoglide_env.sim.pybullet import OrthoglideMachine
            from orthoglide_env.sim.simulator import Simulator
        except ImportError as exc:
            raise ImportError(
                f"the pybullet backend is not available ({exc}); use backend='exact'"
            ) from exc
        if self._sim is None:
            self._sim = Simulator(gui=self.render_mode == "human")
        return OrthoglideMachine(machine, gauges, sim=self._sim)

    def _revive(self) -> None:
        """Build the episode's machine again if a refused reset replaced it in the shared
        PyBullet client: at its posture, exactly as it was after a quasi-static move (a
        dynamic one settles to within 1e-13 mm of that)."""
        machine = self._machine
        if machine is not None and not getattr(machine, "in_client", True):
            machine.rebuild()  # type: ignore[attr-defined]

    def _require_machine(self) -> MachineBackend:
        if self._machine is None:
            raise RuntimeError("call reset() before using the environment")
        return self._machine


@dataclass(frozen=True)
class _Episode:
    """Everything a reset builds, swapped in only once all of it stands."""

    machine: MachineBackend
    layout: tuple[GaugeSpec, ...]
    reading: Reading
    pressed: np.ndarray


# -- what the single and the vector env share -------------------------------------------------
@dataclass(frozen=True)
class EnvSettings:
    """The checked constructor arguments of an env (see the env's docstring)."""

    preset: ErrorPreset
    gauge_noise: GaugeNoise
    layout: tuple[GaugeSpec, ...]
    travel: float
    motion: str
    backend: str
    render_mode: str | None
    clip_actions: bool
    max_episode_steps: int | None

    @classmethod
    def check(cls, *, errors: Any, gauge_sigma: Any, gauge_resolution: Any, motion: Any,
              backend: Any, gauges: Any, travel: Any, max_episode_steps: Any,
              render_mode: Any, clip_actions: Any) -> EnvSettings:
        """The settings, or ``ValueError`` naming the first bad argument and its rule."""
        if not isinstance(errors, str):
            raise ValueError(f"errors must be the name of an error preset, got {errors!r}")
        preset = get_preset(errors)
        if motion not in MOTION_MODES:
            raise ValueError(f"unknown motion {motion!r}; choose from {list(MOTION_MODES)}")
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose from {list(BACKENDS)}")
        if render_mode not in (None, *RENDER_MODES):
            raise ValueError(f"unknown render_mode {render_mode!r}")
        if backend == "exact" and render_mode is not None:
            raise ValueError("the exact backend has no picture: use backend='pybullet' to render")
        if render_mode == "human":
            require_display("render_mode='human'", "render_mode='rgb_array'")
        if max_episode_steps is not None and not (
            isinstance(max_episode_steps, int | np.integer)
            and not isinstance(max_episode_steps, bool) and max_episode_steps >= 1
        ):
            raise ValueError(f"max_episode_steps must be a positive integer or None, got "
                             f"{max_episode_steps!r}")
        if not isinstance(clip_actions, bool | np.bool_):
            raise ValueError(f"clip_actions must be True or False, got {clip_actions!r}")
        if isinstance(travel, bool) or not isinstance(travel, numbers.Real) or not (
            np.isfinite(travel) and travel > 0
        ):
            raise ValueError(f"travel must be a positive finite number (mm), got {travel!r}")
        return cls(preset=preset, gauge_noise=check_noise(gauge_sigma, gauge_resolution, travel),
                   layout=_layout(gauges), travel=float(travel), motion=motion,
                   backend=backend, render_mode=render_mode, clip_actions=bool(clip_actions),
                   max_episode_steps=(None if max_episode_steps is None
                                      else int(max_episode_steps)))

    def spaces(self) -> tuple[spaces.Box, spaces.Dict]:
        """The action and observation spaces of one env."""
        n = len(self.layout)
        action = spaces.Box(PROTOTYPE.rho_min, PROTOTYPE.rho_max, shape=(3,), dtype=np.float64)
        obs = spaces.Dict(
            {
                # A valid reading lies within +-travel/2 of its zero; the box leaves another
                # travel/2 (>= 25 sigma, see MAX_NOISE_FRACTION) for the noise.
                "gauges": spaces.Box(-self.travel, self.travel, shape=(n,), dtype=np.float64),
                "valid": spaces.MultiBinary(n),
                "joints": spaces.Box(PROTOTYPE.rho_min - ENCODER_MARGIN,
                                     PROTOTYPE.rho_max + ENCODER_MARGIN,
                                     shape=(3,), dtype=np.float64),
            }
        )
        return action, obs


def observation(reading: Reading) -> dict[str, np.ndarray]:
    """The observation of a reading (of one env, or of each env of a batch)."""
    return {"gauges": reading.gauges.astype(np.float64), "valid": reading.valid,
            "joints": reading.joints.astype(np.float64)}


def step_info(names: list[str], status: np.ndarray, overtravel: list[str], step_time: float,
              collision: str) -> dict[str, Any]:
    """One env's info: gauge ``names``, their ``status`` codes, the gauges that went into
    overtravel, the step's time and the collision label."""
    return {
        "gauge_names": list(names),
        "status": STATUS_LABELS[status].tolist(),
        "overtravel": overtravel,
        "step_time_s": step_time,
        "collision": collision,
    }


def overtravel_names(names: list[str], new: np.ndarray) -> list[str]:
    """Names of the gauges a :meth:`CalibrationTask.new_overtravels` mask marks."""
    return [name for name, hit in zip(names, new, strict=True) if hit]


def collision_label(mask: np.ndarray) -> str:
    """``info["collision"]``: the pairs in contact, comma separated (empty when none)."""
    return ", ".join(collision_names(mask))


def check_seed(seed: Any) -> None:
    """Gymnasium's rule (None or an int >= 0), with booleans refused and a ValueError."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise ValueError(f"reset seed must be None or an integer >= 0, got {seed!r}")


def reset_options(
    options: Any, default_layout: tuple[GaugeSpec, ...]
) -> tuple[MachineParams | None, tuple[GaugeSpec, ...]]:
    """The validated reset options: the given machine (None: draw one) and the layout."""
    if options is None:
        options = {}
    if not isinstance(options, Mapping):
        raise ValueError(f"reset options must be a dict or None, got {options!r}")
    unknown = [key for key in options if key not in RESET_OPTIONS]
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; allowed: "
                         f"{', '.join(RESET_OPTIONS)}")
    machine = _machine_option(options.get("machine"))
    gauges = options.get("gauges")
    layout = default_layout if gauges is None else _layout(gauges, "reset option 'gauges'")
    if len(layout) != len(default_layout):
        raise ValueError(
            f"reset option 'gauges': this env observes {len(default_layout)} "
            f"gauges; a layout of {len(layout)} needs an env built with gauges=[...] of "
            "that size"
        )
    return machine, layout


def check_actions(action: Any, shape: tuple[int, ...], clip: bool,
                  rows: np.ndarray | None = None) -> np.ndarray:
    """Joint targets (mm, float64) from an action of ``shape``: ``(3,)`` for one env,
    ``(N, 3)`` for N, or ``ValueError`` naming the rule.  With ``clip`` finite targets are
    clipped into the joint limits.  ``rows``: which rows must be valid targets (the others
    are not used: their envs are being reset)."""
    try:
        values = np.asarray(action)
    except (TypeError, ValueError):
        values = np.asarray(None)
    # Integer and float arrays only: numpy would also read booleans, numeric strings
    # and complex numbers with a zero imaginary part as numbers, and turns a boolean
    # among numbers in a list into a number silently.
    if values.dtype.kind not in "iuf" or _holds_bool(action):
        what = "3 numbers" if shape == (3,) else f"an array of shape {shape} of numbers"
        raise ValueError(f"action must be {what} (mm), not text, booleans, complex "
                         f"numbers or objects; got {action!r}")
    target = values.astype(np.float64)
    if target.shape != shape:
        raise ValueError(f"action must have shape {shape}, got {target.shape}")
    if clip:
        finite = np.all(np.isfinite(target), axis=-1, keepdims=True)
        target = np.where(finite, np.clip(target, PROTOTYPE.rho_min, PROTOTYPE.rho_max), target)
    if target.ndim == 1:
        return check_rho(target)
    used = np.ones(len(target), dtype=bool) if rows is None else rows
    low, high = PROTOTYPE.rho_min, PROTOTYPE.rho_max
    bad = used & ~np.all(np.isfinite(target) & (target >= low) & (target <= high), axis=-1)
    if bad.any():
        env = int(np.flatnonzero(bad)[0])
        try:
            check_rho(target[env])
        except ValueError as exc:
            raise ValueError(f"action of env {env}: {exc}") from None
    return target


def _holds_bool(action: Any) -> bool:
    """Whether a (nested) list or tuple action holds a boolean anywhere."""
    if isinstance(action, list | tuple):
        return any(isinstance(v, bool | np.bool_) or _holds_bool(v) for v in action)
    return False


def _machine_option(value: Any) -> MachineParams | None:
    """The ``machine`` reset option.  None, like leaving the key out, draws a machine from
    the preset (as ``seed=None`` and ``options=None`` mean "nothing given" in Gymnasium);
    anything else must be a dict in the machine file schema or a ``MachineParams``, inside
    :attr:`~orthoglide_env.model.design.MachineDesign.validity_range`."""
    if value is None:
        return None
    try:
        if isinstance(value, MachineParams):
            if value.design != PROTOTYPE:
                raise ValueError("this env runs the prototype's design; another design's "
                                 "machine goes to OrthoglideLab-v0 (design=...)")
            check_validity(value)
            return value
        if isinstance(value, dict):
            return MachineParams.from_dict(value, design=PROTOTYPE)
    except ValueError as exc:
        raise ValueError(f"reset option 'machine': {exc}") from None
    raise ValueError(
        "reset option 'machine' must be a dict in the machine file schema, a MachineParams "
        f"or None (draw one from the preset), got {type(value).__name__} {value!r}"
    )


def _layout(gauges: Any, name: str = "gauges") -> tuple[GaugeSpec, ...]:
    """A gauge layout from names such as ``"x-leg/y"`` or ``GaugeSpec`` objects; None is
    the paper's six gauges.  ``name``: what the caller calls the value, for errors."""
    if gauges is None:
        return PAPER_LAYOUT
    if not isinstance(gauges, list | tuple):
        raise ValueError(f"{name} must be a list of gauge names or GaugeSpec objects, got "
                         f"{gauges!r}")
    if not gauges:
        raise ValueError(f"{name}: a gauge layout needs at least one gauge")
    if all(isinstance(g, GaugeSpec) for g in gauges):
        return tuple(gauges)
    if all(isinstance(g, str) for g in gauges):
        try:
            return layout_from_names(list(gauges))
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
    raise ValueError(f"{name} must be names like 'x-leg/y' or GaugeSpec objects, got "
                     f"{gauges!r}")


def _render_modes(backend: str) -> list[str]:
    """The render modes an instance on ``backend`` can produce here."""
    if backend == "exact":
        return []
    return ["rgb_array"] + (["human"] if display_problem() is None else [])
