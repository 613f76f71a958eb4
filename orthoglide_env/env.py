"""Gymnasium environment: one episode is one calibration experiment on one machine."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .backend import MOTION_MODES, ExactMachine, MachineBackend
from .gauges import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    DEFAULT_TRAVEL,
    PAPER_LAYOUT,
    GaugeNoise,
    GaugeSpec,
    Status,
    install,
    layout_from_names,
    zero_gauges,
)
from .geometry import DEFAULT_PRESET, RHO_MAX, RHO_MIN, MachineParams, check_rho, get_preset
from .task import OVERTRAVEL_PENALTY, CalibrationTask, Reading

BACKENDS: tuple[str, ...] = ("pybullet", "exact")
#: Encoders may read a hair outside the control limits after settling (solver residue
#: ~1e-9 mm); the observation box leaves this margin so an observation is always inside.
ENCODER_MARGIN: float = 1.0
#: Largest gauge noise accepted, as a fraction of the travel: it keeps a noisy reading
#: inside the observation box (half a travel of margin is then >= 25 sigma).
MAX_SIGMA_FRACTION: float = 1 / 50


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

    A target outside the joint limits, NaN, inf or of the wrong shape raises
    ``ValueError`` (a real controller refuses it) unless the env was built with
    ``clip_actions=True``, which clips finite targets into the limits.

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
    :data:`~orthoglide_env.task.DRIVE_SPEED` mm/s (axes together), plus the settle-and-read
    dwell, plus :data:`~orthoglide_env.task.OVERTRAVEL_PENALTY` for every gauge pushed past
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
    :mod:`orthoglide_env.collisions` decide it.  On the nominal and realistic machines the
    nearest such parts stay more than 5 mm apart over the whole joint cube, so this guards
    machines far from nominal (given through the ``machine`` reset option).  Both backends
    check the posture reached, not the path to it.  The base has no collision geometry.
    Truncation comes from ``max_episode_steps``.

    Reset options
    -------------
    ``machine``: the true machine, a dict in the machine file schema
    (:meth:`MachineParams.from_dict`) or a ``MachineParams``; default: drawn from the
    ``errors`` preset with ``np_random``.  ``gauges``: the layout of this episode, names
    such as ``"x-leg/y"`` or ``"z/x@0.3"`` or ``GaugeSpec`` objects; it must hold as many
    gauges as the constructor's ``gauges`` (the observation space is fixed), otherwise
    ``ValueError``.  Installation errors are drawn from the preset with ``np_random``; the
    gauges are then set up at mid-travel and zeroed at the Zero posture.

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

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"],
                                          "render_fps": 4}

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
        self.preset = get_preset(errors)
        if motion not in MOTION_MODES:
            raise ValueError(f"unknown motion '{motion}'; choose from {list(MOTION_MODES)}")
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend '{backend}'; choose from {list(BACKENDS)}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"unknown render_mode '{render_mode}'")
        if backend == "exact" and render_mode is not None:
            raise ValueError("the exact backend has no picture: use backend='pybullet' to render")
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError("max_episode_steps must be a positive integer")
        if not travel > 0:
            raise ValueError("gauge travel must be positive")
        if gauge_sigma > travel * MAX_SIGMA_FRACTION:
            raise ValueError(
                f"gauge_sigma {gauge_sigma} mm is not a dial gauge's repeatability: it must be "
                f"at most travel/{1 / MAX_SIGMA_FRACTION:g} = {travel * MAX_SIGMA_FRACTION:g} mm"
            )
        self.gauge_noise = GaugeNoise(gauge_sigma, gauge_resolution)
        self._default_layout = _layout(gauges)
        self.gauge_layout = self._default_layout
        self.travel = float(travel)
        self.motion = motion
        self.backend_name = backend
        self.render_mode = render_mode
        self.clip_actions = clip_actions
        self.max_episode_steps = max_episode_steps
        self.task = CalibrationTask(self.gauge_noise)
        n = len(self.gauge_layout)
        self.action_space = spaces.Box(RHO_MIN, RHO_MAX, shape=(3,), dtype=np.float64)
        self.observation_space = spaces.Dict(
            {
                # A valid reading lies within +-travel/2 of its zero; the box leaves another
                # travel/2 (>= 25 sigma, see MAX_SIGMA_FRACTION) for the noise.
                "gauges": spaces.Box(-self.travel, self.travel, shape=(n,), dtype=np.float64),
                "valid": spaces.MultiBinary(n),
                "joints": spaces.Box(RHO_MIN - ENCODER_MARGIN, RHO_MAX + ENCODER_MARGIN,
                                     shape=(3,), dtype=np.float64),
            }
        )
        self._machine: MachineBackend | None = None
        self._rho = np.zeros(3)
        self._steps = 0
        self._pressed = np.zeros(n, dtype=bool)

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
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"machine", "gauges"})
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: machine, gauges")
        machine = (
            MachineParams.from_dict(options["machine"])
            if isinstance(options.get("machine"), dict)
            else options.get("machine") or self.preset.sample(self.np_random)
        )
        if not isinstance(machine, MachineParams):
            raise ValueError("reset option 'machine' must be a dict in the machine file schema")
        layout = _layout(options["gauges"]) if "gauges" in options else self._default_layout
        if len(layout) != len(self._default_layout):
            raise ValueError(
                f"this env observes {len(self._default_layout)} gauges; a layout of "
                f"{len(layout)} needs an env built with gauges=[...] of that size"
            )
        gauges = install(layout, machine, travel=self.travel, preset=self.preset,
                         rng=self.np_random)
        if self._machine is not None:
            self._machine.close()
        self._machine = self._build(machine, gauges)
        self._machine.set_gauges(zero_gauges(gauges, self._machine.gauge_distances()))
        self.gauge_layout = layout
        self._rho = np.zeros(3)
        self._steps = 0
        reading = self.task.read(self._machine, self.np_random)
        self._pressed = self.task.pressed(self._machine)
        return self._observation(reading), self._info(reading, [], 0.0, "")

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        machine = self._require_machine()
        target = self._check_action(action)
        machine.move(target, self.motion)
        reading = self.task.read(machine, self.np_random)
        pressed = self.task.pressed(machine)
        overtravel = self.task.new_overtravels(machine.gauges, self._pressed, pressed)
        step_time = self.task.move_time(self._rho, target) + OVERTRAVEL_PENALTY * len(overtravel)
        collision = ", ".join(machine.collisions())
        self._rho, self._pressed = target, pressed
        self._steps += 1
        truncated = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        obs = self._observation(reading)
        return obs, -step_time, bool(collision), truncated, self._info(
            reading, overtravel, step_time, collision
        )

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self._require_machine().render()  # type: ignore[attr-defined]
        return None

    def close(self) -> None:
        if self._machine is not None:
            self._machine.close()
            self._machine = None

    # -- helpers -------------------------------------------------------------------------------
    def _build(self, machine: MachineParams, gauges: list) -> MachineBackend:
        if self.backend_name == "exact":
            return ExactMachine(machine, gauges)
        try:
            from .machine import OrthoglideMachine
        except ImportError as exc:
            raise ImportError(
                f"the pybullet backend is not available ({exc}); use backend='exact'"
            ) from exc
        return OrthoglideMachine(machine, gauges, gui=self.render_mode == "human")

    def _require_machine(self) -> MachineBackend:
        if self._machine is None:
            raise RuntimeError("call reset() before using the environment")
        return self._machine

    def _check_action(self, action: Any) -> np.ndarray:
        try:
            target = np.array(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action must be 3 numbers (mm), got {action!r}") from None
        if target.shape != (3,):
            raise ValueError(f"action must have shape (3,), got {target.shape}")
        if self.clip_actions and np.all(np.isfinite(target)):
            return np.clip(target, RHO_MIN, RHO_MAX)
        return check_rho(target)

    def _observation(self, reading: Reading) -> dict[str, np.ndarray]:
        return {"gauges": reading.gauges.astype(np.float64), "valid": reading.valid,
                "joints": reading.joints.astype(np.float64)}

    def _info(self, reading: Reading, overtravel: list[str], step_time: float,
              collision: str) -> dict[str, Any]:
        return {
            "gauge_names": [g.name for g in self.gauge_layout],
            "status": [Status(s).name.lower().replace("_", "-") for s in reading.status],
            "overtravel": overtravel,
            "step_time_s": step_time,
            "collision": collision,
        }


def _layout(gauges: list[str] | tuple[GaugeSpec, ...] | None) -> tuple[GaugeSpec, ...]:
    if gauges is None:
        return PAPER_LAYOUT
    gauges = list(gauges)
    if not gauges:
        raise ValueError("a gauge layout needs at least one gauge")
    if all(isinstance(g, GaugeSpec) for g in gauges):
        return tuple(gauges)
    if all(isinstance(g, str) for g in gauges):
        return layout_from_names(gauges)
    raise ValueError("gauges must be names like 'x-leg/y' or GaugeSpec objects")
