"""The lab as a Gymnasium environment: an episode is a whole calibration experiment.

Where ``OrthoglideCalibration-v0`` only moves the machine, ``OrthoglideLab-v0`` lets an
agent do what a technician does: move and read, lift and engage gauges, re-mount a stand
at another slot, read a laser tracker, and say when it is done, each at the cost of the
lab's time table (:mod:`orthoglide_env.lab.operations`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from orthoglide_env.envs.base import EngineEnv, Face
from orthoglide_env.instruments.slots import GaugeSpec
from orthoglide_env.lab.actions import check_lab_actions
from orthoglide_env.lab.engine import StepResult
from orthoglide_env.lab.notebook import Estimator, Record
from orthoglide_env.lab.rewards import ACCURACY_UNIT_MM
from orthoglide_env.lab.settings import lab_settings, lab_spaces
from orthoglide_env.lab.spec import LAB, REWARDS, check_arguments, signature

__all__ = ["ACCURACY_UNIT_MM", "REWARDS", "Estimator", "OrthoglideLabEnv",
           "OrthoglideLabV1Env", "OrthoglideLabV2Env", "OrthoglideLabV3Env", "OrthoglideLabV4Env",
           "Record"]


class LabFace(Face):
    """The lab's face, for its lone env and its native vector env: the whole action, the
    lab's infos."""

    def _actions(self, actions: Any, shape: tuple[int, ...], used: np.ndarray | None
                 ) -> tuple[np.ndarray, ...]:
        return check_lab_actions(actions, shape, self.settings.stands, len(self.slots),
                                 rows=used, design=self.settings.design,
                                 version=self.settings.version)

    @property
    def slots(self) -> tuple[GaugeSpec, ...]:
        """The lab's slot catalogue, its design's: the ``slot`` indices of actions and
        observations (names in each spec's ``slot``)."""
        return self.settings.slots

    def _step_info(self, result: StepResult, r: int, i: int) -> dict[str, Any]:
        return result.info(r)

    def _step_columns(self, result: StepResult, rows: np.ndarray
                      ) -> dict[str, list[Any]] | None:
        return result.columns(rows)

    def _reset_info(self, i: int) -> dict[str, Any]:
        return {"op": "reset", "step_time_s": 0.0, "collision": "", "overtravel": []}


class OrthoglideLabEnv(LabFace, EngineEnv):
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
                                        4 stop (``lab.operations.Op``)
    rho    Box([-100, 60] mm, (3,))     joint targets, control coordinates     move
    stand  Discrete(stands)             which stand                            lift, engage,
                                                                               re-mount
    slot   Discrete(len(slots))         where to: an index in the lab's slot   re-mount
                                        catalogue ``slots`` (its design's)
    =====  ===========================  =====================================  ==========

    ``move`` drives to ``rho``, settles and reads every engaged gauge and the tracker.
    A slot is a place on a bar (at each of the design's ``slot_positions``), on a carriage
    (across its drive) or on a face of the platform: the env's ``slots`` is the catalogue
    of its design (:func:`~orthoglide_env.lab.operations.slot_catalogue`; the prototype's
    is :data:`~orthoglide_env.lab.operations.SLOTS`, names in ``SLOT_NAMES``, and
    ``slot_index(name, design=...)`` finds one).  A platform gauge reads the platform's
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
    engaged        1 where the plunger is down and      -    {0, 1}
                   the gauge in service
    faulted        1 where the gauge was pushed past    -    {0, 1}
                   its travel: out of service until
                   re-mounted (a lifted one is 0)
    slot           slot index of each stand, or        -     {0 .. len(slots)}
                   len(slots) when not mounted
    mounting       how many times the stand was         -    [0, 1e6]
                   mounted (a new zero each time)
    joints         encoder readings                     mm   [-101, 61]
    tracker        reflector in the tracker's frame     mm   [-1e5, 1e5] (0 without one)
    tracker_valid  1 when the tracker read              -    {0, 1}
    time           seconds used so far                  s    [0, budget_s + longest
                                                             step] (see below)
    =============  ==================================  ====  ============================

    A reading that is not valid is 0.0: use ``valid``.  A stand that is not engaged is
    lifted (``faulted`` 0) or out of service (``faulted`` 1).  The clock never passes
    ``budget_s``: an operation that would end past it is refused (``info["refused"]`` says
    when it would end) and the clock runs to ``budget_s``; the re-installs of stands a
    step pushed past their travel, or a refusal's lever flick, stop there too.  (The
    space's bound, ``budget_s`` plus the longest step, is kept from when the last step
    could end past it: :meth:`~orthoglide_env.lab.settings.LabSettings.longest_step`.)
    Every reading
    is also written to ``records`` (the lab notebook: instrument, mounting, posture,
    value), which agents and estimators read; the machine's truth stays on
    ``true_machine`` for scoring only.

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
    (``info["collision"]``).  ``truncated`` once the time used reaches ``budget_s`` (an
    operation that cannot end within it ends the episode there, refused): every episode
    that is not stopped takes exactly ``budget_s``, so agents compared at one budget use
    equal lab time.

    Info
    ----
    ``op``, ``step_time_s``, ``overtravel`` (stands pushed past their travel on this step),
    ``collision``, ``refused`` ("" or why the operation was refused); at the end also
    ``is_success`` (the predicted TCP error after the best-fit rigid motion, from the
    records' information at the nominal machine, is at most ``success_mm``) and
    ``predicted_tcp_rigid_mm``.

    Render modes
    ------------
    ``rgb_array`` (PyBullet's TinyRenderer in DIRECT mode, no window) and ``human`` (a
    PyBullet GUI window), on the ``pybullet`` backend only; ``metadata["render_modes"]``
    of an instance lists what it can draw here.  ``render_mode="human"`` without a display
    raises ``ValueError`` (PyBullet's GUI would end the process).

    Kwargs (defaults, types, ranges: :data:`orthoglide_env.lab.spec.LAB`): ``errors`` (preset),
    ``gauge_sigma``, ``gauge_resolution`` (mm), ``backend`` (``exact`` or ``pybullet``),
    ``stands`` (default 6), ``tracker`` (a laser tracker on the platform, read at every
    move), ``tracker_sigma`` (mm), ``thermometer`` (a room thermometer: each record
    carries its reading, see Conditions), ``budget_s``, ``reward``, ``estimator`` (for
    ``accuracy``: records and sigma to a ``MachineParams``, e.g.
    ``calibrators.study.episodes.make_estimator()``), ``time_weight``, ``success_mm``,
    ``travel`` (default: the design's gauge travel), ``design`` (the machines'
    :class:`~orthoglide_env.model.design.MachineDesign`, default the prototype: its
    control limits bound ``rho``, its errors' validity range the machines, its
    ``slot_positions`` the bar slots; ``stands`` is at most its slot count, and its
    ``slot_positions`` must include 0.5, where the paper's stands open every episode),
    ``conditions`` (the world beyond the geometry: ``"ideal"``, ``"lab"``, ``"workshop"``,
    a :class:`~orthoglide_env.world.conditions.Conditions` naming which effects act, or its
    dict; default ``"lab"``, :data:`~orthoglide_env.world.conditions.DEFAULT_CONDITIONS`),
    ``reference`` (the lab has a gauge block: the catalogue's
    ``reference`` slots, see :mod:`orthoglide_env.instruments.slots`; default False),
    ``render_mode``.  A bad argument raises ``ValueError``
    naming it and its rule.

    Conditions
    ----------
    Under ``lab`` or ``workshop`` each episode also draws its world from ``np_random``
    (:mod:`orthoglide_env.world`): the screws' lead error, backlash and warm-up move the
    carriages away from what the encoders (``joints``) say; the room's temperature, read on
    the lab's clock, grows the machine and the stands; each stand's indicator has its own
    error curve and retrace (a digital one, ``"indicator": "digital"``, its own curve and
    more scatter near its stroke's ends); stands creep after mounting and give under the
    measuring force; the platform and bars deflect under the weight and the gauges' forces;
    the tracker reads with its MPE-based noise.  An agent that works longer meets a warmer
    machine.  The drawn world is on ``true_world`` (for scoring only); a ``machine`` reset
    option whose dict holds a ``world`` (a machine file written with ``calibrate
    --save-truth``) replays that world instead of drawing one, and is refused by a lab of
    other conditions.  ``ideal`` draws nothing: every stream is as before.

    With ``thermometer=True`` every record also carries the room's temperature as the
    lab's thermometer read it then (``temperature_c``, C; None without one).  Under
    conditions with the ``thermometer`` effect it reads with a fixed offset within a class
    A Pt100's tolerance and rounds to 0.01 K; otherwise it reads the truth (20 C exactly
    where the room does not act).  Its offset is drawn from a jump of ``np_random``, which
    does not move: the machine, its world and every reading are those of a lab without
    one.

    Instruments
    -----------
    ``instruments`` lists what the lab owns (names in
    :data:`~orthoglide_env.instruments.catalogue.INSTRUMENT_NAMES`; an unknown one
    raises ``ValueError``).  In ``OrthoglideLab-v1`` with the
    ``interferometer``, ``align`` drives to Zero, sets the interferometer up along drive
    ``axis`` (the retroreflector on its carriage) and zeroes it there (the first set-up
    also waits for its material sensor to settle; :data:`~orthoglide_env.lab.operations.
    TIME`); from then on every move also reads it (with its dwell): the carriage's
    displacement from the zero less the commanded one, in mm, with the instrument's own
    errors (:mod:`orthoglide_env.instruments.interferometer`).  Each set-up is a mounting
    of the notebook (``interferometer.x#1``).  ``align`` in a lab without it is refused.

    In ``OrthoglideLab-v2`` with the ``ballbar`` (ISO 230-4's circular tests), ``pivot``
    drives to ``rho``, centres the ballbar's pivot where the TCP is and fits the bar of
    index ``bar`` (:data:`~orthoglide_env.lab.operations.TIME`: the set-up's time).  A
    move puts the bar in where the nominal machine brings the TCP within its travel of
    the pivot (the bar's nominal length, +-1 mm) and reads it there: the TCP's distance
    from the pivot less the nominal length, in mm, with the instrument's own errors
    (:mod:`orthoglide_env.instruments.ballbar`).  Once it is in, a move that would take it
    outside its travel raises ``ValueError`` before anything changes; any other
    operation takes it off.  Each set-up is a mounting of the notebook (``ballbar#1``).
    ``pivot`` in a lab without it is refused.

    In ``OrthoglideLab-v3`` with the ``step-gauge`` (a KOBA-type gauge, faces every
    20 mm), ``place`` drives to ``rho``, lays the gauge along world axis ``axis`` with its
    face 0 at the TCP there and zeroes the probe on the platform on it (:data:`~orthoglide_env.
    lab.operations.TIME`: the set-up's time).  While it is set up every move must bring the
    nominal machine's TCP onto the gauge's line at one of its faces (else ``ValueError``
    before anything changes) and reads it, with the probe's dwell: how far the TCP lies
    past the face along the gauge, from where it lay at face 0, in mm, with the
    instrument's own errors (:mod:`orthoglide_env.instruments.step_gauge`).  Any other
    operation takes the probe off.  Each set-up is a mounting of the notebook
    (``step-gauge#1``).  ``place`` in a lab without it is refused.

    In ``OrthoglideLab-v4`` a move chooses whether it reads the interferometer set up: the
    action's ``laser`` 1 waits the laser's dwell and reads it (as every move of v1-v3
    does, and as a v4 move does whose action leaves the key out), 0 drives, settles and
    reads the dials (and the tracker, the bar, the probe) without the dwell and without a
    laser reading (``interferometer_valid`` 0; the beam stays aligned and its count kept,
    as a technician's laser that is not read at a posture).  ``laser`` has no effect on
    an operation other than a move (a re-mount's or a set-up's reading at Zero reads a
    laser set up, without a dwell, as before) nor in a lab whose interferometer is not set
    up.

    Version history
    ---------------
    * every version: an operation that would end past ``budget_s`` is refused and the
      clock runs to ``budget_s`` (truncated); the re-installs after an overtravel and a
      refusal's flick stop at ``budget_s``.  Before, the step that reached the budget was
      played whole, so an episode could end past it by up to the longest step (a
      re-mount planned at 1496 s of a 1500 s budget ended at 1621 s).  The spaces are
      unchanged and every episode whose steps all end within the budget is unchanged,
      bit for bit, so the ids keep their versions.
    * v4 (``OrthoglideLab-v4``, :class:`OrthoglideLabV4Env`): the action gains ``laser``
      (Discrete(2), optional, 1 when left out): a move with ``laser`` 0 reads no
      interferometer and pays no dwell (see Instruments).  A lab's operator does not wait
      for the laser's averaged reading where only the dials are read; in v1-v3 every move
      with the laser set up waits ``TIME.interferometer_target_s`` and reads it.  The
      observation is v3's; ``OrthoglideLab-v3`` keeps its spaces and every stream.
    * v3 (``OrthoglideLab-v3``, :class:`OrthoglideLabV3Env`): the lab may own a step gauge
      (``instruments=["dial", "step-gauge"]``, see Instruments).  The action's ``op`` gains
      7, ``place``, which takes the action's ``axis`` (the world axis to lay the gauge
      along); the observation gains ``step_gauge`` (mm, Box(-1, 1, (1,)): its reading, 0
      when it did not read), ``step_gauge_valid`` (1 when it read) and ``step_gauge_in``
      (1 while the probe is on the gauge).  ``OrthoglideLab-v2`` keeps its spaces and
      refuses the step gauge with ``ValueError``.
    * v2 (``OrthoglideLab-v2``, :class:`OrthoglideLabV2Env`): the lab may own a ballbar
      (``instruments=["dial", "ballbar"]``, see Instruments).  The action's ``op`` gains 6,
      ``pivot``, and the action a key ``bar`` (Discrete(3): the index of the bar's length
      in :data:`~orthoglide_env.world.table.BALLBAR_LENGTHS_MM`; other operations may leave
      it out); the observation gains ``ballbar`` (mm, Box(-2, 2, (1,)): its reading, 0 when
      it did not read), ``ballbar_valid`` (1 when it read) and ``ballbar_in`` (1 while the
      bar is in).  ``OrthoglideLab-v1`` keeps its spaces and refuses the ballbar with
      ``ValueError``.
    * v0 (issue 37): ``conditions`` defaults to ``"lab"`` (was ``"ideal"``).  The spaces,
      and every stream under a named ``conditions``, are unchanged, so the id keeps its
      version (Gymnasium bumps it when an env's dynamics or spaces change); a lab built
      without ``conditions`` now draws the real lab's world each episode.  Pass
      ``conditions="ideal"`` for the earlier default's numbers, bit for bit.
    * v1 (``OrthoglideLab-v1``, :class:`OrthoglideLabV1Env`): the lab may own a laser
      interferometer (``instruments=["dial", "interferometer"]``, see Instruments).  The
      action's ``op`` gains 5, ``align``, and the action a key ``axis`` (Discrete(3), the
      drive to set it up along; other operations may leave it out); the observation gains
      ``interferometer`` (mm, Box(-1, 1, (1,)): its reading, 0 when it did not read),
      ``interferometer_valid`` (1 when it read) and ``interferometer_axis`` (Discrete(4):
      the drive it is set up along, 3 for none).  ``OrthoglideLab-v0`` keeps its spaces
      and refuses the interferometer with ``ValueError``.
    * v0: ``instruments`` names what the lab owns (``dial``, ``tracker``; the default is
      the dial gauges, and the tracker where ``tracker=True``); ``step-gauge`` and
      ``ballbar`` are refused as not yet available.
    * v0: ``reference`` adds the gauge block: three more slots, ``reference/x``, ``/y``,
      ``/z`` (after the design's catalogue, whose indices stay), a platform gauge zeroed
      against the block held to the face at Zero and then reading the bare face a block's
      length back; a re-mount there costs ``TIME.reference_s`` more.  Default off: every
      space and stream as before.
    * v0: ``thermometer`` (default False: numbers unchanged, bit for bit) adds a room
      thermometer whose reading each record carries; the ``thermometer`` effect its error.
    * v0: ``conditions`` adds the world beyond the geometry (then default ``ideal``:
      numbers unchanged, bit for bit); the ``machine`` reset option may carry its ``world``.
    * v0: the slot catalogue is the design's (was the prototype's for every design, and a
      design with other ``slot_positions`` was refused).
    * v0: the constructor's arguments and defaults are its table in
      :mod:`orthoglide_env.lab.spec`; an unknown one raises ``ValueError`` (was
      ``TypeError``).
    * v0 (first release): the lab on the engine ``OrthoglideCalibration-v0`` shares.
    """

    __signature__ = signature(LAB)

    #: The env's version: 1 adds the interferometer to the spaces, 2 the ballbar, 3 the step
    #: gauge, 4 the moves' choice to read the laser (see the history).
    version: int = 0

    def __init__(self, **kwargs: Any) -> None:
        settings = lab_settings(check_arguments(LAB, kwargs), self.version)
        self.design, self.conditions = settings.design, settings.conditions
        self.preset, self.noise = settings.preset, settings.noise
        self.backend_name, self.n_stands = settings.backend, settings.stands
        self.tracker, self.tracker_sigma = settings.tracker, settings.tracker_sigma
        self.budget_s, self.reward_mode = settings.budget_s, settings.reward
        self.estimator = settings.estimator
        self.time_weight, self.success_mm = settings.time_weight, settings.success_mm
        self.travel, self.reference = settings.travel, settings.reference
        self.instruments = settings.instruments
        self._start_engine(settings, lab_spaces(settings))

    # -- the episode, as the lab's notebook and clock show it -------------------------------
    @property
    def records(self) -> list[Record]:
        """The lab notebook: every reading of the episode, in order."""
        return self._batch.notebooks[0].records

    @property
    def mountings(self) -> list[str]:
        """Each stand's present mounting, as the notebook names it ("" if not mounted)."""
        return list(self._batch.mounting[0])

    @property
    def _time(self) -> float:
        """Seconds used so far."""
        return float(self._batch.time[0])

    # -- ground truth, for the scorer only -------------------------------------------------
    @property
    def true_tracker_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """The tracker station's rotation and position (scoring only)."""
        return self._batch.tracker_rotation[0].copy(), self._batch.tracker_position[0].copy()

    # -- what the records say ------------------------------------------------------------------
    def final_tcp_rigid_mm(self) -> float:
        """TCP error RMS after the best-fit rigid motion of the machine the episode's
        estimator makes of its records (scoring against the truth)."""
        self._require()
        return self._batch.final_tcp_rigid_mm(0)

    def information(self) -> tuple[np.ndarray, list[str]]:
        """The records' information about every parameter they involve, in units of each
        parameter's scale (see ``information`` reward), and the parameters' names."""
        return self._batch.notebooks[0].information()

    def predicted_tcp_rigid_mm(self) -> float:
        """TCP error RMS after the best-fit rigid motion that the records' information
        predicts (at the nominal machine, a priori sizes from the realistic preset)."""
        return self._batch.notebooks[0].predicted_tcp_rigid_mm()


class OrthoglideLabV1Env(OrthoglideLabEnv):
    """``OrthoglideLab-v1``: :class:`OrthoglideLabEnv` (whose docstring is the spec) whose
    spaces carry the interferometer: the ``align`` operation, the action's ``axis`` and
    the observation's ``interferometer`` keys."""

    version = 1


class OrthoglideLabV2Env(OrthoglideLabEnv):
    """``OrthoglideLab-v2``: :class:`OrthoglideLabEnv` (whose docstring is the spec) whose
    spaces carry the interferometer and the ballbar: the ``pivot`` operation, the action's
    ``bar`` and the observation's ``ballbar`` keys."""

    version = 2


class OrthoglideLabV3Env(OrthoglideLabEnv):
    """``OrthoglideLab-v3``: :class:`OrthoglideLabEnv` (whose docstring is the spec) whose
    spaces carry the interferometer, the ballbar and the step gauge: the ``place``
    operation and the observation's ``step_gauge`` keys."""

    version = 3


class OrthoglideLabV4Env(OrthoglideLabEnv):
    """``OrthoglideLab-v4``: :class:`OrthoglideLabV3Env`'s spaces, the action with the
    ``laser`` key: a move reads the interferometer set up, and waits its dwell, only where
    it asks (:class:`OrthoglideLabEnv`'s docstring is the spec)."""

    version = 4
