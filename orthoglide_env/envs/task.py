"""The calibration task: what the lab sees of a machine, and what each move costs.

Kept apart from the environment class (as panda-gym keeps task and robot apart): the
task turns the machine's raw gauge geometry into readings (noise, resolution, validity),
keeps the book of gauge overtravels and crashes, and prices every move in seconds of a
real experiment.  Every function works on one machine or on a batch of machines (arrays
with the batch dimensions first), so the single env and the vector env share it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.envs.backend import MachineBackend
from orthoglide_env.instruments.gauges import (
    GaugeArray,
    GaugeNoise,
    Status,
    pressed_past_travel,
    readings_from_distances,
    status_of,
)
from orthoglide_env.lab.operations import TIME

# The lab's time table (orthoglide_env/lab.py) prices every move.
DRIVE_SPEED: float = TIME.drive_speed_mm_s
SETTLE_AND_READ: float = TIME.settle_and_read_s
OVERTRAVEL_PENALTY: float = TIME.overtravel_s


@dataclass(frozen=True)
class Reading:
    """What the lab sees after one move (of each machine of a batch: every field then has
    the batch dimensions first)."""

    gauges: np.ndarray  # mm, 0.0 where not valid
    valid: np.ndarray  # int8, 1 where the gauge touches its bar within travel
    joints: np.ndarray  # encoder readings, mm
    status: np.ndarray  # Status codes, one per gauge


class CalibrationTask:
    """Readings with noise, move costs and the overtravel/collision book."""

    def __init__(self, noise: GaugeNoise) -> None:
        self.noise = noise

    def read(self, machine: MachineBackend, rng: np.random.Generator) -> Reading:
        """Read every gauge and encoder of ``machine`` (noise drawn from ``rng``)."""
        t = machine.gauge_distances()
        return self.reading(machine.gauge_array, t, machine.encoders(),
                            self.noise.draws(rng, np.shape(t)))

    def reading(self, gauges: GaugeArray, t: np.ndarray, joints: np.ndarray,
                draws: np.ndarray) -> Reading:
        """The reading of ``gauges`` at ray distances ``t`` and encoders ``joints``, with the
        standard normal noise ``draws`` (:meth:`GaugeNoise.draws`, one per gauge)."""
        status = status_of(gauges, t)
        values = self.noise.applied(readings_from_distances(gauges, t), draws)
        valid = status == Status.VALID
        return Reading(
            gauges=np.where(valid, values, 0.0),
            valid=valid.astype(np.int8),
            joints=joints,
            status=status,
        )

    @staticmethod
    def move_time(start: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Seconds a real machine spends driving from ``start`` to ``target`` and reading
        (shapes ``(..., 3)``; one time per machine)."""
        return TIME.move(start, target)

    @staticmethod
    def step_time(start: np.ndarray, target: np.ndarray, overtravels: np.ndarray
                  ) -> np.ndarray:
        """Seconds a step costs: the move, plus :data:`OVERTRAVEL_PENALTY` for every gauge
        of ``overtravels`` (the :meth:`new_overtravels` mask, ``(..., G)``)."""
        return CalibrationTask.move_time(start, target) + OVERTRAVEL_PENALTY * np.count_nonzero(
            overtravels, axis=-1)

    @staticmethod
    def pressed(machine: MachineBackend) -> np.ndarray:
        """Which gauges a bar presses past their travel toward the stand (overtravel),
        whether or not the tip is on the face that gives a reading."""
        return pressed_past_travel(machine.gauge_array, *machine.target_boxes())

    @staticmethod
    def new_overtravels(before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """Which gauges went into overtravel on this move (``before``/``after``: the
        :meth:`pressed` masks); staying in overtravel is not a new one."""
        return after & ~before
