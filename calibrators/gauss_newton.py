"""``gauss-newton``: the paper's measurements, fitted with the exact gauge model.

The paper linearises the gauge differences around the nominal machine; with errors of a
few millimetres that leaves a bias of tenths of a millimetre.  This strategy iterates
Gauss-Newton on the exact model (the same ray-on-bar geometry the machine has, evaluated
at the current estimate with ideally installed gauges) to convergence (steps below
1e-7 mm), weighting the differences by the inverse of their exact covariance (they share
Zero readings), so the estimate is efficient and its covariance is the Cramér-Rao bound.
A step that does not lower the cost is retried with Levenberg-Marquardt damping, which
keeps it converging on machines the six-parameter model does not describe exactly.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from .base import register
from .differences import Differences, model_differences, model_jacobian
from .paper import PaperCalibrator

#: Convergence: the model's round-off makes steps wander at ~1e-9 mm once converged (the
#: weak drho ~ dL directions amplify it ~60x), so steps are resolved to 1e-7 mm, five
#: orders below a gauge's resolution.
STEP_TOL: float = 1e-7  # mm
MAX_ITERATIONS: int = 50
#: Damping of a rejected step grows tenfold per retry, from this fraction of diag(J^T J).
DAMPING_START: float = 1e-4


@register
class GaussNewtonCalibrator(PaperCalibrator):
    """Same experiment as ``paper``; exact model, iterated to convergence."""

    name = "gauss-newton"

    def jacobian(self, rows: Differences, theta: np.ndarray, free: tuple[int, ...],
                 at: np.ndarray | None = None) -> np.ndarray:
        """The exact model's Jacobian over the free parameters (``at``: the model's value
        at ``theta`` when already known)."""
        return model_jacobian(theta, rows, free, at)

    def predict(self, rows: Differences, theta: np.ndarray) -> np.ndarray:
        return model_differences(theta, rows)

    def solve(self, rows: Differences, free: tuple[int, ...], sigma: float
              ) -> tuple[np.ndarray, np.ndarray, int]:
        """Weighted least squares on the exact model, started from the linear solution.

        The residuals are whitened by the covariance's Cholesky factor, so the fixed point
        is the weighted least-squares one.  Plain Gauss-Newton steps converge
        quadratically on a machine the model describes (a few iterations from the linear
        start); with model error the residual's curvature along the weak drho ~ dL
        directions rivals J^T W J, and a step that raises the cost is damped instead."""
        theta, _, _ = super().solve(rows, free, sigma)
        chol = np.linalg.cholesky(rows.cov_unit)
        idx = list(free)

        def whiten(values: np.ndarray) -> np.ndarray:
            return solve_triangular(chol, values, lower=True)

        model = self.predict(rows, theta)
        residual = whiten(model - rows.values)
        damping = 0.0
        for iteration in range(1, MAX_ITERATIONS + 1):
            jac = whiten(self.jacobian(rows, theta, free, at=model))
            normal = jac.T @ jac
            gradient = jac.T @ residual
            while True:
                lhs = normal + damping * np.diag(np.diag(normal))
                step = np.zeros(6)
                step[idx] = -np.linalg.solve(lhs, gradient)
                trial_model = self.predict(rows, theta + step)
                trial = whiten(trial_model - rows.values)
                converged = np.max(np.abs(step)) < STEP_TOL
                if trial @ trial <= residual @ residual or converged:
                    break
                damping = DAMPING_START if damping == 0.0 else 10 * damping
                if damping > 1e12:
                    raise RuntimeError("Gauss-Newton stalled: no step lowers the cost")
            theta, model, residual = theta + step, trial_model, trial
            damping = damping / 10 if damping > DAMPING_START else 0.0
            if converged:
                # The Jacobian of the last iteration is within STEP_TOL of the solution:
                # its covariance differs from the one at the solution by ~1e-9 relative.
                return theta, sigma**2 * np.linalg.inv(normal), iteration
        raise RuntimeError(f"Gauss-Newton did not converge in {MAX_ITERATIONS} iterations")
