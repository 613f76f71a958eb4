"""``gauss-newton``: the paper's measurements, fitted with the exact gauge model.

The paper linearises the gauge differences around the nominal machine; with errors of a
few millimetres that leaves a bias of tenths of a millimetre.  This strategy iterates
Gauss-Newton on the exact model (the same ray-on-bar geometry the machine has, evaluated
at the current estimate with ideally installed gauges) until the step is below 1e-7 mm,
weighting the differences by the inverse of their exact covariance (they share Zero
readings), so the estimate is efficient and its covariance is the Cramér-Rao bound.
"""

from __future__ import annotations

import numpy as np

from .base import register
from .differences import Differences, model_differences
from .paper import PaperCalibrator

#: Convergence: the model's round-off makes steps wander at ~1e-9 mm once converged (the
#: weak drho ~ dL directions amplify it ~60x), so stop at 1e-7 mm, five orders of
#: magnitude below a gauge's resolution.
STEP_TOL: float = 1e-7  # mm
MAX_ITERATIONS: int = 50
FD_STEP: float = 1e-4  # mm; central differences, truncation ~FD_STEP^2 / L ~ 1e-11


@register
class GaussNewtonCalibrator(PaperCalibrator):
    """Same experiment as ``paper``; exact model, iterated to convergence."""

    name = "gauss-newton"

    def jacobian(self, rows: Differences, theta: np.ndarray, free: tuple[int, ...]) -> np.ndarray:
        cols = []
        for k in free:
            step = np.zeros(6)
            step[k] = FD_STEP
            cols.append((model_differences(theta + step, rows)
                         - model_differences(theta - step, rows)) / (2 * FD_STEP))
        return np.column_stack(cols)

    def predict(self, rows: Differences, theta: np.ndarray) -> np.ndarray:
        return model_differences(theta, rows)

    def solve(self, rows: Differences, free: tuple[int, ...], sigma: float
              ) -> tuple[np.ndarray, np.ndarray, int]:
        theta, _, _ = super().solve(rows, free, sigma)  # the linear solution starts it
        weight = np.linalg.inv(rows.cov_unit)
        idx = list(free)
        for iteration in range(1, MAX_ITERATIONS + 1):
            jac = self.jacobian(rows, theta, free)
            normal = jac.T @ weight @ jac
            residual = rows.values - self.predict(rows, theta)
            step = np.linalg.solve(normal, jac.T @ weight @ residual)
            theta[idx] += step
            if np.max(np.abs(step)) < STEP_TOL:
                # The Jacobian of a step this small is the Jacobian at the solution.
                return theta, sigma**2 * np.linalg.inv(normal), iteration
        raise RuntimeError(f"Gauss-Newton did not converge in {MAX_ITERATIONS} iterations")
