"""What the environment needs from a virtual machine, and the exact-model machine.

Two machines implement :class:`MachineBackend`: :class:`ExactMachine` (this module: the
closed-form/Newton solution of the geometry, instant) and the PyBullet closed-chain
machine of :mod:`orthoglide_env.machine` (the faithful one).  The environment and the
fidelity tests treat them alike.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .collisions import collisions
from .gauges import Gauge, collision_boxes, exact_ray_distances, exact_target_boxes
from .geometry import MachineParams
from .kinematics import direct

MOTION_MODES: tuple[str, ...] = ("quasi-static", "dynamic")


def check_motion_mode(mode: str) -> None:
    if mode not in MOTION_MODES:
        raise ValueError(f"unknown motion mode '{mode}'; choose from {list(MOTION_MODES)}")


class MachineBackend(Protocol):
    """A virtual Orthoglide with gauges installed on its base (ground truth inside)."""

    machine: MachineParams
    gauges: list[Gauge]

    def move(self, rho: np.ndarray, mode: str = "quasi-static") -> None:
        """Drive the three actuators to control coordinates ``rho`` (mm, already
        validated against the control limits) and let the mechanism settle."""

    def encoders(self) -> np.ndarray:
        """Encoder readings (mm, control coordinates), shape (3,)."""

    def tcp(self) -> np.ndarray:
        """True TCP position (mm), shape (3,)."""

    def gauge_distances(self) -> np.ndarray:
        """Ray distance ``t`` (mm) of every gauge's tip to its target; NaN when the ray
        does not hit the target bar first."""

    def collisions(self) -> list[str]:
        """Names of the pairs of moving parts in contact (empty when none)."""

    def target_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Box of every gauge's target bar: centres (mm), rotations, half extents (mm)."""

    def set_gauges(self, gauges: list[Gauge]) -> None:
        """Replace the installed gauges (same layout, e.g. after zeroing)."""

    def close(self) -> None:
        """Release every resource."""


class ExactMachine:
    """The machine as the exact kinematic model computes it (no dynamics, no solver)."""

    def __init__(self, machine: MachineParams, gauges: list[Gauge]) -> None:
        self.machine = machine
        self.gauges = list(gauges)
        self.move(np.zeros(3))

    def move(self, rho: np.ndarray, mode: str = "quasi-static") -> None:
        check_motion_mode(mode)
        rho = np.array(rho, dtype=float)
        # Solved before anything is stored: a posture the machine cannot be assembled in
        # raises and leaves the machine where it was.  The geometry of a posture is computed
        # once; every reading below uses it.
        tcp = direct(self.machine, rho)
        self._boxes = collision_boxes(self.machine, rho, tcp)
        self._rho, self._tcp = rho, tcp

    def encoders(self) -> np.ndarray:
        return self._rho.copy()

    def tcp(self) -> np.ndarray:
        return self._tcp.copy()

    def gauge_distances(self) -> np.ndarray:
        return exact_ray_distances(self.machine, self.gauges, self._rho, self._boxes)

    def collisions(self) -> list[str]:
        # Within the joint limits the nearest crash pair stays millimetres apart on the
        # nominal and realistic machines (tests/test_collisions.py); the check is for
        # machines far from nominal, given through reset options.
        return collisions(self.machine, self._rho, self._boxes)

    def target_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return exact_target_boxes(self.gauges, self._boxes)

    def set_gauges(self, gauges: list[Gauge]) -> None:
        self.gauges = list(gauges)

    def close(self) -> None:
        """Nothing to release."""
