"""The exact-model estimator: any parameter set, priors or base parameters, honest errors.

One damped Gauss-Newton (Levenberg) solver, batched over machines: every machine of a
sweep that ran the same design is fitted in the same numpy calls, each with its own
damping, convergence and failure flag; one machine is a batch of one.

What it minimises, per machine, in units where every free parameter is divided by its
scale (:func:`calibrators.parameters.scales`) and every reading by the gauge sigma::

    sum over readings (y - f(theta) - zero[mounting])^2 / sigma^2  +  sum over priors phi^2

The zero of each mounting (a gauge's dial is set where it was set) is eliminated exactly
by centring residuals and Jacobian within each mounting.  A free parameter without a prior
is a *base-parameter* fit: the normal matrix is eigen-decomposed and the combinations
whose information is below :data:`RETAIN` (the data pin them down worse than their
a-priori scale) are not moved from nominal; they are reported by name and their a-priori
scale goes into the covariance, so that predicted errors include what the data cannot
see.  A prior makes every combination identifiable in the Bayesian sense (its information
is at least 1), so the same code is a MAP fit.

Honest uncertainty: the cost at the solution is a chi-square with
``readings - mountings - (retained directions without prior)`` degrees of freedom when the
model explains the readings.  Beyond the :data:`CHI2_LEVEL` quantile the fit says so and
scales its covariance by chi2/dof.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .exact_model import Design, jacobian, predict

#: A combination is identifiable (and moved by a base-parameter fit) when its information
#: in scaled units is at least this: the data determine it at least as well as its
#: a-priori scale does.
RETAIN: float = 1.0
#: A noise-free fit is weighted as if its gauges had this repeatability (mm): weights and
#: the identifiability threshold need a finite sigma.
NOISE_FLOOR: float = 1e-6
#: Convergence on the step, in units of each parameter's scale (2e-8 mm for drho).
STEP_TOL: float = 1e-8
#: ... or on the cost, when a step lowers it by less than this fraction.
COST_RTOL: float = 1e-12
MAX_ITERATIONS: int = 50
DAMPING_START: float = 1e-3
DAMPING_MAX: float = 1e10
#: Significance of the chi-square test of the model: above the (1 - CHI2_LEVEL) quantile
#: the readings are not explained by the model and the noise.
CHI2_LEVEL: float = 1e-3


@dataclass
class BatchFit:
    """The result of fitting M machines of one design."""

    theta: np.ndarray  # (M, n) every parameter, physical units (fixed ones at their value)
    free: np.ndarray  # (n,) bool
    scale: np.ndarray  # (n,)
    prior: np.ndarray  # (n,) prior sigma, inf where none
    covariance: np.ndarray  # (M, nf, nf) free parameters, physical units, unscaled
    information: np.ndarray  # (M, nf, nf) data information in scaled units
    residuals: np.ndarray  # (M, N) mm: reading - model - zero; NaN where not used
    chi2: np.ndarray  # (M,)
    dof: np.ndarray  # (M,)
    retained: np.ndarray  # (M,) directions moved by the fit
    converged: np.ndarray  # (M,) bool
    iterations: np.ndarray  # (M,)
    sigma: float  # the gauge sigma the fit was weighted with (mm)
    #: (M, n, n) covariance of (estimate - truth) over every parameter, physical units,
    #: with the errors the model leaves out (see :func:`_model_error`).
    error_covariance: np.ndarray

    @property
    def chi2_dof(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.dof > 0, self.chi2 / self.dof, np.nan)

    @property
    def misfit(self) -> np.ndarray:
        """(M,) bool: the chi-square test rejects the model at :data:`CHI2_LEVEL`."""
        return (self.dof > 0) & (stats.chi2.sf(self.chi2, np.maximum(self.dof, 1)) < CHI2_LEVEL)

    @property
    def covariance_scale(self) -> np.ndarray:
        """(M,) chi2/dof where the model is rejected, else 1."""
        return np.where(self.misfit, self.chi2_dof, 1.0)

    @property
    def scaled_covariance(self) -> np.ndarray:
        """The covariance to report over the free parameters: where the model is rejected,
        the one with the unmodelled errors (:func:`_model_error`) when the fit left
        parameters out, else the covariance inflated by chi2/dof."""
        idx = np.flatnonzero(self.free)
        with_model = self.error_covariance[:, idx[:, None], idx]
        inflated = self.covariance * self.covariance_scale[:, None, None]
        modelled = np.any(self.error_covariance != 0, axis=(1, 2)) & (
            np.diagonal(self.error_covariance, axis1=1, axis2=2)[:, ~self.free].any(axis=1))
        return np.where(modelled[:, None, None], with_model, inflated)

    def identifiable(self, m: int) -> np.ndarray:
        """Directions (rows, over the free parameters in scaled units) that the data of
        machine ``m`` determine at least as well as their scale."""
        return identifiable_directions(self.information[m])

    def unidentifiable(self, m: int) -> np.ndarray:
        values, vectors = np.linalg.eigh(self.information[m])
        return vectors[:, values < RETAIN].T

    def z_scores(self, m: int, truth: np.ndarray) -> np.ndarray:
        """(estimate - truth) / std along machine ``m``'s identifiable directions."""
        idx = np.flatnonzero(self.free)
        return z_scores(self.theta[m, idx], np.asarray(truth)[idx], self.scaled_covariance[m],
                        self.information[m], self.scale[idx])


def identifiable_directions(information: np.ndarray) -> np.ndarray:
    """Eigenvectors (rows, most informative first) of a data information matrix in scaled
    units whose eigenvalue is at least :data:`RETAIN`: the combinations the data determine
    at least as well as their a-priori scale."""
    values, vectors = np.linalg.eigh(information)
    return vectors[:, values >= RETAIN].T[::-1]


def z_scores(estimate: np.ndarray, truth: np.ndarray, covariance: np.ndarray,
             information: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(estimate - truth) / reported std along the identifiable directions of
    ``information`` (free parameters: physical ``estimate``, ``truth``, ``covariance``;
    ``information`` in units of ``scale``).  For an honest estimator these are standard
    normal: their RMS over many machines is the check that its error bars can be trusted."""
    err = (estimate - truth) / scale
    cov = covariance / np.outer(scale, scale)
    dirs = identifiable_directions(information)
    return dirs @ err / np.sqrt(np.einsum("kf,fg,kg->k", dirs, cov, dirs))


def _centre(values: np.ndarray, mask: np.ndarray, onehot: np.ndarray) -> np.ndarray:
    """Subtract each mounting's mean over its used readings (axis 1 of ``values``, which
    may carry a trailing parameter axis); unused readings become 0."""
    weights = mask.astype(float)
    counts = np.maximum(weights @ onehot, 1.0)  # (M, K)
    if values.ndim == 2:
        mean = ((values * weights) @ onehot) / counts
        return (values - mean @ onehot.T) * weights
    mean = np.einsum("mnf,nk->mkf", values * weights[..., None], onehot) / counts[..., None]
    return (values - np.einsum("mkf,nk->mnf", mean, onehot)) * weights[..., None]


def fit_batch(design: Design, values: np.ndarray, mask: np.ndarray, sigma: float,
              free: np.ndarray, fixed: np.ndarray, prior: np.ndarray, scale: np.ndarray,
              max_iterations: int = MAX_ITERATIONS,
              unmodelled: np.ndarray | None = None) -> BatchFit:
    """Fit machines whose readings ``values`` (M, N) of ``design`` are used where ``mask``.

    ``free``, ``fixed``, ``prior``, ``scale``: per parameter of ``design.space`` (mask of the
    free ones, values of the others, prior sigmas or inf, scales).  The fit starts from
    nominal (the prior mean) for the free parameters.  ``unmodelled``: the parameters that
    are neither free nor known (the model leaves them out); their misfit goes into the
    reported covariance (:func:`_model_error`)."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    mask = np.atleast_2d(np.asarray(mask, dtype=bool)) & np.isfinite(values)
    values = np.where(mask, values, 0.0)
    m_count = len(values)
    idx = np.flatnonzero(free)
    s = scale[idx]
    with np.errstate(divide="ignore"):
        precision = np.where(np.isfinite(prior[idx]), (s / prior[idx]) ** 2, 0.0)
    weight = 1.0 / max(sigma, NOISE_FLOOR)
    onehot = np.eye(len(design.mountings))[design.mounting]
    theta = np.tile(np.asarray(fixed, dtype=float), (m_count, 1))
    theta[:, idx] = 0.0

    def cost_of(model: np.ndarray, th: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, ...]:
        r = _centre((model - values[rows]) * weight, mask[rows], onehot)
        phi = th[:, idx] / s
        return r, np.sum(r**2, axis=1) + np.sum(precision * phi**2, axis=1)

    def normal(th: np.ndarray, model: np.ndarray, rows: np.ndarray, r: np.ndarray):
        jac = _centre(jacobian(th, design, free, scale, at=model) * weight, mask[rows], onehot)
        info = np.einsum("mnf,mng->mfg", jac, jac)
        a = info + np.eye(len(idx)) * precision
        g = np.einsum("mnf,mn->mf", jac, r) + precision * th[:, idx] / s
        return info, a, g

    def step_of(a: np.ndarray, g: np.ndarray, damping: np.ndarray) -> np.ndarray:
        lam, vec = np.linalg.eigh(a)
        keep = lam >= RETAIN * (1 - 1e-9)
        inv = np.where(keep, 1.0 / (np.where(keep, lam, 1.0) + damping[:, None]), 0.0)
        return -np.einsum("mfk,mk,mgk,mg->mf", vec, inv, vec, g)

    done = np.zeros(m_count, dtype=bool)
    failed = np.zeros(m_count, dtype=bool)
    iterations = np.zeros(m_count, dtype=int)
    damping = np.zeros(m_count)
    for _ in range(max_iterations):
        rows = np.flatnonzero(~done & ~failed)
        if not len(rows):
            break
        th = theta[rows]
        model = predict(th, design)
        r, cost = cost_of(model, th, rows)
        _, a, g = normal(th, model, rows, r)
        iterations[rows] += 1
        pending = np.ones(len(rows), dtype=bool)
        while pending.any():
            sub = np.flatnonzero(pending)
            step = step_of(a[sub], g[sub], damping[rows[sub]])
            trial = th[sub].copy()
            trial[:, idx] += step * s
            _, trial_cost = cost_of(predict(trial, design), trial, rows[sub])
            small = np.max(np.abs(step), axis=1, initial=0.0) < STEP_TOL
            accept = trial_cost <= cost[sub]
            flat = accept & (cost[sub] - trial_cost <= COST_RTOL * cost[sub])
            ok = sub[accept]
            theta[rows[ok]] = trial[accept]
            done[rows[sub[(accept & (small | flat)) | small]]] = True
            damping[rows[ok]] = np.where(damping[rows[ok]] > DAMPING_START,
                                         damping[rows[ok]] / 10, 0.0)
            pending[ok] = False
            pending[sub[small]] = False
            grow = sub[~accept & ~small]
            damping[rows[grow]] = np.maximum(damping[rows[grow]] * 10, DAMPING_START)
            give_up = grow[damping[rows[grow]] > DAMPING_MAX]
            failed[rows[give_up]] = True
            pending[give_up] = False
    converged = done & ~failed

    # The covariance and information at the solution.
    rows = np.arange(m_count)
    model = predict(theta, design)
    r, cost = cost_of(model, theta, rows)
    jac = _centre(jacobian(theta, design, free, scale, at=model) * weight, mask, onehot)
    info = np.einsum("mnf,mng->mfg", jac, jac)
    lam, vec = np.linalg.eigh(info + np.eye(len(idx)) * precision)
    keep = lam >= RETAIN * (1 - 1e-9)
    # Directions the fit did not move keep their a-priori scale (1 in scaled units).
    inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 1.0)
    cov_scaled = np.einsum("mfk,mk,mgk->mfg", vec, inv, vec)
    mountings_used = (mask.astype(float) @ onehot > 0).sum(axis=1)
    free_without_prior = np.sum(precision == 0)
    retained = keep.sum(axis=1)
    dof = mask.sum(axis=1) - mountings_used - np.maximum(
        retained - (len(idx) - free_without_prior), 0)
    residuals = np.where(mask, -r / weight, np.nan)
    fit = BatchFit(
        theta=theta, free=np.asarray(free, dtype=bool), scale=np.asarray(scale, dtype=float),
        prior=np.asarray(prior, dtype=float), covariance=cov_scaled * np.outer(s, s),
        information=info, residuals=residuals, chi2=cost, dof=dof, retained=retained,
        converged=converged, iterations=iterations, sigma=sigma,
        error_covariance=np.zeros((m_count, len(free), len(free))),
    )
    unmodelled = np.zeros(len(free), dtype=bool) if unmodelled is None else unmodelled
    gain = np.einsum("mfk,mk,mgk,mng->mfn", vec, np.where(keep, inv, 0.0), vec, jac)
    _model_error(fit, design, mask, onehot, weight, jac, gain, unmodelled)
    return fit


def _model_error(fit: BatchFit, design: Design, mask: np.ndarray, onehot: np.ndarray,
                 weight: float, jac: np.ndarray, gain: np.ndarray,
                 unmodelled: np.ndarray) -> None:
    """Fill ``fit.error_covariance``: the covariance of (estimate - truth) over every
    parameter, including the ``unmodelled`` ones the fit kept at nominal.

    A model that leaves parameters out is wrong by ``J_u theta_u``.  Taking the left-out
    errors as zero-mean with covariance ``kappa * scale^2`` (their structure from the exact
    model, their size from the data: ``kappa`` makes the expected chi-square equal the
    observed one), the estimate's error is ``gain @ (noise + J_u theta_u)``: its covariance
    has the unmodelled part ``kappa * (gain J_u)(gain J_u)^T``, and the left-out parameters
    themselves are off by their whole size.  Where the data show no misfit, ``kappa`` is
    zero.  Scaling the covariance by chi2/dof instead, as a fit with only noise in mind
    would, leaves the parameters' error 8x larger than their reported std on realistic
    machines fitted with the paper's six parameters: the model error inside the column
    space of the Jacobian goes into the weak directions undetected, and only its
    structure tells how much."""
    idx = np.flatnonzero(fit.free)
    out = np.flatnonzero(unmodelled)
    s_free = fit.scale[idx]
    cov = fit.error_covariance
    cov[:, idx[:, None], idx] = fit.covariance
    rows = np.flatnonzero(fit.misfit)
    if not len(out) or not len(rows):
        return
    ju = _centre(jacobian(fit.theta[rows], design, unmodelled, fit.scale) * weight,
                 mask[rows], onehot)  # (m, N, n_out)
    propagated = np.einsum("mfn,mnu->mfu", gain[rows], ju)  # gain J_u
    left = ju - np.einsum("mnf,mfu->mnu", jac[rows], propagated)
    excess = np.maximum(fit.chi2[rows] - fit.dof[rows], 0.0)
    kappa = excess / np.maximum(np.einsum("mnu,mnu->m", left, left), 1e-300)
    s_out = fit.scale[out]
    cov_ff = fit.covariance[rows] + kappa[:, None, None] * np.einsum(
        "mfu,mgu->mfg", propagated, propagated) * np.outer(s_free, s_free)
    cov[rows[:, None, None], idx[:, None], idx] = cov_ff
    cov[rows[:, None, None], out[:, None], out] = kappa[:, None, None] * np.diag(s_out**2)
    cross = -kappa[:, None, None] * propagated * np.outer(s_free, s_out)
    cov[rows[:, None, None], idx[:, None], out] = cross
    cov[rows[:, None, None], out[:, None], idx] = np.swapaxes(cross, 1, 2)
