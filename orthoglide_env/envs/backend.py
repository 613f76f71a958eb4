"""What the environment needs from a virtual machine, and the exact-model machine.

Two machines implement :class:`MachineBackend`: :class:`ExactMachine` (this module: the
closed-form/Newton solution of the geometry, instant) and the PyBullet closed-chain
machine of :mod:`orthoglide_env.sim.pybullet` (the faithful one).  The environment and the
fidelity tests treat them alike.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from orthoglide_env.instruments.gauges import (
    Gauge,
    GaugeArray,
    as_gauge_array,
    collision_boxes,
    exact_ray_distances,
    exact_target_boxes,
)
from orthoglide_env.model.collisions import collision_mask, collision_names
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import direct

MOTION_MODES: tuple[str, ...] = ("quasi-static", "dynamic")


def check_motion_mode(mode: str) -> None:
    if mode not in MOTION_MODES:
        raise ValueError(f"unknown motion mode '{mode}'; choose from {list(MOTION_MODES)}")


class MachineBackend(Protocol):
    """A virtual Orthoglide with gauges installed on its base (ground truth inside)."""

    machine: MachineParams

    @property
    def gauges(self) -> list[Gauge]:
        """The installed gauges."""

    @property
    def gauge_array(self) -> GaugeArray:
        """The installed gauges as arrays (what the reading model computes with)."""

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

    def collision_mask(self) -> np.ndarray:
        """Which pairs of :data:`~orthoglide_env.model.collisions.PAIR_NAMES` are in contact."""

    def target_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Box of every gauge's target bar: centres (mm), rotations, half extents (mm)."""

    def set_gauges(self, gauges: list[Gauge]) -> None:
        """Replace the installed gauges (same layout, e.g. after zeroing)."""

    def close(self) -> None:
        """Release every resource."""


class ExactMachine:
    """The machine as the exact kinematic model computes it (no dynamics, no solver).

    A batch of machines is one ``ExactMachine`` too: ``machine`` with a batch shape
    (:attr:`MachineParams.batch_shape`) and ``gauges`` a :class:`GaugeArray` of that batch
    shape; then ``rho`` and every reading carry the batch dimensions first.  One machine
    is the batch of shape ``()``, computed by the same code.
    """

    def __init__(self, machine: MachineParams, gauges: list[Gauge] | GaugeArray,
                 rho: np.ndarray | None = None, tcp: np.ndarray | None = None) -> None:
        """``rho``: the posture to start at (default Zero), as :meth:`move` takes it;
        ``tcp``: the TCP there, when already solved."""
        self.machine = machine
        self.gauge_array = as_gauge_array(gauges)
        self.move(np.zeros(3) if rho is None else rho, tcp=tcp)

    @property
    def gauges(self) -> list[Gauge]:
        return self.gauge_array.to_gauges()

    def move(self, rho: np.ndarray, mode: str = "quasi-static", tcp: np.ndarray | None = None
             ) -> None:
        """Go to control coordinates ``rho``, shape ``(*batch, 3)`` (or ``(3,)``: the same
        posture on every machine); ``tcp``: the TCP there, when already solved."""
        check_motion_mode(mode)
        rho = np.array(np.broadcast_to(rho, (*self.machine.batch_shape, 3)), dtype=float)
        # Solved before anything is stored: a posture the machine cannot be assembled in
        # raises and leaves the machine where it was.  The geometry of a posture is computed
        # once; every reading below uses it.
        tcp = direct(self.machine, rho) if tcp is None else np.asarray(tcp, dtype=float)
        self._boxes = collision_boxes(self.machine, rho, tcp)
        self._rho, self._tcp = rho, tcp

    def encoders(self) -> np.ndarray:
        return self._rho.copy()

    def tcp(self) -> np.ndarray:
        return self._tcp.copy()

    def gauge_distances(self) -> np.ndarray:
        return exact_ray_distances(self.machine, self.gauge_array, self._rho, self._boxes)

    def collision_mask(self) -> np.ndarray:
        # Within the joint limits the nearest crash pair stays millimetres apart on the
        # nominal and realistic machines (tests/test_collisions.py); the check is for
        # machines far from nominal, given through reset options.
        return collision_mask(self.machine, self._rho, self._boxes)

    def collisions(self) -> list[str]:
        return collision_names(self.collision_mask())

    def target_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return exact_target_boxes(self.gauge_array, self._boxes)

    def set_gauges(self, gauges: list[Gauge] | GaugeArray) -> None:
        self.gauge_array = as_gauge_array(gauges)

    def close(self) -> None:
        """Nothing to release."""
