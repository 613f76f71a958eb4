"""``OrthoglideCalibration-v0``: one episode is one calibration experiment on one machine.

A thin face of the lab engine (:mod:`orthoglide_env.lab.engine`, which ``OrthoglideLab-v0``
runs on too): the lab with gauge stands at the layout's slots, all engaged, and only one
operation, move and read; an overtravel lasts while the bar presses; no tracker.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from orthoglide_env.envs.base import EngineEnv, Face
from orthoglide_env.instruments.dial import Status
from orthoglide_env.instruments.slots import GaugeSpec
from orthoglide_env.lab.actions import check_targets
from orthoglide_env.lab.engine import StepResult
from orthoglide_env.lab.operations import Op
from orthoglide_env.lab.settings import calibration_settings, calibration_spaces
from orthoglide_env.lab.spec import CALIBRATION, check_arguments, signature

#: How ``info["status"]`` names each :class:`~orthoglide_env.instruments.dial.Status` code,
#: indexed by the code.
STATUS_LABELS: np.ndarray = np.array([s.name.lower().replace("_", "-") for s in Status])


class CalibrationFace(Face):
    """The calibration env's face, for its lone env and its native vector env: joint
    targets (every action a move) and infos per gauge."""

    LAYOUT_OPTION = True
    clip_actions: bool

    def _actions(self, actions: Any, shape: tuple[int, ...], used: np.ndarray | None
                 ) -> tuple[np.ndarray, ...]:
        rho = check_targets(actions, (*shape, 3), clip=self.clip_actions, rows=used,
                            design=self.settings.design)
        zeros = np.zeros(shape, dtype=np.int64)
        return np.full(shape, Op.MOVE), rho, zeros, zeros

    def _step_info(self, result: StepResult, r: int, i: int) -> dict[str, Any]:
        names = gauge_names(self.gauge_layouts[i])
        hits = result.new_overtravel[r]
        overtravel = [names[k] for k in np.flatnonzero(hits)] if hits.any() else []
        return self._info(i, names, overtravel, float(result.seconds[r]), result.collision[r])

    def _reset_info(self, i: int) -> dict[str, Any]:
        return self._info(i, gauge_names(self.gauge_layouts[i]), [], 0.0, "")

    def _info(self, i: int, names: list[str], overtravel: list[str], step_time: float,
              collision: str) -> dict[str, Any]:
        """Env ``i``'s info: its gauges' ``names`` and status, the gauges that went into
        overtravel, the step's time and the collision label."""
        return {"gauge_names": list(names), "status": STATUS_LABELS[self._batch.status[i]].tolist(),
                "overtravel": overtravel, "step_time_s": step_time, "collision": collision}


class OrthoglideCalibrationEnv(CalibrationFace, EngineEnv):
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
    Minus the seconds a real experiment spends on the step (the lab's time table,
    :data:`~orthoglide_env.lab.operations.TIME`): travel at ``drive_speed_mm_s`` (axes
    together), plus the settle-and-read dwell, plus ``overtravel_s`` for every gauge
    pushed past its travel toward its stand on this move.

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
    (:meth:`MachineParams.from_dict`) or a ``MachineParams`` of the env's ``design``,
    inside the design's validity range; left out or ``None`` (as ``seed=None`` means "none
    given"): drawn from the ``errors`` preset with ``np_random``.  Its dict may hold a
    ``world`` (the machine's drawn non-geometric truth, drawn under this env's
    ``conditions``): it is replayed instead of drawn.  Anything
    else (a list, ``0``, ``""``, ``False``) raises ``ValueError``.  ``gauges``: the layout
    of this episode, names such as ``"x-leg/y"`` or ``"z/x@0.3"`` or ``GaugeSpec``
    objects (left out or ``None``: the constructor's); it must hold as many gauges as the
    constructor's ``gauges`` (the observation space is fixed), otherwise ``ValueError``.
    Installation errors are drawn from the preset with ``np_random``; the gauges are then
    set up at mid-travel and zeroed at the Zero posture.

    Refused input
    -------------
    A bad or unknown constructor argument (defaults, types and ranges:
    :data:`orthoglide_env.lab.spec.CALIBRATION`), reset option, seed or action raises
    ``ValueError`` whose one-line message names the input and the rule.  A refused
    ``reset`` or ``step`` changes nothing: the episode before it goes on (its machine,
    gauges, posture and random stream), or, before the first good reset, every ``step``
    still raises ``RuntimeError``.

    Render modes
    ------------
    ``rgb_array`` (PyBullet's TinyRenderer in DIRECT mode, no window) and ``human`` (a
    PyBullet GUI window), on the ``pybullet`` backend only.  An instance's
    ``metadata["render_modes"]`` lists what it can draw here: nothing on the ``exact``
    backend, and ``human`` only where a display is available; ``render_mode="human"``
    without one raises ``ValueError`` (PyBullet's GUI would end the process).

    Public attributes for calibrators: ``gauge_layout`` (this episode's tuple of
    ``GaugeSpec``), ``gauge_noise`` (the spec sheet's sigma and resolution), ``travel``.

    Info
    ----
    ``gauge_names``, ``status`` (per gauge: valid, no-contact, overtravel, missed),
    ``overtravel`` (gauges that went into overtravel on this step), ``step_time_s``,
    ``collision`` (empty string when none).  Only deterministic values.

    Ground truth (``true_machine``, ``true_gauges``) is on the unwrapped env for scoring;
    agents must not read it.

    Version history
    ---------------
    * v0 (issue 37): ``conditions`` defaults to ``"lab"``
      (:data:`~orthoglide_env.world.conditions.DEFAULT_CONDITIONS`), was ``"ideal"``.  The
      spaces, and every stream under a named ``conditions``, are unchanged, so the id keeps
      its version (Gymnasium bumps it when an env's dynamics or spaces change); an env
      built without ``conditions`` now meets the real lab's world.  Pass
      ``conditions="ideal"`` for the earlier default's numbers, bit for bit.
    * v0: ``conditions`` (``"ideal"``, ``"lab"``, ``"workshop"``, a ``Conditions`` or its
      dict; then default ``ideal``, whose numbers were unchanged bit for bit) adds the world
      beyond the geometry, as ``OrthoglideLab-v0`` describes it: ``joints`` are then the
      encoders' (the commanded positions), not where the carriages are; ``true_world``
      holds the drawn world.
    * v0 (issue 20): runs on the lab engine.  The seeded streams did not change: on the
      exact backend observations, rewards and infos are the earlier implementation's, bit
      for bit.  On the ``pybullet`` backend the gauges are now set up at Zero with the
      exact model's ray distances (as the lab's are), not the simulator's: the installed
      gauges (``true_gauges``) move by ~1e-13 mm, below the readings' last bit in the
      runs compared.  Constructor arguments are checked by the table of
      :mod:`orthoglide_env.lab.spec`, whose words both envs share; it holds their defaults
      too, and an unknown argument raises ``ValueError`` (was ``TypeError``).  ``design``
      (a :class:`~orthoglide_env.model.design.MachineDesign`, default the prototype, as
      the lab's) sets the machines' dimensions and limits, the action and ``joints``
      boxes and the default ``travel``; the tables above give the prototype's numbers.
    * v0 (first release): move and read, on its own implementation.
    """

    __signature__ = signature(CALIBRATION)

    def __init__(self, **kwargs: Any) -> None:
        args = check_arguments(CALIBRATION, kwargs)
        settings = calibration_settings(args)
        self.preset, self.gauge_noise = settings.preset, settings.noise
        self.travel, self.motion = settings.travel, settings.motion
        self.backend_name = settings.backend
        self.clip_actions = args["clip_actions"]
        self.max_episode_steps = settings.max_steps
        self._start_engine(settings, calibration_spaces(settings))

    @property
    def gauge_layout(self) -> tuple[GaugeSpec, ...]:
        """This episode's gauges: the constructor's, or the ``gauges`` reset option's."""
        return self.gauge_layouts[0]


@functools.lru_cache(maxsize=64)
def gauge_names(layout: tuple[GaugeSpec, ...]) -> list[str]:
    """The names of a layout's gauges, as ``info["gauge_names"]`` gives them (a list the
    info copies)."""
    return [g.slot for g in layout]
