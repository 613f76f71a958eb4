"""Identifiability of a design: Fisher information, Cramér-Rao bounds, weak directions.

For differences ``y = f(theta) + e`` with ``cov(e) = sigma^2 C`` the Fisher information
is ``F = J^T C^-1 J / sigma^2`` and no unbiased estimator has a smaller covariance than
``F^-1``.  The singular values of the whitened Jacobian ``L^-1 J`` (``C = L L^T``) tell
how well each direction of parameter space shows in the data.  The singular values and
weak directions reported are those of the identification Jacobian itself (as for eq. 10,
whose singular values are 1.01, 0.68, 0.68, 0.0166, 0.0164, 0.0164): the right singular
vectors with small singular values are the combinations the design barely sees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibrators.estimators.base import PARAM_NAMES, check_params
from calibrators.estimators.differences import differences, model_jacobian
from calibrators.measurements import Measurements
from orthoglide_env.instruments.dial import DEFAULT_SIGMA

#: A direction is reported as weak when its singular value is below this fraction of the
#: largest (the paper's design: 0.0164 / 1.01 ~ 0.016 for the drho ~ dL directions).
WEAK_RATIO: float = 0.1


@dataclass(frozen=True)
class Identifiability:
    fisher: np.ndarray  # for readings of unit variance; divide by sigma^2
    crlb: np.ndarray  # standard deviation bound of each parameter (mm) at the given sigma
    singular_values: np.ndarray
    weak_directions: list[dict[str, float]]

    @property
    def condition_number(self) -> float:
        return float(self.singular_values[0] / self.singular_values[-1])


def analyse(jac: np.ndarray, cov_unit: np.ndarray, sigma: float,
            names: tuple[str, ...] | None = None) -> Identifiability:
    """Identifiability of parameters with Jacobian ``jac`` (rows: data, columns: params)
    for data with covariance ``sigma^2 * cov_unit``."""
    names = names or PARAM_NAMES[: jac.shape[1]]
    if not np.all(np.isfinite(jac)):
        raise ValueError("the design reads gauges where they miss their bar (no information)")
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    if len(sv) < jac.shape[1] or sv[-1] <= sv[0] * 1e-12:
        raise ValueError("the design does not identify every parameter (rank deficient)")
    white = np.linalg.solve(np.linalg.cholesky(cov_unit), jac)
    fisher = white.T @ white
    crlb = sigma * np.sqrt(np.diag(np.linalg.inv(fisher)))
    weak = [
        {name: float(round(v, 4)) for name, v in zip(names, row, strict=True) if abs(v) > 0.05}
        for s, row in zip(sv, vt, strict=True) if s < WEAK_RATIO * sv[0]
    ]
    return Identifiability(fisher, crlb, sv, weak)


def of_design(data: Measurements, params: str = "paper6", sigma: float = DEFAULT_SIGMA,
              theta: np.ndarray | None = None) -> Identifiability:
    """Identifiability of any strategy's readings (its design): the exact gauge model's
    Jacobian of the averaged differences at the machine ``theta`` (drho, dL; default
    nominal, the only one known before calibrating), with the covariance the averaging
    gives them.  Only where the readings are taken and how often matters, not their
    values."""
    free = check_params(params)
    rows = differences(data)
    if len(rows) < len(free):
        raise ValueError(f"only {len(rows)} differences for {len(free)} parameters")
    theta = np.zeros(6) if theta is None else np.asarray(theta, dtype=float)
    names = tuple(PARAM_NAMES[k] for k in free)
    return analyse(model_jacobian(theta, rows, free), rows.cov_unit, sigma, names)
