"""The exact-model fit of a batch of machines and its honest errors: the solution's
covariance, with the errors the model leaves out or considers, and the chi-square test.

The problem and its solvers are :mod:`calibrators.estimators.solvers`.  A free parameter
without a prior is a *base-parameter* fit: the normal matrix is eigen-decomposed and the
combinations whose information is below :data:`RETAIN` (the data pin them down worse
than their a-priori scale) are not moved from nominal; they are reported by name and their a-priori
scale goes into the covariance, so that predicted errors include what the data cannot
see.  A prior makes every combination identifiable in the Bayesian sense (its information
is at least 1), so the same code is a MAP fit.

Honest uncertainty: the cost at the solution is a chi-square with
``readings - mountings - (retained directions without prior)`` degrees of freedom when the
model explains the readings.  Beyond the :data:`CHI2_LEVEL` quantile the fit says so and
scales its covariance by chi2/dof.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from functools import cached_property

import numpy as np

from calibrators.estimators.consider import Consider
from calibrators.estimators.solvers import MAX_ITERATIONS as MAX_ITERATIONS
from calibrators.estimators.solvers import RETAIN as RETAIN
from calibrators.estimators.solvers import SOLVERS as SOLVERS
from calibrators.estimators.solvers import Problem, StartModel, centre, damped_step, transposed
from orthoglide_env.reading_model import (
    ReadingLayout,
    carriage_derivatives,
    pivot_derivatives,
)
from orthoglide_env.scoring.grid import blocks

#: Significance of the chi-square test of the model: above the (1 - CHI2_LEVEL) quantile
#: the readings are not explained by the model and the noise.
CHI2_LEVEL: float = 1e-3


#: What every machine of a :class:`BatchFit` shares: its parameters and their weights.
_SHARED = ("free", "scale", "prior", "sigma")


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
    sigma: float | np.ndarray  # the noise each reading was weighted with (mm)
    #: (M, n, n) covariance of (estimate - truth) over every parameter, physical units,
    #: with the errors the model leaves out (see :func:`_model_error`).
    error_covariance: np.ndarray
    #: (M, nf, K) how far each considered term's unit coefficient moves the free
    #: parameters (physical units): the estimate's covariance with the terms.
    considered_gain: np.ndarray

    def split(self) -> list[BatchFit]:
        """One fit per machine (each a batch of one), with its chi-square test's verdict
        (:attr:`misfit`, taken for the whole batch at once)."""
        out = [replace(self, **{f.name: getattr(self, f.name)[m:m + 1] for f in fields(self)
                                if f.name not in _SHARED})
               for m in range(len(self.theta))]
        for m, part in enumerate(out):
            part.__dict__["misfit"] = self.misfit[m:m + 1]
        return out

    @classmethod
    def joined(cls, parts: list[BatchFit]) -> BatchFit:
        """The fits ``parts`` of one design (each with its own verdict) as one batch, the
        inverse of :meth:`split`: what is worked out per machine from a fit is then worked
        out over the arrays of machines at once, the same numbers."""
        out = replace(parts[0], **{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                                   for f in fields(cls) if f.name not in _SHARED})
        out.__dict__["misfit"] = np.concatenate([p.misfit for p in parts])
        return out

    @property
    def chi2_dof(self) -> np.ndarray:
        """(M,) chi2/dof, NaN without degrees of freedom."""
        return np.divide(self.chi2, self.dof, out=np.full(np.shape(self.chi2), np.nan),
                         where=self.dof > 0)

    @cached_property
    def misfit(self) -> np.ndarray:
        """(M,) bool: the chi-square test rejects the model at :data:`CHI2_LEVEL` (taken
        once: a fit is not changed after it is made)."""
        return chi2_rejects(self.dof, self.chi2)

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


def chi2_rejects(dof: np.ndarray, chi2: np.ndarray) -> np.ndarray:
    """Whether the chi-square test at :data:`CHI2_LEVEL` rejects a fit of ``dof`` degrees
    of freedom and chi-square ``chi2`` (arrays alike; never without a degree of freedom)."""
    # SciPy loads when a fit is judged, not when the command line starts.  The survival
    # function itself (what scipy.stats.chi2.sf evaluates, without its per-call overhead:
    # this runs once per machine of a sweep).
    from scipy import special

    dof = np.asarray(dof)
    return (dof > 0) & (special.chdtrc(np.maximum(dof, 1), chi2) < CHI2_LEVEL)


def directions(information: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvectors (rows) of a data information matrix in scaled units: those whose
    eigenvalue is at least :data:`RETAIN`, most informative first (the combinations the
    data determine at least as well as their a-priori scale), and the others."""
    values, vectors = np.linalg.eigh(information)
    return vectors[:, values >= RETAIN].T[::-1], vectors[:, values < RETAIN].T


def z_scores(estimate: np.ndarray, truth: np.ndarray, covariance: np.ndarray,
             information: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(estimate - truth) / reported std along the identifiable directions of
    ``information`` (free parameters: physical ``estimate``, ``truth``, ``covariance``;
    ``information`` in units of ``scale``).  For an honest estimator these are standard
    normal: their RMS over many machines is the check that its error bars can be trusted."""
    err = (estimate - truth) / scale
    cov = covariance / np.outer(scale, scale)
    dirs, _ = directions(information)
    return dirs @ err / np.sqrt(np.einsum("kf,fg,kg->k", dirs, cov, dirs))


def newton_step(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                sigma: float | np.ndarray, free: np.ndarray, theta: np.ndarray,
                prior: np.ndarray, scale: np.ndarray, world: np.ndarray | None = None
                ) -> np.ndarray:
    """One undamped Gauss-Newton step of :func:`fit_batch`'s problem from ``theta`` (M, P):
    the fit of readings a little different from those ``theta`` solves (a fold of them
    left out), to second order in that difference, at one Jacobian's cost instead of a
    fit's (the model bends on the scale of the leg length, a fold moves it by microns)."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    mask = np.atleast_2d(np.asarray(mask, dtype=bool)) & np.isfinite(values)
    problem = Problem(design, np.where(mask, values, 0.0), mask, sigma,
                       np.asarray(free, dtype=bool), np.asarray(prior, dtype=float),
                       np.asarray(scale, dtype=float), world)
    theta = np.array(theta, dtype=float)
    rows = np.arange(len(theta))
    r, _ = problem.residual(theta, rows)
    a, g = problem.normal(problem.jacobian(theta, rows), r, theta)
    eigen = None if problem.full_rank else np.linalg.eigh(a)
    theta[:, problem.idx] += damped_step(a, g, np.zeros(len(theta)), eigen) * problem.s
    return theta


def fit_batch(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
              sigma: float | np.ndarray, free: np.ndarray, fixed: np.ndarray,
              prior: np.ndarray, scale: np.ndarray,
              max_iterations: int = MAX_ITERATIONS, unmodelled: np.ndarray | None = None,
              solver: str = "gauss-newton", consider: Consider | None = None,
              left_out: np.ndarray | None = None, world: np.ndarray | None = None,
              start: np.ndarray | None = None, curvature: bool = False,
              shared: StartModel | None = None) -> BatchFit:
    """Fit machines whose readings ``values`` (M, N) of ``design`` are used where ``mask``.

    ``free``, ``fixed``, ``prior``, ``scale``: per parameter of ``design.space`` (mask of the
    free ones, values of the others, prior sigmas or inf, scales).  The fit starts from
    nominal (the prior mean) for the free parameters.  ``unmodelled``: the parameters that
    are neither free nor known (the model leaves them out); their a-priori spread
    ``left_out`` (per parameter of the space, mm or rad; default their scale) and their
    misfit go into the reported covariance (:func:`_model_error`).  ``solver``: one of
    :data:`SOLVERS`.  ``sigma``: the noise of every reading (mm), or one for all.
    ``consider``: the real lab's effects the model leaves out
    (:mod:`calibrators.estimators.consider`), added to the covariance
    (:func:`_considered`).  ``world``: (M, N, K) reading patterns (:func:`world_columns`)
    whose coefficients are the parameters after the design's space, fitted instead.
    ``start``: where the free parameters start (per parameter, or (M, P); default the
    prior mean): a refit of nearly the same readings converges in a step or two from the
    first fit's solution.  ``curvature``: the model's curvature over the estimate's own
    spread goes into the covariance too (:func:`_curvature`).  ``shared``: the model and
    Jacobian at the start, kept for the other fits of the same ``design``, ``free``,
    ``fixed`` and ``scale`` that start there (:class:`~calibrators.estimators.solvers.
    StartModel`)."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver '{solver}'; choose from {list(SOLVERS)}")
    values = np.atleast_2d(np.asarray(values, dtype=float))
    mask = np.atleast_2d(np.asarray(mask, dtype=bool)) & np.isfinite(values)
    values = np.where(mask, values, 0.0)
    m_count = len(values)
    problem = Problem(design, values, mask, sigma, np.asarray(free, dtype=bool),
                       np.asarray(prior, dtype=float), np.asarray(scale, dtype=float), world,
                       shared)
    idx, s = problem.idx, problem.s
    theta = np.tile(np.asarray(fixed, dtype=float), (m_count, 1))
    theta[:, idx] = 0.0 if start is None else np.broadcast_to(start, theta.shape)[:, idx]
    converged, iterations, last = SOLVERS[solver](problem, theta, max_iterations)
    rows = np.arange(m_count)
    model = problem.predict(theta, rows)
    r, cost = problem.residual(theta, rows, model)
    # A converged fit's last Jacobian is its solution's to ~1e-11 (the last step is below
    # 1e-9 of each scale; the model bends on the scale of the leg length).
    jac = (last if last is not None and converged.all()
           else problem.jacobian(theta, rows))
    info = transposed(jac) @ jac
    normal = info + np.eye(len(idx)) * problem.precision
    if problem.full_rank:
        # Every direction is retained: the covariance is the inverse (a third of the
        # eigen-decomposition's cost), and the gain's matrix is the same.
        cov_scaled = gain_matrix = np.linalg.inv(normal)
        retained = np.full(m_count, len(idx))
    else:
        lam, vec = np.linalg.eigh(normal)
        keep = lam >= RETAIN * (1 - 1e-9)
        # Directions the fit did not move keep their a-priori scale (1 in scaled units).
        inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 1.0)
        cov_scaled = (vec * inv[:, None, :]) @ transposed(vec)
        gain_matrix = (vec * np.where(keep, inv, 0.0)[:, None, :]) @ transposed(vec)
        retained = keep.sum(axis=1)
    mountings_used = (mask.astype(float) @ problem.onehot > 0).sum(axis=1)
    priored = int(np.sum(problem.precision > 0))
    dof = mask.sum(axis=1) - mountings_used - np.maximum(retained - priored, 0)
    moved = np.zeros((m_count, len(idx), 0))
    if consider is not None and not consider.empty:
        moved = _considered(problem, jac, gain_matrix, world_columns(design, consider))
        cov_scaled = cov_scaled + moved @ transposed(moved)
    if curvature:
        bent = _curvature(problem, theta, jac, cov_scaled, gain_matrix)
        cov_scaled = cov_scaled + bent @ transposed(bent)
    fit = BatchFit(
        theta=theta, free=problem.free, scale=problem.scale,
        prior=np.asarray(prior, dtype=float), covariance=cov_scaled * np.outer(s, s),
        information=info, residuals=np.where(mask, -r / problem.weight, np.nan), chi2=cost,
        dof=dof, retained=retained, converged=converged, iterations=iterations, sigma=sigma,
        error_covariance=np.zeros((m_count, len(free), len(free))),
        considered_gain=moved * s[:, None],
    )
    _model_error(fit, problem, jac, gain_matrix,
                 np.zeros(len(free), dtype=bool) if unmodelled is None else unmodelled,
                 problem.scale if left_out is None else np.asarray(left_out, dtype=float))
    return fit


#: Draws of the estimate's spread over which :func:`_curvature` averages (a fixed stream:
#: a fit of the same readings reports the same covariance).
CURVATURE_DRAWS: int = 32


def _curvature(problem: Problem, theta: np.ndarray, jac: np.ndarray, cov_scaled: np.ndarray,
               gain_matrix: np.ndarray, draws: int = CURVATURE_DRAWS) -> np.ndarray:
    """(M, nf, draws) how far the model's curvature moves the estimate, in scaled units:
    ``moved moved^T`` is what it adds to the covariance.

    The covariance is the linear model's, but the truth lies off the estimate by the
    estimate's own spread, which along what the readings do not see (a rigid motion of
    the whole machine above all: millimetres and milliradians, held by the error preset's
    prior) is large.  There the readings change only at second order, by ``phi^2 L``:
    0.3-1 um for the preset's 2 mrad, which the fit explains with the combinations it
    determines best (``drho_i - dL_i``).  An instrument that reads at 0.1-0.35 um
    determines those to 0.2-0.3 um in three hours, so the curvature outgrows them.  The
    truth's offset is drawn from the covariance ``draws`` times (a fixed seed), and the
    part of its readings that the Jacobian does not carry, whitened and centred as the
    residuals are, is taken through the gain; its mean stays in (a second moment), as it
    is a bias of the same sign on every machine."""
    rows = np.arange(len(theta))
    idx, s = problem.idx, problem.s
    lam, vec = np.linalg.eigh(cov_scaled)
    root = vec * np.sqrt(np.maximum(lam, 0.0))[:, None, :]
    base = problem.predict(theta, rows)
    stream = np.random.default_rng(0)
    out = np.empty((len(theta), len(idx), draws))
    for k in range(draws):
        offset = (root @ stream.standard_normal(len(idx)))  # (M, nf)
        shifted = theta.copy()
        shifted[:, idx] += offset * s
        change = centre((problem.predict(shifted, rows) - base) * problem.weight,
                        problem.mask, problem.onehot, problem.design.mounting)
        bent = change - (jac @ offset[..., None])[..., 0]
        out[..., k] = (gain_matrix @ (transposed(jac) @ bent[..., None]))[..., 0]
    return out / np.sqrt(draws)


def world_columns(design: ReadingLayout, consider: Consider) -> np.ndarray:
    """(M, N, K) each consider term's pattern over the readings (mm per unit coefficient):
    a carriage's pattern times the reading's derivative by that axis's encoder offset (at
    the nominal machine: the machine's errors change it by parts in 1e3 of a term of a few
    um), and for a ballbar's, its pattern where its pivot was centred times the reading's
    derivative by the carriages there; or a reading's own."""
    derivative = carriage_derivatives(design)  # (N, 3), mm/mm
    drive = np.einsum("na,mnak->mnk", derivative, consider.drive)
    if consider.pivot is not None:
        drive = drive + np.einsum("na,mnak->mnk", pivot_derivatives(design), consider.pivot)
    return np.concatenate([drive, consider.reading], axis=-1)


def _considered(problem: Problem, jac: np.ndarray, gain_matrix: np.ndarray,
                columns: np.ndarray) -> np.ndarray:
    """(M, nf, K) how far, in scaled units, each consider term moves the estimate: its
    reading pattern ``columns`` (:func:`world_columns`), whitened and centred within its
    mounting as the residuals are, moves it by ``gain J^T C`` per unit of its coefficient,
    whose second moment the pattern already carries; ``moved moved^T`` is what the terms
    add to the covariance."""
    columns = centre(columns * problem.weight[:, None], problem.mask, problem.onehot,
                     problem.design.mounting)
    return gain_matrix @ (transposed(jac) @ columns)


def _model_error(fit: BatchFit, problem: Problem, jac: np.ndarray, gain_matrix: np.ndarray,
                 unmodelled: np.ndarray, spread: np.ndarray) -> None:
    """Fill ``fit.error_covariance``: the covariance of (estimate - truth) over every
    parameter, including the ``unmodelled`` ones the fit kept at nominal.

    A model that leaves parameters out is wrong by ``J_u theta_u``.  Taking the left-out
    errors as zero-mean with covariance ``D`` (their structure from the exact model), the
    estimate's error is ``gain @ (noise + J_u theta_u)``: its covariance has the
    unmodelled part ``(gain J_u) D (gain J_u)^T``, and the left-out parameters themselves
    are off by their whole size.  ``D`` is at least their a-priori ``spread`` squared (most
    of ``J_u theta_u`` lies in the column space of ``J`` and goes into the estimate unseen
    by the residuals, so a fit on readings that show no misfit is no less wrong), and
    ``kappa * scale^2`` where the data say more: where the chi-square test rejects,
    ``kappa`` makes the expected chi-square equal the observed one.  Scaling the
    covariance by chi2/dof instead, as a fit with only noise in mind would, leaves the
    parameters' error 8x larger than their reported std on realistic machines fitted with
    the paper's six parameters."""
    idx = np.flatnonzero(fit.free)
    out = np.flatnonzero(unmodelled)
    cov = fit.error_covariance
    cov[:, idx[:, None], idx] = fit.covariance
    if not len(out):
        return
    # The left-out parameters' Jacobian of a whole batch is tens of MB, passed over a
    # dozen times: machines a cache-sized block at a time (each machine's numbers are its
    # own, whatever its block).
    for block in blocks(len(fit.theta)):
        _model_error_of(fit, problem, jac[block], gain_matrix[block], unmodelled, spread,
                        np.arange(len(fit.theta))[block])


def _model_error_of(fit: BatchFit, problem: Problem, jac: np.ndarray,
                    gain_matrix: np.ndarray, unmodelled: np.ndarray, spread: np.ndarray,
                    rows: np.ndarray) -> None:
    """:func:`_model_error` of machines ``rows`` (``jac`` and ``gain_matrix``: theirs)."""
    idx = np.flatnonzero(fit.free)
    out = np.flatnonzero(unmodelled)
    s_free = fit.scale[idx]
    cov = fit.error_covariance
    ju = problem.jacobian(fit.theta[rows], rows, free=unmodelled)  # (M, N, n_out)
    # gain J_u, the gain being ``gain_matrix @ J^T`` (the pseudo-inverse over the retained
    # directions times the Jacobian).
    propagated = gain_matrix @ (transposed(jac) @ ju)
    left = ju - jac @ propagated
    excess = np.where(fit.misfit[rows], np.maximum(fit.chi2[rows] - fit.dof[rows], 0.0), 0.0)
    kappa = excess / np.maximum(np.einsum("mnu,mnu->m", left, left), 1e-300)
    # D in scaled units: per machine and left-out parameter.
    d = np.maximum(kappa[:, None], (spread[out] / fit.scale[out])[None] ** 2)
    if not d.any():
        return
    s_out = fit.scale[out]
    cov_ff = fit.covariance[rows] + np.einsum(
        "mfu,mu,mgu->mfg", propagated, d, propagated) * np.outer(s_free, s_free)
    cov[rows[:, None, None], idx[:, None], idx] = cov_ff
    cov[rows[:, None, None], out[:, None], out] = d[:, None, :] * np.eye(len(out)) * s_out**2
    cross = -(propagated * d[:, None, :]) * np.outer(s_free, s_out)
    cov[rows[:, None, None], idx[:, None], out] = cross
    cov[rows[:, None, None], out[:, None], idx] = np.swapaxes(cross, 1, 2)
