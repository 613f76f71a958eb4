"""``gauss-newton``: the paper's measurements, fitted with the exact gauge model.

The paper linearises the gauge differences around the nominal machine; with errors of a
few millimetres that leaves a bias of tenths of a millimetre.  This strategy iterates
Gauss-Newton on the exact model (the same ray-on-bar geometry the machine has, evaluated
at the current estimate with ideally installed gauges) to convergence (steps ~1e-7 mm),
weighting the differences by the inverse of their exact covariance (they share Zero
readings), so the estimate is efficient and its covariance is the Cramér-Rao bound.
Levenberg-Marquardt damping keeps it converging on machines the six-parameter model does
not describe exactly.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import least_squares

from .base import register
from .differences import Differences, model_differences
from .paper import PaperCalibrator

#: Convergence: the model's round-off makes steps wander at ~1e-9 mm once converged (the
#: weak drho ~ dL directions amplify it ~60x), so steps are resolved to ~1e-7 mm (scipy's
#: xtol is relative to the parameters, a few mm), five orders below a gauge's resolution.
STEP_TOL: float = 1e-7  # mm
MAX_ITERATIONS: int = 50
#: Forward differences: truncation ~FD_STEP / L ~ 3e-7 of each derivative, which only
#: touches the convergence rate and the covariance at that relative level, never the
#: fixed point (the residual is always evaluated exactly).
FD_STEP: float = 1e-4  # mm


@register
class GaussNewtonCalibrator(PaperCalibrator):
    """Same experiment as ``paper``; exact model, iterated to convergence."""

    name = "gauss-newton"

    def jacobian(self, rows: Differences, theta: np.ndarray, free: tuple[int, ...],
                 at: np.ndarray | None = None) -> np.ndarray:
        """Forward-difference Jacobian over the free parameters (``at``: the model's value
        at ``theta`` when already known)."""
        base = model_differences(theta, rows) if at is None else at
        cols = []
        for k in free:
            step = np.zeros(6)
            step[k] = FD_STEP
            cols.append((model_differences(theta + step, rows) - base) / FD_STEP)
        return np.column_stack(cols)

    def predict(self, rows: Differences, theta: np.ndarray) -> np.ndarray:
        return model_differences(theta, rows)

    def solve(self, rows: Differences, free: tuple[int, ...], sigma: float
              ) -> tuple[np.ndarray, np.ndarray, int]:
        """Weighted least squares on the exact model.  Gauss-Newton steps, safeguarded by
        Levenberg-Marquardt damping (MINPACK through scipy): with model error the residual
        curvature along the weak drho ~ dL directions rivals J^T W J, where undamped steps
        can crawl or oscillate.  The residuals are whitened by the covariance's Cholesky
        factor, so the fixed point is the weighted least-squares one."""
        theta, _, _ = super().solve(rows, free, sigma)  # the linear solution starts it
        chol = np.linalg.cholesky(rows.cov_unit)
        idx = list(free)

        def full(x: np.ndarray) -> np.ndarray:
            out = theta.copy()
            out[idx] = x
            return out

        def residual(x: np.ndarray) -> np.ndarray:
            return solve_triangular(chol, self.predict(rows, full(x)) - rows.values, lower=True)

        def jacobian(x: np.ndarray) -> np.ndarray:
            return solve_triangular(chol, self.jacobian(rows, full(x), free), lower=True)

        result = least_squares(residual, theta[idx], jac=jacobian, method="lm",
                               xtol=STEP_TOL / 10, ftol=1e-15, gtol=1e-15,
                               max_nfev=MAX_ITERATIONS * (len(idx) + 1))
        if result.status <= 0:
            raise RuntimeError(f"Gauss-Newton did not converge: {result.message}")
        white = jacobian(result.x)
        return full(result.x), sigma**2 * np.linalg.inv(white.T @ white), int(result.njev)
