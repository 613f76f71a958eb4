"""One PyBullet client, configured for a stiff closed-chain mechanism.

Every PyBullet call of the project goes through :class:`Simulator`, which owns exactly
one client (so several machines, vector envs and tests coexist in one process) and
releases it on :meth:`close`.  Metres and kilograms live here and below only.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass

from orthoglide_env.sim.display import require_display


@contextlib.contextmanager
def _c_output_silenced() -> Iterator[None]:
    """Silence what PyBullet's C code prints on import and connect (a build banner on
    stderr, ``argv[0]=`` on stdout): it would corrupt ``--json`` output and one-line
    error messages.  Python-level streams are flushed first so nothing of ours is lost."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


with _c_output_silenced():
    import pybullet as pb
    from pybullet_utils.bullet_client import BulletClient

__all__ = ["PhysicsSettings", "Simulator", "pb"]


@dataclass(frozen=True)
class PhysicsSettings:
    """Solver settings measured to close the Orthoglide's loops to below 0.1 µm.

    The default residual threshold (1e-7) stops the sequential-impulse solver early
    whatever the iteration count, hence the tiny threshold; the MLCP solvers diverge on
    this over-constrained mechanism, so the default solver stays.
    """

    time_step: float = 1e-3
    solver_iterations: int = 150
    residual_threshold: float = 1e-30
    erp: float = 1.0
    gravity: float = -9.81


class Simulator:
    """A PyBullet client in DIRECT mode (or GUI on request).

    ``gui=True`` without a display raises ``ValueError`` before PyBullet is asked: its GUI
    connection would end the process.
    """

    def __init__(self, *, gui: bool = False, settings: PhysicsSettings | None = None) -> None:
        if gui:
            require_display("gui=True", "gui=False")
        self.settings = settings or PhysicsSettings()
        self.gui = gui
        #: How many times the world was cleared: a machine built in it knows whether it
        #: is still there.
        self.generation = 0
        with _c_output_silenced():
            self.client = BulletClient(connection_mode=pb.GUI if gui else pb.DIRECT)
        self._configure()

    def _configure(self) -> None:
        s = self.settings
        self.client.setPhysicsEngineParameter(
            fixedTimeStep=s.time_step, numSolverIterations=s.solver_iterations,
            solverResidualThreshold=s.residual_threshold, erp=s.erp, contactERP=s.erp,
            frictionERP=s.erp)
        self.client.setGravity(0.0, 0.0, s.gravity)
        if self.gui:
            self.client.configureDebugVisualizer(pb.COV_ENABLE_GUI, 0)

    def clear(self) -> None:
        """Remove every body, constraint and shape, and set the solver up again, so that
        the client hosts a new machine: cheaper than a new connection, and one client per
        worker serves any number of machines in turn."""
        self.client.resetSimulation()
        # resetSimulation also resets gravity and solver parameters to PyBullet's defaults.
        self._configure()
        self.generation += 1

    @property
    def connected(self) -> bool:
        return self.client._client >= 0

    def load_urdf_text(self, text: str) -> int:
        """Load a URDF given as a string; returns the body id (fixed base)."""
        fd, path = tempfile.mkstemp(suffix=".urdf")
        try:
            with os.fdopen(fd, "w") as handle:
                handle.write(text)
            return self.client.loadURDF(path, useFixedBase=True,
                                        flags=pb.URDF_USE_IMPLICIT_CYLINDER)
        finally:
            os.unlink(path)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.client.stepSimulation()

    def close(self) -> None:
        """Disconnect; safe to call twice."""
        if self.connected:
            self.client.disconnect()
            self.client._client = -1
