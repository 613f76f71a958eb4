"""The lab's rules on a batch of episodes: one implementation for every face of the lab.

``OrthoglideLab-v0`` (:mod:`orthoglide_env.envs.lab`) and ``OrthoglideCalibration-v0``
(:mod:`orthoglide_env.envs.calibration`) run a :class:`LabBatch` of one episode; their
native vector envs run one of N.  Every rule is written once, on arrays whose first axis
is the episode: the time costs in :mod:`~orthoglide_env.lab.clock`, the refusals in
:mod:`~orthoglide_env.lab.refusals`, the rewards in :mod:`~orthoglide_env.lab.rewards`, and
here the installations, the levers, overtravel, readings, the tracker, collisions and the
end, each in a method of its name; and every random draw comes from the episode's
own stream in the order a lone lab draws it: the batched numbers equal the lone lab's to
the last bit.  What differs between the faces is in their :class:`~orthoglide_env.lab.
settings.LabSettings`; the machines are behind :class:`~orthoglide_env.lab.machines.
LabMachines`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from orthoglide_env.instruments import ballbar, interferometer, step_gauge, thermometer
from orthoglide_env.instruments.dial import Status, readings_of_status, status_of
from orthoglide_env.instruments.gauges import Gauge, GaugeArray
from orthoglide_env.instruments.slots import GaugeSpec, Part, on_platform
from orthoglide_env.instruments.stands import install_array, installation_errors
from orthoglide_env.lab.clock import overtravel_seconds, step_seconds, travel_seconds
from orthoglide_env.lab.faults import LabFaults
from orthoglide_env.lab.machines import ExactMachine, LabMachines, Sight
from orthoglide_env.lab.notebook import Notebook, Record, predicted_many
from orthoglide_env.lab.operations import CODE, OP_NAMES, TIME, TRACKER_DISTANCE, Op
from orthoglide_env.lab.refusals import assembled as assembled  # re-exported: its old home
from orthoglide_env.lab.refusals import raise_unreachable, refusals
from orthoglide_env.lab.rewards import ACCURACY_UNIT_MM as ACCURACY_UNIT_MM  # (its old home)
from orthoglide_env.lab.rewards import SECONDS_PER_HOUR as SECONDS_PER_HOUR  # (its old home)
from orthoglide_env.lab.rewards import step_rewards
from orthoglide_env.lab.settings import LabSettings
from orthoglide_env.model.collisions import PAIR_NAMES, collision_names
from orthoglide_env.model.errors import AXIS_NAMES, MachineParams
from orthoglide_env.reading_model import TrackerAxis
from orthoglide_env.scoring.truth import score
from orthoglide_env.world.faults import fault_stream
from orthoglide_env.world.table import (
    REFERENCE_DEVIATION,
    REFERENCE_LENGTH_MM,
    STEP_GAUGE_FACES,
)
from orthoglide_env.world.truth import REFERENCE_C, UM, World, draw_range

#: Whether each operation code puts the machine somewhere and reads it (a table, where
#: ``np.isin`` cost 4 % of a lone env's step).
_READS: np.ndarray = np.isin(np.arange(len(Op)), (Op.MOVE, Op.REMOUNT, Op.ALIGN, Op.PIVOT,
                                                   Op.PLACE))


#: The end of a refusal of an operation that would end past the budget (the episode
#: is then truncated): a written procedure ends there.
TIME_UP = "the time is up"


@dataclass
class StepResult:
    """One step of episodes ``rows`` (one entry per row)."""

    obs: dict[str, np.ndarray]
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    op: np.ndarray
    seconds: np.ndarray
    overtravel: list[list[str]]
    new_overtravel: np.ndarray  # (R, stands) the stands pushed past their travel
    collision: list[str]
    refused: list[str]
    predicted: np.ndarray  # predicted TCP error at the end, NaN where the episode goes on
    success: np.ndarray  # at the end: the predicted error meets the lab's target

    def info(self, i: int) -> dict[str, Any]:
        """Row ``i``'s info, as the lab env gives it."""
        info = {key: values[0] for key, values in self._ongoing(np.array([i])).items()}
        if self.terminated[i] or self.truncated[i]:
            info.update(is_success=bool(self.success[i]),
                        predicted_tcp_rigid_mm=float(self.predicted[i]))
        return info

    def columns(self, rows: np.ndarray) -> dict[str, list[Any]] | None:
        """:meth:`info` of ``rows`` key by key (each key's values in the order of
        ``rows``), or None when one of them ends its episode (its info has more keys): a
        step of a lab vector env makes no dict per env (a fifth of its own cost)."""
        ended = self.terminated[rows] | self.truncated[rows]
        return None if ended.any() else self._ongoing(rows)

    def _ongoing(self, rows: np.ndarray) -> dict[str, list[Any]]:
        """The info keys every step of ``rows`` has, key by key in the order of ``rows``."""
        picked = rows.tolist()
        return {"op": [OP_NAMES[o] for o in self.op[rows].tolist()],
                "step_time_s": self.seconds[rows].tolist(),
                "overtravel": [self.overtravel[r] for r in picked],
                "collision": [self.collision[r] for r in picked],
                "refused": [self.refused[r] for r in picked]}


class LabBatch:
    """The state of ``size`` lab episodes and the lab's rules applied to any of them.

    Episodes are rows; each has its random stream (``streams``), given at its reset.  The
    truth for scoring is on ``machines`` and each notebook's ``installed``; agents see
    observations and ``notebooks[i].records`` only."""

    def __init__(self, settings: LabSettings, size: int, backend: LabMachines) -> None:
        self.settings, self.size, self.backend = settings, size, backend
        n, s = size, settings.stands
        self.streams: list[np.random.Generator | None] = [None] * n
        self.machines: MachineParams | None = None
        self.rho = np.zeros((n, 3))
        self.tcp = np.full((n, 3), np.nan)  # the TCP at ``rho`` where solved, else NaN
        self.time = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.mounts = np.zeros(n, dtype=np.int64)  # mountings so far (names new ones)
        self.slot = np.full((n, s), -1, dtype=np.int64)  # -1: not mounted
        self.engaged = np.zeros((n, s), dtype=bool)
        self.faulted = np.zeros((n, s), dtype=bool)  # pushed past its travel: out of service
        self.pressed = np.zeros((n, s), dtype=bool)  # pressed past its travel at the last look
        self.status = np.zeros((n, s), dtype=np.int64)  # Status of each reading at the last
        self.count = np.zeros((n, s), dtype=np.int64)  # times each stand was mounted
        self.mounting: list[list[str]] = [[""] * s for _ in range(n)]
        self.slots = settings.slots  # the slot catalogue: its design's
        self.gauges = _unmounted((n, s), settings.travel, self.slots[0])
        self.notebooks = [self._notebook() for _ in range(n)]
        self.tracker_rotation = np.zeros((n, 3, 3))
        self.tracker_position = np.zeros((n, 3))
        self.tracker_reading = np.zeros((n, 3))
        self.thermometer_offset = np.zeros(n)  # K, each lab's thermometer (the truth)
        # The interferometer (a lab that owns one): the drive it is set up along (-1: none),
        # its set-ups so far, its count and the command where it was zeroed (-1: zero it at
        # its next reading), its reading now (NaN: none this step), and each lab's errors
        # (the truth): scale error and material sensor's error (K).
        self.laser_axis = np.full(n, -1, dtype=np.int64)
        self.laser_setups = np.zeros(n, dtype=np.int64)
        self.laser_zero = np.full(n, np.nan)
        self.laser_zero_rho = np.zeros(n)
        self.laser_reading = np.full(n, np.nan)
        self.laser_scale = np.zeros(n)
        self.laser_sensor = np.zeros(n)
        # The ballbar (a lab that owns one): its set-ups so far, the bar's nominal length
        # (NaN: not set up), the command its pivot was centred at, whether the bar is in,
        # its reading now (NaN: none this step); each lab's errors and the pivot (the
        # truth: where the centre ball is, in the geometry's frame) and its noise streams.
        self.bar_setups = np.zeros(n, dtype=np.int64)
        self.bar_length = np.full(n, np.nan)
        self.bar_centre = np.zeros((n, 3))
        self.bar_in = np.zeros(n, dtype=bool)
        self.bar_ready = np.zeros(n, dtype=bool)  # set up, the bar to go in at the next move
        self.bar_reading = np.full(n, np.nan)
        self.bar_scale = np.zeros(n)
        self.bar_centring = np.zeros((n, ballbar.MAX_SETUPS, 3))
        self.bar_pivot = np.zeros((n, 3))
        self.bar_streams: list[np.random.Generator | None] = [None] * n
        # The step gauge (a lab that owns one): its set-ups so far, the axis it lies along
        # and the command of its face 0, whether the probe is on it, where the TCP touched
        # face 0 (the truth, grown with the room; NaN: at the next reading), its reading
        # now (NaN: none this step); each lab's errors (the truth) and its noise streams.
        self.gauge_setups = np.zeros(n, dtype=np.int64)
        self.gauge_axis = np.zeros(n, dtype=np.int64)
        self.gauge_start = np.zeros((n, 3))
        self.gauge_in = np.zeros(n, dtype=bool)
        self.gauge_origin = np.full((n, 3), np.nan)
        self.gauge_reading = np.full(n, np.nan)
        self.gauge_faces = np.zeros((n, STEP_GAUGE_FACES))
        self.gauge_scale = np.zeros(n)
        self.gauge_normals = np.zeros((n, step_gauge.MAX_SETUPS, 3))
        self.gauge_streams: list[np.random.Generator | None] = [None] * n
        # The world beyond the geometry (None under ideal conditions): its drawn truth, the
        # carriages' actual positions, each axis's last direction of travel and each
        # plunger's (+1: going in) and its last ray distance.
        self.world: World | None = None
        self.actual = np.zeros((n, 3))
        self.approach = np.ones((n, 3))
        self.going_in = np.ones((n, s))
        self.last_t = np.full((n, s), np.nan)
        # The gauge block: each episode's true length (mm), and the length held in front of
        # each stand's plunger now (0: none; only while a reference stand is zeroed).
        self.block_length = np.full(n, REFERENCE_LENGTH_MM)
        self.block = np.zeros((n, s))
        # The slots stands can be at, by name: the catalogue, and any other place a layout
        # names (its index then lies past the catalogue's).
        self.places: list[GaugeSpec] = list(self.slots)
        self._place_index = {spec.slot: k for k, spec in enumerate(self.slots)}
        # What has gone wrong so far (None: a lab without faults).
        self.faults = (LabFaults(settings.faults, settings.conditions.name, settings.budget_s,
                                 n, s) if settings.faults.active else None)

    def place(self, spec: GaugeSpec) -> int:
        """The index of ``spec`` in :attr:`places` (added when new)."""
        index = self._place_index.get(spec.slot)
        if index is None:
            index = self._place_index[spec.slot] = len(self.places)
            self.places.append(spec)
        return index

    def _notebook(self) -> Notebook:
        return Notebook(self.settings.noise.effective_sigma, self.settings.tracker_sigma,
                        self.settings.design)

    def require(self) -> MachineParams:
        if self.machines is None:
            raise RuntimeError("call reset() before using the environment")
        return self.machines

    def reset(self, rows: np.ndarray, streams: list[np.random.Generator],
              machine: MachineParams | None = None,
              layout: tuple[GaugeSpec, ...] | None = None,
              world: World | None = None) -> dict[str, np.ndarray]:
        """New episodes for ``rows`` (each drawing from its stream in ``streams``, or on
        ``machine`` and ``world`` when given, a machine file's truth): the stands at the
        slots of ``layout`` (default the settings'), zeroed at Zero, and the first reading.
        Their observation rows."""
        settings = self.settings
        specs = settings.layout if layout is None else layout
        first = [self.place(spec) for spec in specs]
        # Seeded before the episode's stream draws: a seed's faults are known from it alone.
        own = None if self.faults is None else [fault_stream(s) for s in streams]
        drawn, rotations, positions, errors, worlds, offsets = [], [], [], [], [], []
        lasers: list[tuple[float, float]] = []
        bars: list[ballbar.BallbarErrors] = []
        probes: list[step_gauge.StepGaugeErrors] = []
        for stream in streams:
            drawn.append(settings.preset.sample(stream, settings.design) if machine is None
                         else machine)
            if settings.station:
                rotations.append(_random_rotation(stream))
                direction = stream.normal(size=3)
                positions.append(TRACKER_DISTANCE * direction / np.linalg.norm(direction))
            errors.append(installation_errors(len(first), settings.preset, stream))
            if settings.conditions.active:
                worlds.append(World.draw(settings.conditions, stream, settings.stands)
                              if world is None else world)
            if settings.thermometer:
                offsets.append(thermometer.draw_offset(settings.conditions, stream))
            if settings.interferometer:
                lasers.append(interferometer.draw_errors(settings.conditions, stream))
            if settings.ballbar:
                bars.append(ballbar.draw_errors(settings.conditions, stream))
            if settings.step_gauge:
                probes.append(step_gauge.draw_errors(settings.conditions, stream))
        blocks = np.full(len(rows), REFERENCE_LENGTH_MM)
        if settings.reference and settings.conditions.active:
            # Drawn last: a lab without the block draws what it always drew.
            deviation = REFERENCE_DEVIATION.at(settings.conditions.name)
            blocks += np.array([draw_range(stream, deviation, (), True, UM)
                                for stream in streams])
        machines = MachineParams.stack(drawn)
        world = World.stack(worlds) if worlds else None
        installed = self._installed(machines, list(specs), np.stack(errors), world,
                                    np.zeros(len(rows)), np.ones((len(rows), 3)),
                                    np.broadcast_to(np.arange(len(first)),
                                                    (len(rows), len(first))))
        # Nothing above is stored: a failure leaves every episode as it was.
        self.backend.start(rows, machines)
        self.machines = machines if self.machines is None or len(rows) == self.size else (
            _with_rows(self.machines, rows, machines))
        if world is not None:
            self.world = world if self.world is None or len(rows) == self.size else (
                self.world.with_rows(rows, world))
            self.approach[rows] = self.going_in[rows] = 1.0
            self.last_t[rows] = np.nan
            self.actual[rows] = world.joints(np.zeros((len(rows), 3)), self.approach[rows],
                                             np.zeros(len(rows)), settings.design)
        self.block_length[rows] = blocks
        self.block[rows] = 0.0
        self.rho[rows] = 0.0
        self.tcp[rows] = np.nan
        self.time[rows] = 0.0
        self.steps[rows] = 0
        self.mounts[rows] = len(first)
        on = np.arange(settings.stands) < len(first)  # the stands mounted at the start
        self.slot[rows] = -1
        self.slot[rows, : len(first)] = first
        self.engaged[rows] = self.count[rows] = on
        self.faulted[rows] = False  # (``pressed`` is set by the first look below)
        self.gauges = self.gauges.with_rows((rows[:, None], np.arange(settings.stands)), _unmounted(
            (len(rows), settings.stands), settings.travel, self.slots[0]))
        self.gauges = self.gauges.with_rows((rows[:, None], np.arange(len(first))), installed)
        names = [spec.slot for spec in specs]
        if self.faults is not None:
            self.faults.reset(rows, own)  # type: ignore[arg-type]
        for r, i in enumerate(rows):
            self.streams[i] = streams[r]
            self.mounting[i] = names + [""] * (settings.stands - len(first))
            book = self._notebook()
            book.install(names, installed, r)
            self.notebooks[i] = book
        if settings.station:
            self.tracker_rotation[rows] = rotations
            self.tracker_position[rows] = positions
        if settings.thermometer:
            self.thermometer_offset[rows] = offsets
        if settings.interferometer:
            self.laser_scale[rows], self.laser_sensor[rows] = np.array(lasers).T
        self.laser_axis[rows], self.laser_setups[rows] = -1, 0
        self.laser_reading[rows] = np.nan
        if settings.ballbar:
            self.bar_scale[rows] = [b.scale for b in bars]
            self.bar_centring[rows] = [b.centring for b in bars]
            for r, i in enumerate(rows.tolist()):
                self.bar_streams[i] = ballbar.noise_stream(streams[r])
        self.bar_setups[rows], self.bar_length[rows] = 0, np.nan
        self.bar_in[rows] = self.bar_ready[rows] = False
        self.bar_reading[rows] = np.nan
        if settings.step_gauge:
            self.gauge_faces[rows] = [g.faces for g in probes]
            self.gauge_scale[rows] = [g.scale for g in probes]
            self.gauge_normals[rows] = [g.normals for g in probes]
            for r, i in enumerate(rows.tolist()):
                self.gauge_streams[i] = step_gauge.noise_stream(streams[r])
        self.gauge_setups[rows] = 0
        self.gauge_in[rows] = False
        self.gauge_reading[rows] = np.nan
        self._sync(rows)
        if world is not None:
            self.backend.move(rows, self.actual[rows])
        sight = self._look(rows, np.zeros(len(rows)))
        self.pressed[rows] = sight.pressed & self.engaged[rows]
        values = self._read(rows, np.zeros(len(rows)), sight)
        return self.observation(rows, values)

    def step(self, rows: np.ndarray, op: np.ndarray, rho: np.ndarray, stand: np.ndarray,
             slot: np.ndarray, read_laser: np.ndarray | None = None) -> StepResult:
        """Apply each row's checked action (see
        :func:`~orthoglide_env.lab.actions.check_lab_actions`) to its episode: the clock,
        the refusals, the new installations, the carriages, the levers, a look at the
        machine (overtravel, crashes), the readings, the end and the reward, in this order
        (the order of every random draw).  ``read_laser`` (``OrthoglideLab-v4``): whether each
        row's move reads the interferometer set up, and waits its dwell (None: every
        move does, as before; an operation other than a move reads it whatever)."""
        settings, machines = self.settings, self.require()
        # Where each move or re-mount takes the carriages, and when: the commanded posture
        # in an ideal world.
        aligns = op == CODE.ALIGN  # (its axis is in ``slot``)
        pivots = op == CODE.PIVOT  # (its bar is in ``slot``)
        places = op == CODE.PLACE  # (its axis is in ``slot``)
        goal = np.where(((op == CODE.REMOUNT) | aligns)[:, None], 0.0, rho)
        if read_laser is not None:
            read_laser = read_laser | (op != CODE.MOVE)
        laser = (self.laser_axis[rows] >= 0) & (True if read_laser is None else read_laser)
        travel_s = travel_seconds(op, self.rho[rows], goal, settings.tracker, (
            (op == CODE.REMOUNT) & self._references(slot) if settings.reference else None),
            *((laser, self.laser_setups[rows] == 0) if settings.interferometer else
              (None, None)), probe=self.gauge_in[rows] if settings.step_gauge else None)
        approach, target = self._carriages(rows, goal, self.time[rows] + travel_s)
        refused, reached = refusals(machines, rows, op, rho, stand, slot, target,
                                    self.slot[rows], self.places)
        if aligns.any() and not settings.interferometer:
            for r in np.flatnonzero(aligns):
                refused[r] = ("the lab has no interferometer (instruments="
                              f"{list(settings.instruments)})")
        if pivots.any():
            self._refuse_setups(rows, pivots, refused, "ballbar", self.settings.ballbar,
                                self.bar_setups, ballbar.MAX_SETUPS)
        if places.any():
            self._refuse_setups(rows, places, refused, "step gauge", self.settings.step_gauge,
                                self.gauge_setups, step_gauge.MAX_SETUPS)
        if settings.strict_moves:
            raise_unreachable(machines, rows, op, rho, reached, target, self.size)
        late = self._refuse_late(rows, op, travel_s, refused)
        ok = np.array([not r for r in refused], dtype=bool)
        inserted = self._bar_after(rows, ok, op, goal)
        probing = self._gauge_after(rows, ok, op, goal)
        moves, remounts = ok & (op == CODE.MOVE), ok & (op == CODE.REMOUNT)
        aligned, pivoted, placed = ok & aligns, ok & pivots, ok & places
        flicks = ok & ((op == CODE.LIFT) | (op == CODE.ENGAGE))
        # New installations first (they draw from the streams before the readings do, and
        # may fail): nothing is stored before they are made.
        mounted = self._installations(rows[remounts], stand[remounts], slot[remounts],
                                      (self.time[rows] + travel_s)[remounts],
                                      approach[remounts]) if remounts.any() else None
        seconds = step_seconds(ok, flicks, moves | remounts | aligned | pivoted | placed,
                               travel_s)
        # An operation that cannot end within the budget is not begun: the time is up.
        seconds[late] = settings.budget_s - self.time[rows][late]
        self._drive(rows, moves | pivoted | placed, remounts | aligned, goal, reached, target,
                    approach)
        self.bar_in[rows] = inserted
        self.gauge_in[rows] = probing
        self.bar_ready[rows] &= ~ok  # (a set-up below makes its own ready)
        if aligned.any():
            self._align(rows[aligned], slot[aligned])
        if flicks.any():
            self._flick(rows[flicks], stand[flicks], (op == CODE.ENGAGE)[flicks])
        if remounts.any():
            self._mount(rows[remounts], stand[remounts], slot[remounts],
                        mounted)  # type: ignore[arg-type]
            self._sync(rows[remounts])
        reads = ok & _READS[op]
        presses = reads | (ok & (op == CODE.ENGAGE))
        looks = _READS[op] | presses  # a refused move still checks for a crash
        sight = self._look(rows[looks], (self.time[rows] + seconds)[looks])
        at = np.cumsum(looks) - 1  # row of each looked-at episode in ``sight``
        overtravel, new_overtravel = self._overtravel(rows, presses, sight, at)
        seconds += overtravel_seconds(new_overtravel)
        if pivoted.any():
            self._pivot(rows[pivoted], goal[pivoted], slot[pivoted])
        if placed.any():
            self._place(rows[placed], goal[placed], slot[placed])
        values = np.full((len(rows), settings.stands), np.nan)
        self.laser_reading[rows] = np.nan
        self.bar_reading[rows] = np.nan
        self.gauge_reading[rows] = np.nan
        if reads.any():
            values[reads] = self._read(rows[reads], seconds[reads], Sight(
                *(part[at[reads]] for part in sight)),
                None if read_laser is None else read_laser[reads])
        if remounts.any():
            self._take_blocks_away(rows[remounts], stand[remounts])
        # The budget ends the lab's time, whatever a step's stands pushed past their travel
        # (or a refusal's lever flick) would have taken after it: equal lab time for every
        # agent, enforced.
        seconds = np.minimum(seconds, np.maximum(settings.budget_s - self.time[rows], 0.0))
        self.time[rows] += seconds
        self.steps[rows] += 1
        collision = self._collisions(op, looks, sight, at)
        terminated, truncated = self._ends(rows, op, collision)
        ended = terminated | truncated
        reward = self._rewards(rows, seconds, ended)
        predicted = np.full(len(rows), np.nan)
        if ended.any():
            predicted[ended] = predicted_many([self.notebooks[i] for i in rows[ended]])
        return StepResult(self.observation(rows, values, reads), reward, terminated, truncated,
                          op, seconds, overtravel, new_overtravel, collision, refused,
                          predicted,
                          ended & (predicted <= settings.success_mm))

    # -- the pieces of a step ------------------------------------------------------------------
    def _drive(self, rows: np.ndarray, moves: np.ndarray, remounts: np.ndarray,
               goal: np.ndarray, reached: np.ndarray, target: np.ndarray,
               approach: np.ndarray) -> None:
        """Drive the carriages of the ``moves`` and ``remounts`` (masks over ``rows``) to
        their ``goal`` (commanded; the backend's machines to ``target``, where they are):
        a move's TCP is where it ``reached``, a re-mount's is solved at the next look."""
        carried = moves | remounts
        if not carried.any():
            return
        self.rho[rows[carried]] = goal[carried]
        self.tcp[rows[carried]] = np.where(moves[carried, None], reached[carried], np.nan)
        if self.world is not None:
            self.actual[rows[carried]] = target[carried]
            self.approach[rows[carried]] = approach[carried]
        self.backend.move(rows[carried], target[carried])

    def _align(self, rows: np.ndarray, axis: np.ndarray) -> None:
        """Set the interferometer of ``rows`` up along drive ``axis``: a new set-up, its
        count zeroed at its first reading (at Zero, where the step drove)."""
        self.laser_axis[rows] = axis
        self.laser_setups[rows] += 1
        self.laser_zero[rows] = np.nan

    def _laser(self, rows: np.ndarray, when: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """What the interferometers of ``rows`` (each set up) read at lab time ``when``
        with standard normal ``draws``: the carriage's displacement from the zero as the
        instrument measures it (the machine grown with the room, then compensated at its
        material sensor's temperature), less the command's (mm)."""
        settings, axis = self.settings, self.laser_axis[rows]
        at = self.rho if self.world is None else self.actual
        raw = at[rows, axis] - settings.design.rho_min
        factor = interferometer.compensation(settings.conditions, self.laser_scale[rows],
                                             self.laser_sensor[rows], np.zeros(len(rows)))
        if self.world is not None:
            world = self._of(self.world, rows)
            raw = raw * world.scale(when)
            factor = interferometer.compensation(settings.conditions, self.laser_scale[rows],
                                                 self.laser_sensor[rows],
                                                 world.temperature(when))
        fresh = np.isnan(self.laser_zero[rows])
        self.laser_zero[rows[fresh]] = raw[fresh]
        self.laser_zero_rho[rows[fresh]] = self.rho[rows[fresh], axis[fresh]]
        moved = self.rho[rows, axis] - self.laser_zero_rho[rows]
        return (factor * (raw - self.laser_zero[rows]) - moved
                + interferometer.sigma(settings.conditions) * draws)

    def _refuse_setups(self, rows: np.ndarray, chosen: np.ndarray, refused: list[str],
                       name: str, owned: bool, setups: np.ndarray, most: int) -> None:
        """Refuse the set-ups of instrument ``name`` (``chosen``, a mask over ``rows``) of
        a lab without it (``owned`` False), or one whose ``most`` drawn set-ups are all used
        (``setups`` so far, per env)."""
        for r in np.flatnonzero(chosen):
            if not owned:
                refused[r] = (f"the lab has no {name} (instruments="
                              f"{list(self.settings.instruments)})")
            elif setups[rows[r]] >= most:
                refused[r] = f"the {name} was set up {most} times: no more"

    def _bar_after(self, rows: np.ndarray, ok: np.ndarray, op: np.ndarray, goal: np.ndarray
                   ) -> np.ndarray:
        """Whether the bar of each of ``rows`` is in after the step: the first move after a
        set-up puts it in, and every move while it is in keeps it in (each must bring the
        nominal machine's TCP within the bar's travel of the pivot: ``ValueError`` before
        anything changes); any other operation takes it off."""
        before = self.bar_in[rows] | self.bar_ready[rows]
        after = self.bar_in[rows] & ~ok
        moving = ok & (op == CODE.MOVE) & before
        travel, design = ballbar.travel_mm(), self.settings.design
        for r in np.flatnonzero(moving).tolist():
            i = int(rows[r])
            spec = ballbar.BallbarSpec(tuple(self.bar_centre[i].tolist()),
                                       float(self.bar_length[i]))
            reading = float(ballbar.nominal_readings(design, spec, goal[r]))
            if abs(reading) > travel:
                where = f" of env {i}" if self.size > 1 else ""
                raise ValueError(
                    f"action{where} rho {goal[r].tolist()} mm: the ballbar ({spec.length:g} mm "
                    f"bar, pivot centred at rho {list(spec.centre)}) would read "
                    f"{reading:+.3f} mm, outside its travel +-{travel:g} mm (any operation "
                    "but a move takes the bar off)")
            after[r] = True
        return after

    def _pivot(self, rows: np.ndarray, centre: np.ndarray, bar: np.ndarray) -> None:
        """Set the ballbar of ``rows`` up: its pivot centred where the TCP now is (the
        centre command ``centre``, the look of this step solved it), off by the set-up's
        centring error; the bar of index ``bar`` fitted, not yet in."""
        count = self.bar_setups[rows]
        self.bar_pivot[rows] = self.tcp[rows] + self.bar_centring[rows, count]
        self.bar_centre[rows] = centre
        self.bar_length[rows] = [ballbar.length_of(int(b)) for b in bar]
        self.bar_setups[rows] += 1
        self.bar_ready[rows] = True

    def _read_bar(self, rows: np.ndarray) -> None:
        """Read the bars of ``rows`` (each in) at the TCP the last look solved: NaN where
        the true distance leaves the travel (the nominal machine put it inside)."""
        draws = np.array([self.bar_streams[i].normal() for i in rows.tolist()])  # type: ignore[union-attr]
        distance = np.linalg.norm(self.tcp[rows] - self.bar_pivot[rows], axis=-1)
        values = ballbar.readings(distance, self.bar_length[rows], self.bar_scale[rows],
                                  self.settings.conditions, draws)
        self.bar_reading[rows] = np.where(np.abs(values) <= ballbar.travel_mm(), values, np.nan)

    def _gauge_after(self, rows: np.ndarray, ok: np.ndarray, op: np.ndarray, goal: np.ndarray
                     ) -> np.ndarray:
        """Whether the probe of each of ``rows`` is on the step gauge after the step: a
        set-up puts it on, and every move while it is on keeps it there (each must bring
        the nominal machine's TCP to a face: ``ValueError`` before anything changes); any
        other operation takes it off."""
        after = (self.gauge_in[rows] & ~ok) | (ok & (op == CODE.PLACE))
        design = self.settings.design
        for r in np.flatnonzero(ok & (op == CODE.MOVE) & self.gauge_in[rows]).tolist():
            i = int(rows[r])
            spec = step_gauge.StepGaugeSpec(int(self.gauge_axis[i]),
                                            tuple(self.gauge_start[i].tolist()))
            problem = step_gauge.off_face(design, spec, goal[r])
            if problem:
                where = f" of env {i}" if self.size > 1 else ""
                raise ValueError(f"action{where} rho {goal[r].tolist()} mm: no step of the "
                                 f"gauge ({spec.slot}) is read there: {problem} (any "
                                 "operation but a move takes the probe off)")
            after[r] = True
        return after

    def _place(self, rows: np.ndarray, start: np.ndarray, axis: np.ndarray) -> None:
        """Set the step gauge of ``rows`` up along world ``axis`` with face 0 at the TCP of
        command ``start`` (where the step drove): its probe is zeroed on face 0 at this
        step's reading."""
        self.gauge_axis[rows] = axis
        self.gauge_start[rows] = start
        self.gauge_setups[rows] += 1
        self.gauge_origin[rows] = np.nan

    def _read_gauge(self, rows: np.ndarray, when: np.ndarray) -> None:
        """Read the step gauges of ``rows`` (each on) at the TCP the last look solved, at
        lab time ``when``: the face the nominal machine puts the TCP at, the TCP grown
        with the room, and the room's temperature and the thermometer's reading of it; NaN
        where the true TCP leaves the probe's range (the nominal machine put it inside)."""
        settings = self.settings
        draws = np.array([self.gauge_streams[i].normal() for i in rows.tolist()])  # type: ignore[union-attr]
        tcp = self.tcp[rows]
        temperature = read = np.zeros(len(rows))
        if self.world is not None:
            world = self._of(self.world, rows)
            tcp = tcp * world.scale(when)[:, None]
            temperature = world.temperature(when)
        if settings.thermometer:
            read = np.asarray(self._room(rows, when), dtype=float) - REFERENCE_C
        fresh = np.isnan(self.gauge_origin[rows, 0])
        self.gauge_origin[rows[fresh]] = tcp[fresh]
        axis = self.gauge_axis[rows]
        face = np.array([int(step_gauge.faces_of(settings.design, step_gauge.StepGaugeSpec(
            int(a), tuple(start)), rho)[0]) for a, start, rho in zip(
                axis.tolist(), self.gauge_start[rows].tolist(), self.rho[rows], strict=True)])
        normal = step_gauge.world_normal(
            axis, self.gauge_normals[rows, self.gauge_setups[rows] - 1])
        values = step_gauge.readings(
            tcp - self.gauge_origin[rows], normal, axis, face,
            (self.gauge_faces[rows], self.gauge_scale[rows]), (temperature, read),
            settings.conditions, draws)
        reach = step_gauge.probe_range_mm()
        self.gauge_reading[rows] = np.where(np.abs(values) <= reach, values, np.nan)

    def _flick(self, rows: np.ndarray, stand: np.ndarray, engages: np.ndarray) -> None:
        """Lift (or, where ``engages``, engage) the plunger of each ``stand`` of ``rows``."""
        self.engaged[rows, stand] = engages
        # An engaged plunger drops onto its bar: it comes out.
        self.going_in[rows[engages], stand[engages]] = -1.0
        self.last_t[rows[engages], stand[engages]] = np.nan

    def _overtravel(self, rows: np.ndarray, presses: np.ndarray, sight: Sight, at: np.ndarray
                    ) -> tuple[list[list[str]], np.ndarray]:
        """The engaged stands of the ``presses`` (a mask over ``rows``) that ``sight`` (the
        look at row ``at``) shows newly pushed past their travel: each row's names of them,
        and them (R, stands).  Under ``overtravel="fault"`` they go out of service until
        re-mounted; otherwise each press is momentary (staying pressed is not a new one)."""
        settings = self.settings
        overtravel: list[list[str]] = [[] for _ in rows]
        new_overtravel = np.zeros((len(rows), settings.stands), dtype=bool)
        if not presses.any():
            return overtravel, new_overtravel
        pressing = rows[presses]
        pressed = (sight.pressed[at[presses]] & self.engaged[pressing]
                   & (self.slot[pressing] >= 0))
        before = self.faulted if settings.overtravel == "fault" else self.pressed
        new = pressed & ~before[pressing]
        if settings.overtravel == "fault":
            self.faulted[pressing] |= new
        self.pressed[pressing] = pressed
        new_overtravel[presses] = new
        hits = new.any(axis=-1)
        for r, hit in zip(np.flatnonzero(presses)[hits], new[hits], strict=True):
            overtravel[r] = [f"stand {k} ({self.mounting[rows[r]][k]})"
                             for k in np.flatnonzero(hit)]
        return overtravel, new_overtravel

    def _take_blocks_away(self, rows: np.ndarray, stand: np.ndarray) -> None:
        """A reference stand was zeroed on the gauge block, then the block is taken away
        (the stands just mounted: ``stand`` of ``rows``)."""
        if self.block[rows, stand].any():
            self.block[rows, stand] = 0.0
            self._sync(rows)

    def _collisions(self, op: np.ndarray, looks: np.ndarray, sight: Sight, at: np.ndarray
                    ) -> list[str]:
        """The parts that collide (", "-joined, "" for none) where a move or re-mount looked
        (``looks``; the look at row ``at`` of ``sight``)."""
        collision = [""] * len(op)
        crashed = np.zeros(len(op), dtype=bool)
        crashed[looks] = sight.crashed.any(axis=-1)
        for r in np.flatnonzero(crashed & _READS[op]):
            collision[r] = ", ".join(collision_names(sight.crashed[at[r]]))
        return collision

    def _refuse_late(self, rows: np.ndarray, op: np.ndarray, travel_s: np.ndarray,
                     refused: list[str]) -> np.ndarray:
        """Refuse (in ``refused``) each operation of ``rows`` not refused yet that would end
        past the budget (its drive and work, ``travel_s``; a lever's flick); the mask of
        them."""
        budget = self.settings.budget_s
        flick = (op == CODE.LIFT) | (op == CODE.ENGAGE)
        ends = self.time[rows] + np.where(flick, TIME.lift_s, np.where(_READS[op], travel_s,
                                                                       0.0))
        late = (ends > budget) & np.array([not r for r in refused], dtype=bool)
        for r in np.flatnonzero(late):
            refused[r] = (f"it would end at {ends[r]:.1f} s, past the budget of {budget:g} s: "
                          f"{TIME_UP}")
        return late

    def _ends(self, rows: np.ndarray, op: np.ndarray, collision: list[str]
              ) -> tuple[np.ndarray, np.ndarray]:
        """Which episodes of ``rows`` end now: terminated (a stop, a crash) and truncated
        (the time budget spent, or the step limit reached, crashed or not)."""
        settings = self.settings
        terminated = (op == CODE.STOP) | np.array([bool(c) for c in collision], dtype=bool)
        truncated = ~terminated & (self.time[rows] >= settings.budget_s)
        if settings.max_steps is not None:
            truncated |= self.steps[rows] >= settings.max_steps
        return terminated, truncated

    def _rewards(self, rows: np.ndarray, seconds: np.ndarray, ended: np.ndarray) -> np.ndarray:
        """The reward of each step of ``rows`` (see :func:`~orthoglide_env.lab.rewards.
        step_rewards`), with what its kind needs of the notebooks and the truth."""
        settings = self.settings
        gains = finals = None
        if settings.reward == "information":
            # Each notebook sums its own information, step by step (a loop over episodes).
            gains = np.array([self.notebooks[i].update_logdet() for i in rows])
        elif settings.reward != "time":
            finals = [self.final_tcp_rigid_mm(int(i)) for i in rows[ended]]
        return step_rewards(settings.reward, seconds, gains=gains,
                            time_weight=settings.time_weight, final_errors=finals,
                            ended=ended)

    def _carriages(self, rows: np.ndarray, goal: np.ndarray, when: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Each axis's direction of travel (R, 3) to ``goal`` (commanded, R x 3) and where
        the carriages then are at lab time ``when`` (the goal itself in an ideal world)."""
        if self.world is None:
            return self.approach[rows], goal
        before = self.rho[rows]
        approach = np.where(goal > before, 1.0, np.where(goal < before, -1.0,
                                                         self.approach[rows]))
        world, gauges = self._of(self.world, rows), self._of(self.gauges, rows)
        # The indicators press as they did at the last look (the plunger's next depth is
        # a micrometre-level change of a force that moves the platform by nanometres).
        pressing = np.where(self.engaged[rows], self.last_t[rows], np.nan)
        share = np.where(gauges.part == int(Part.BAR), 1 - gauges.at,
                         np.where(on_platform(gauges.part), 1.0, 0.0))
        load = world.platform_load(pressing, gauges.travel, gauges.direction, share)
        return approach, world.joints(goal, approach, when, self.settings.design, load)

    def _references(self, slot: np.ndarray) -> np.ndarray:
        """Whether each slot index names a reference slot."""
        return np.array([self.places[s].part == Part.REFERENCE for s in slot.tolist()],
                        dtype=bool)

    def _through(self, gauges: GaugeArray, block: np.ndarray) -> np.ndarray:
        """How much nearer a block of length ``block`` (mm, ``(R, G)``) held to the face
        brings each gauge's target along its ray: the length over the cosine of the ray's
        tilt from the face's normal, the world axis it measures along."""
        axis = np.broadcast_to(gauges.axis, block.shape)[..., None]
        along = np.take_along_axis(gauges.direction, axis, axis=-1)[..., 0]
        with np.errstate(invalid="ignore"):
            return np.where(block > 0, block / np.abs(along), 0.0)

    def _of(self, value: Any, rows: np.ndarray) -> Any:
        """Rows ``rows`` of a batch's ``value`` (itself, not a copy, when they are every
        episode)."""
        return value if len(rows) == self.size else value[rows]

    def _installations(self, rows: np.ndarray, stand: np.ndarray, slot: np.ndarray,
                       when: np.ndarray, approach: np.ndarray
                       ) -> tuple[GaugeArray, World | None]:
        """New installations of stands ``stand`` at ``slot`` on the machines of ``rows``
        (some; drawn from their streams), zeroed at Zero at lab time ``when`` (reached
        from the ``approach`` directions): one gauge per row, (R,), and the machines'
        worlds with the new mountings."""
        errors, worlds = [], []
        for r, i in enumerate(rows):
            errors.append(installation_errors(1, self.settings.preset, self.streams[i]))
            if self.world is not None:
                worlds.append(self.world[i].mounted(self.streams[i], when[r], [stand[r]]))
        errors = np.stack(errors)
        world = World.stack(worlds) if worlds else None
        per_row: list[GaugeArray] = [None] * len(rows)  # type: ignore[list-item]
        for value in np.unique(slot):
            mine = np.flatnonzero(slot == value)
            block = (self.block_length[rows[mine], None]
                     if self.places[value].part == Part.REFERENCE else None)
            try:
                part = self._installed(self.require()[rows[mine]], [self.places[value]],
                                       errors[mine], None if world is None else world[mine],
                                       when[mine], approach[mine], stand[mine, None], block)
            except ValueError:
                raise ValueError(f"slot {self.places[value].slot} cannot be reached on this "
                                 "machine") from None
            for j, r in enumerate(mine):
                per_row[r] = part[j]
        return GaugeArray.stack(per_row), world

    def _installed(self, machines: MachineParams, specs: list, errors: np.ndarray,
                   world: World | None, when: np.ndarray, approach: np.ndarray,
                   stands: np.ndarray, block: np.ndarray | None = None) -> GaugeArray:
        """Gauges of ``specs`` installed on each machine with ``errors`` (R, G, 2, 3) on
        ``stands`` (R, G), slid to mid-travel and zeroed at Zero at lab time ``when`` (the
        dial reads 0 then, whatever the world adds), against a gauge block of length
        ``block`` (R, G) held to the face when given; ``ValueError`` when one misses its
        bar there."""
        design = self.settings.design
        gauges = install_array(specs, machines, travel=self.settings.travel, errors=errors)
        block = np.zeros(gauges.origin.shape[:-1]) if block is None else block
        if world is None:
            return gauges.zeroed(ExactMachine(machines, gauges).gauge_distances()
                                 - self._through(gauges, block))
        zero = world.joints(np.zeros((len(when), 3)), approach, when, design)
        # Slid to mid-travel, then the bezel is turned to 0 where the dial points.
        slid = gauges.zeroed(ExactMachine(machines, gauges, zero).gauge_distances()
                             - self._through(gauges, block))
        half = slid.zero * world.scale(when)[:, None]
        return replace(slid, zero=half + world.columns(stands).distance_offsets(
            half, np.ones(half.shape), when, slid.at, slid.part == Part.BAR, slid.travel,
            design))

    def _mount(self, rows: np.ndarray, stand: np.ndarray, slot: np.ndarray,
               made: tuple[GaugeArray, World | None]) -> None:
        """Store the installations of :meth:`_installations` (one gauge per row)."""
        gauges, world = made
        self.gauges = self.gauges.with_rows((rows, stand), gauges)
        if world is not None:
            self.world = self.world.with_rows(rows, world)  # type: ignore[union-attr]
            self.going_in[rows, stand] = 1.0  # slid in to mid-travel
            self.last_t[rows, stand] = np.nan
        self.mounts[rows] += 1
        self.block[rows, stand] = np.where(self._references(slot), self.block_length[rows], 0.0)
        self.slot[rows, stand] = slot
        self.engaged[rows, stand] = True
        self.faulted[rows, stand] = False
        self.pressed[rows, stand] = False
        self.count[rows, stand] += 1
        if self.faults is not None:
            self.faults.remounted(rows, stand)
        for r, (i, k, s) in enumerate(zip(rows, stand, slot, strict=True)):
            name = f"{self.places[s].slot}#{self.mounts[i]}"
            self.mounting[i][k] = name
            self.notebooks[i].installed[name] = gauges[r].to_gauges()[0]

    def _sync(self, rows: np.ndarray) -> None:
        """Hand the backend the gauges of every mounted stand of ``rows``."""
        self.backend.set_gauges(rows, self._seen(rows), self.slot[rows] >= 0)

    def _seen(self, rows: np.ndarray) -> GaugeArray:
        """The gauges of ``rows`` as the machine meets them: a plunger set on a gauge block
        held to the face reads as if its stand stood the block's length nearer."""
        gauges, block = self._of(self.gauges, rows), self.block[rows]
        if not block.any():
            return gauges
        ahead = self._through(gauges, block)[..., None] * gauges.direction
        return replace(gauges, origin=gauges.origin + np.nan_to_num(ahead))

    def _look(self, rows: np.ndarray, when: np.ndarray) -> Sight:
        """What the machines of ``rows`` show at lab time ``when``."""
        if not len(rows):
            stands = self.settings.stands
            return Sight(np.zeros((0, stands)), np.zeros((0, stands), dtype=bool),
                         np.zeros((0, len(PAIR_NAMES)), dtype=bool), np.zeros((0, 3)))
        at = self.rho if self.world is None else self.actual
        if self.faults is not None:
            self.faults.fire(self, rows, when)
            at = self.faults.moved(at)
        sight = self.backend.look(rows, self._of(self.require(), rows), self._seen(rows),
                                  *(self._of(x, rows) for x in (at, self.tcp, self.engaged)))
        self.tcp[rows] = sight.tcp
        return sight if self.world is None else self._in_world(rows, sight, when)

    def _in_world(self, rows: np.ndarray, sight: Sight, when: np.ndarray) -> Sight:
        """``sight`` (the geometry at the carriages' positions) as the world shows it at
        ``when``: the structure grown with the room, each reading moved by its stand,
        indicator and bar; each engaged plunger's direction of travel followed."""
        world, gauges = self._of(self.world, rows), self._of(self.gauges, rows)
        scale = world.scale(when)
        t = sight.t * scale[:, None]
        last = self.last_t[rows]
        followed = self.engaged[rows] & np.isfinite(t)
        with np.errstate(invalid="ignore"):
            going = np.where(followed & (t < last), 1.0, np.where(
                followed & (t > last), -1.0, self.going_in[rows]))
        self.going_in[rows] = going
        self.last_t[rows] = np.where(followed, t, last)
        t = t + world.distance_offsets(t, going, when, gauges.at, gauges.part == int(Part.BAR),
                                       gauges.travel, self.settings.design)
        return sight._replace(t=t, tcp=sight.tcp * scale[:, None])

    def _read(self, rows: np.ndarray, pending: np.ndarray, sight: Sight,
              laser: np.ndarray | None = None) -> np.ndarray:
        """Read every engaged, working gauge (and the tracker) of ``rows``: noisy values per
        stand, NaN where there is none; every reading goes to the notebooks.  ``pending``:
        the seconds of the step so far (the readings are written at its end); ``laser``:
        which rows may read their interferometer, where one is set up (None: all)."""
        settings = self.settings
        gauges = self._of(self.gauges, rows)
        mounted = self.slot[rows] >= 0
        status = status_of(gauges, sight.t)
        self.status[rows] = status
        good = status == int(Status.VALID)
        ideal = readings_of_status(gauges, sight.t, status)
        draws = np.zeros(ideal.shape)
        laser = (self.laser_axis[rows] >= 0) & (True if laser is None else laser)
        laser_draws = np.zeros(len(rows))
        counts = mounted.sum(axis=1).tolist()
        drawn = []
        for r, i in enumerate(rows.tolist()):
            # A lone lab draws one number per mounted gauge, then the tracker's three.
            stream: np.random.Generator = self.streams[i]  # type: ignore[assignment]
            drawn.append(settings.noise.draws(stream, (counts[r],)))
            if settings.tracker:
                seen = self.tracker_rotation[i] @ sight.tcp[r] + self.tracker_position[i]
                if self.world is not None and "tracker" in settings.conditions:
                    noise = self.world.tracker_noise(stream.normal(0.0, 1.0, (1, 3)),
                                                     seen[None])[0]
                else:
                    noise = stream.normal(0.0, settings.tracker_sigma, 3)
                self.tracker_reading[i] = seen + noise
            if laser[r]:
                laser_draws[r] = stream.normal()
        draws[mounted] = np.concatenate(drawn)  # row by row, each row's stands in order
        if laser.any():
            self.laser_reading[rows[laser]] = self._laser(
                rows[laser], (self.time[rows] + pending)[laser], laser_draws[laser])
        if self.bar_in[rows].any():
            self._read_bar(rows[self.bar_in[rows]])
        if self.gauge_in[rows].any():
            probing = self.gauge_in[rows]
            self._read_gauge(rows[probing], (self.time[rows] + pending)[probing])
        if self.world is not None:
            # The same draws, scaled up where a digital indicator scatters more: a batch
            # draws what a lone lab draws.
            ideal = ideal + draws * self._of(self.world, rows).scatter(sight.t, gauges.travel)
        noisy = settings.noise.applied(ideal, draws)
        valid = good & mounted & self.engaged[rows] & ~self.faulted[rows]
        values = np.where(valid, noisy, np.nan)
        if self.faults is not None:
            values = self.faults.shown(rows, values)
        if settings.notebook:
            self._write(rows, pending, valid, values)
        return values

    def _write(self, rows: np.ndarray, pending: np.ndarray, valid: np.ndarray,
               values: np.ndarray) -> None:
        """Write the ``valid`` gauge ``values`` (and the tracker's) of ``rows`` into their
        notebooks, from plain lists (one Record per reading)."""
        settings = self.settings
        if self.faults is not None:
            valid, values = self.faults.written(rows, valid, values)
        index, rho = rows.tolist(), [tuple(p) for p in self.rho[rows].tolist()]
        steps, stamps = self.steps[rows].tolist(), (self.time[rows] + pending).tolist()
        read, slots = values.tolist(), self.slot[rows].tolist()
        room = self._room(rows, self.time[rows] + pending)
        notebooks, places, mountings, written = (self.notebooks, self.places, self.mounting,
                                                 Record.written)
        for r, k in zip(*(part.tolist() for part in np.nonzero(valid)), strict=True):
            i = index[r]
            notebooks[i].records.append(written(places[slots[r][k]], mountings[i][k], rho[r],
                                                read[r][k], steps[r], stamps[r], room[r]))
        if settings.tracker:
            tracker = self.tracker_reading[rows].tolist()
            for r, i in enumerate(index):
                self.notebooks[i].records.extend(
                    Record.written(TrackerAxis(c), f"tracker.{AXIS_NAMES[c]}", rho[r],
                                   tracker[r][c], steps[r], stamps[r], room[r])
                    for c in range(3))
        for r in np.flatnonzero(np.isfinite(self.laser_reading[rows])).tolist():
            i, axis = index[r], int(self.laser_axis[index[r]])
            self.notebooks[i].records.append(Record(
                interferometer.InterferometerAxis(axis),
                interferometer.mounting_name(axis, int(self.laser_setups[i])), rho[r],
                float(self.laser_reading[i]), steps[r], stamps[r], room[r]))

        for r in np.flatnonzero(np.isfinite(self.bar_reading[rows])).tolist():
            i = index[r]
            spec = ballbar.BallbarSpec(tuple(self.bar_centre[i].tolist()),
                                       float(self.bar_length[i]))
            self.notebooks[i].records.append(Record(
                spec, ballbar.mounting_name(int(self.bar_setups[i])), rho[r],
                float(self.bar_reading[i]), steps[r], stamps[r], room[r]))

        for r in np.flatnonzero(np.isfinite(self.gauge_reading[rows])).tolist():
            i = index[r]
            spec = step_gauge.StepGaugeSpec(int(self.gauge_axis[i]),
                                            tuple(self.gauge_start[i].tolist()))
            self.notebooks[i].records.append(Record(
                spec, step_gauge.mounting_name(int(self.gauge_setups[i])), rho[r],
                float(self.gauge_reading[i]), steps[r], stamps[r], room[r]))

    def _room(self, rows: np.ndarray, when: np.ndarray) -> list[float | None]:
        """What the thermometer of each of ``rows`` reads (C) at lab time ``when``; None
        where the lab has none."""
        if not self.settings.thermometer:
            return [None] * len(rows)
        temperature = (np.zeros(len(rows)) if self.world is None
                       else self._of(self.world, rows).temperature(when))
        return thermometer.read(self.settings.conditions, temperature,
                                self.thermometer_offset[rows]).tolist()

    # -- the truth and observations ------------------------------------------------------------
    def true_tcp(self, row: int) -> np.ndarray:
        """Where episode ``row``'s TCP truly is now (mm; scoring and fidelity checks)."""
        rows = np.array([row])
        at = self.rho if self.world is None else self.actual
        tcp = self.backend.look(rows, *(x[rows] for x in (
            self.require(), self.gauges, at, self.tcp, self.engaged))).tcp
        if self.world is not None:
            tcp = tcp * self.world[rows].scale(self.time[rows])[:, None]
        return tcp[0].copy()  # (a look may be shared: it is read-only)

    def final_tcp_rigid_mm(self, row: int) -> float:
        """TCP error RMS after the best-fit rigid motion of the machine the estimator makes
        of episode ``row``'s records (scoring against the truth)."""
        truth = self.require()[row]
        try:
            estimate = self.settings.estimator(self.notebooks[row].records,  # type: ignore[misc]
                                               self.settings.noise.effective_sigma)
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            estimate = MachineParams(design=truth.design)
        world = None if self.world is None else self.world[row]
        return score(estimate, truth, world=world).tcp_after.rigid.rms

    def observation(self, rows: np.ndarray, values: np.ndarray,
                    fresh: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Observation rows of episodes ``rows`` whose gauges read ``values`` (NaN: none);
        ``fresh``: which of them read (and so read the tracker), default all."""
        fresh = np.ones(len(rows), dtype=bool) if fresh is None else fresh
        tracked = fresh & self.settings.tracker
        valid = np.isfinite(values)
        slot = self.slot[rows]
        return {
            "gauges": np.where(valid, values, 0.0),
            "valid": valid.astype(np.int8),
            "engaged": (self.engaged[rows] & ~self.faulted[rows]).astype(np.int8),
            "faulted": self.faulted[rows].astype(np.int8),
            "slot": np.where(slot >= 0, slot, len(self.slots)).astype(np.int64),
            "mounting": self.count[rows].astype(np.float64),
            "joints": self.backend.encoders(rows, self.rho[rows], None if self.world is None
                                            else self.actual[rows]),
            "tracker": np.where(tracked[:, None], self.tracker_reading[rows], 0.0),
            "tracker_valid": tracked.astype(np.int8)[:, None],
            "time": self.time[rows][:, None].copy(),
            **(self._laser_observation(rows, fresh) if self.settings.version >= 1 else {}),
            **(self._bar_observation(rows, fresh) if self.settings.version >= 2 else {}),
            **(self._gauge_observation(rows, fresh) if self.settings.version >= 3 else {}),
        }

    def _gauge_observation(self, rows: np.ndarray, fresh: np.ndarray) -> dict[str, np.ndarray]:
        """``OrthoglideLab-v3``'s step-gauge keys of ``rows``' observations."""
        read = fresh & np.isfinite(self.gauge_reading[rows])
        return {"step_gauge": np.where(read, self.gauge_reading[rows], 0.0)[:, None],
                "step_gauge_valid": read.astype(np.int8)[:, None],
                "step_gauge_in": self.gauge_in[rows].astype(np.int8)[:, None]}

    def _bar_observation(self, rows: np.ndarray, fresh: np.ndarray) -> dict[str, np.ndarray]:
        """``OrthoglideLab-v2``'s ballbar keys of ``rows``' observations."""
        read = fresh & np.isfinite(self.bar_reading[rows])
        return {"ballbar": np.where(read, self.bar_reading[rows], 0.0)[:, None],
                "ballbar_valid": read.astype(np.int8)[:, None],
                "ballbar_in": self.bar_in[rows].astype(np.int8)[:, None]}

    def _laser_observation(self, rows: np.ndarray, fresh: np.ndarray
                           ) -> dict[str, np.ndarray]:
        """``OrthoglideLab-v1``'s interferometer keys of ``rows``' observations."""
        read = fresh & np.isfinite(self.laser_reading[rows])
        axis = self.laser_axis[rows]
        return {"interferometer": np.where(read, self.laser_reading[rows], 0.0)[:, None],
                "interferometer_valid": read.astype(np.int8)[:, None],
                "interferometer_axis": np.where(axis >= 0, axis, 3).astype(np.int64)}

    def true_gauges(self, row: int) -> list[Gauge]:
        """Every installation of episode ``row``, in mounting order (scoring only)."""
        return list(self.notebooks[row].installed.values())


def _unmounted(shape: tuple[int, int], travel: float, spec: GaugeSpec) -> GaugeArray:
    """Gauges of stands that are not mounted: no ray (NaN), so nothing reads or presses
    (named after ``spec``, any slot)."""
    return GaugeArray(origin=np.full((*shape, 3), np.nan), direction=np.full((*shape, 3), np.nan),
                      sign=np.ones(shape), travel=travel, zero=travel / 2,
                      leg=spec.leg, axis=spec.axis, at=spec.at)


def _with_rows(machines: MachineParams, rows: np.ndarray, new: MachineParams) -> MachineParams:
    vector = machines.to_vector()
    vector[rows] = new.to_vector()
    return MachineParams.from_vector(vector, machines.design)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (a normalised normal quaternion)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
