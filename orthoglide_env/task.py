"""The calibration task: what the lab sees of a machine, and what each move costs.

Kept apart from the environment class (as panda-gym keeps task and robot apart): the
task turns the machine's raw gauge geometry into readings (noise, resolution, validity),
keeps the book of gauge overtravels and crashes, and prices every move in seconds of a
real experiment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .backend import MachineBackend
from .gauges import (
    Gauge,
    GaugeNoise,
    Status,
    pressed_past_travel,
    readings_from_distances,
    status_of,
)
from .lab import TIME

# The lab's time table (orthoglide_env/lab.py) prices every move.
DRIVE_SPEED: float = TIME.drive_speed_mm_s
SETTLE_AND_READ: float = TIME.settle_and_read_s
OVERTRAVEL_PENALTY: float = TIME.overtravel_s


@dataclass(frozen=True)
class Reading:
    """What the lab sees after one move."""

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
        status = status_of(machine.gauges, t)
        values = self.noise.apply(readings_from_distances(machine.gauges, t), rng)
        valid = status == Status.VALID
        return Reading(
            gauges=np.where(valid, values, 0.0),
            valid=valid.astype(np.int8),
            joints=machine.encoders(),
            status=status,
        )

    @staticmethod
    def move_time(start: np.ndarray, target: np.ndarray) -> float:
        """Seconds a real machine spends driving from ``start`` to ``target`` and reading."""
        return TIME.move(start, target)

    @staticmethod
    def pressed(machine: MachineBackend) -> np.ndarray:
        """Which gauges a bar presses past their travel toward the stand (overtravel),
        whether or not the tip is on the face that gives a reading."""
        return pressed_past_travel(machine.gauges, *machine.target_boxes())

    @staticmethod
    def new_overtravels(gauges: list[Gauge], before: np.ndarray, after: np.ndarray) -> list[str]:
        """Names of gauges that went into overtravel on this move (``before``/``after``:
        the :meth:`pressed` masks); staying in overtravel is not a new one."""
        return [g.spec.name for g, b, a in zip(gauges, before, after, strict=True) if a and not b]
