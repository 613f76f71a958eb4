"""The native vector env of ``OrthoglideCalibration-v0``: N machines in one numpy pass,
built by ``gymnasium.make_vec("OrthoglideCalibration-v0", num_envs=N,
vectorization_mode="vector_entry_point", backend="exact")``."""

from __future__ import annotations

from typing import Any

from orthoglide_env.envs.calibration import CalibrationFace
from orthoglide_env.envs.vector import EngineVectorEnv
from orthoglide_env.instruments.gauges import Gauge
from orthoglide_env.lab.settings import calibration_settings, calibration_spaces
from orthoglide_env.lab.spec import CALIBRATION_VECTOR, check_arguments, signature


class OrthoglideCalibrationVectorEnv(CalibrationFace, EngineVectorEnv):
    """``num_envs`` calibration experiments (``OrthoglideCalibration-v0``, whose docstring
    is the spec) on the exact backend, stepped together as
    :class:`~orthoglide_env.envs.vector.EngineVectorEnv` says: env ``i`` is one
    ``gym.make("OrthoglideCalibration-v0", backend="exact", ...)`` reset with seed
    ``seed + i`` in a ``SyncVectorEnv``, bit for bit.

    ========  ===================================================  ====  =================
    what      shape and meaning                                    unit  range
    ========  ===================================================  ====  =================
    action    (N, 3): env i's target control coordinates rho       mm    [-100, 60]
    gauges    (N, G) readings, in each env's layout order          mm    [-travel, travel]
    valid     (N, G) 1 where the gauge touches its bar             -     {0, 1}
    joints    (N, 3) encoder readings                              mm    [-101, 61]
    reward    (N,) minus the step's seconds (0 on an autoreset)    s     <= 0
    ========  ===================================================  ====  =================

    A target one env would refuse (outside the joint limits, not real numbers, the wrong
    shape, or a posture its machine cannot be assembled in) raises ``ValueError`` naming
    the env, and no env moves.  ``truncated`` after ``max_episode_steps`` steps (500 from
    ``make_vec``).  Reset options: the single env's ``machine`` and ``gauges``, and
    ``reset_mask``; an autoreset draws a machine with the env's default gauge layout.
    Info keys: the single env's (``gauge_names``, ``status``, ``overtravel``,
    ``step_time_s``, ``collision``).

    Ground truth for scoring: ``true_machines`` (a :class:`MachineParams` batch of shape
    (N,)), ``true_gauges`` (one list of gauges per env); ``gauge_layouts``, ``gauge_noise``
    and ``travel`` are public as on the single env.
    """

    __signature__ = signature(CALIBRATION_VECTOR)

    def __init__(self, **kwargs: Any) -> None:
        args = check_arguments(CALIBRATION_VECTOR, kwargs)
        settings = calibration_settings(args)
        self.preset, self.gauge_noise = settings.preset, settings.noise
        self.travel = settings.travel
        self.clip_actions, self.max_episode_steps = args["clip_actions"], settings.max_steps
        self._start_engine(settings, args["num_envs"], args["autoreset_mode"],
                           calibration_spaces(settings))

    @property
    def true_gauges(self) -> list[list[Gauge]]:
        """Every env's installations, in mounting order (scoring only)."""
        self._require()
        return [self._batch.true_gauges(i) for i in range(self.num_envs)]
