"""The exact-model estimator: any parameter set, priors or base parameters, honest errors.

One damped Gauss-Newton (Levenberg) solver, batched over machines: every machine of a
sweep that ran the same design is fitted in the same numpy calls, each with its own
damping, convergence and failure flag; one machine is a batch of one.

What it minimises, per machine, in units where every free parameter is divided by its
scale (:func:`calibrators.estimators.parameters.scales`) and every reading by the gauge sigma::

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

from dataclasses import dataclass, fields, replace

import numpy as np

from calibrators.estimators.consider import Consider
from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.model.errors import ERROR_NAMES
from orthoglide_env.reading_model import ReadingLayout, jacobian, predict

#: A combination is identifiable (and moved by a base-parameter fit) when its information
#: in scaled units is at least this: the data determine it at least as well as its
#: a-priori scale does.
RETAIN: float = 1.0
#: Convergence on the step, in units of each parameter's scale (2e-9 mm for drho): above
#: the wander that round-off leaves (the readings carry ~eps * L ~ 7e-14 mm, the
#: closed-form Jacobian ~eps relative), so a converged fit is reproducible to ~1e-9 of
#: each scale whatever batch it ran in.
STEP_TOL: float = 1e-9
#: ... or when the cost decrease the Gauss-Newton step predicts (half its squared length in
#: the metric of the normal matrix) is below this: the step is then under 1.5e-7 standard
#: deviations along every direction, whatever the round-off floor of a given design.
DECREMENT_TOL: float = 1e-14
#: A predicted decrease below this many times the cost's round-off is not tested against
#: the cost (see :meth:`_Problem.cost_resolution`).
RESOLUTION_MARGIN: float = 100.0
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
    sigma: float | np.ndarray  # the noise each reading was weighted with (mm)
    #: (M, n, n) covariance of (estimate - truth) over every parameter, physical units,
    #: with the errors the model leaves out (see :func:`_model_error`).
    error_covariance: np.ndarray
    #: (M, nf, K) how far each considered term's unit coefficient moves the free
    #: parameters (physical units): the estimate's covariance with the terms.
    considered_gain: np.ndarray

    def split(self) -> list[BatchFit]:
        """One fit per machine (each a batch of one)."""
        shared = ("free", "scale", "prior", "sigma")
        return [replace(self, **{f.name: getattr(self, f.name)[m:m + 1] for f in fields(self)
                                 if f.name not in shared})
                for m in range(len(self.theta))]

    @property
    def chi2_dof(self) -> np.ndarray:
        """(M,) chi2/dof, NaN without degrees of freedom."""
        return np.divide(self.chi2, self.dof, out=np.full(np.shape(self.chi2), np.nan),
                         where=self.dof > 0)

    @property
    def misfit(self) -> np.ndarray:
        """(M,) bool: the chi-square test rejects the model at :data:`CHI2_LEVEL`."""
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


def _centre(values: np.ndarray, mask: np.ndarray, onehot: np.ndarray,
            mounting: np.ndarray) -> np.ndarray:
    """Subtract each mounting's mean over its used readings (axis 1 of ``values``, which
    may carry a trailing parameter axis; ``onehot`` (N, K) and ``mounting`` (N,): each
    reading's mounting); unused readings become 0.  ``values`` is overwritten (the fits'
    arrays are large, and fresh): it is returned."""
    weights = mask.astype(float)
    counts = np.maximum(weights @ onehot, 1.0)  # (M, K)
    if values.ndim == 3:
        weights = weights[..., None]
        counts = counts[..., None]
    values *= weights
    if values.ndim == 2:
        mean = (values @ onehot) / counts
    else:
        mean = (onehot.T @ values) / counts
    values -= mean[:, mounting]
    values *= weights
    return values


class _Problem:
    """The least-squares problem of :func:`fit_batch`, for a subset ``rows`` of machines."""

    def __init__(self, design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                 sigma: float | np.ndarray,
                 free: np.ndarray, prior: np.ndarray, scale: np.ndarray,
                 world: np.ndarray | None = None) -> None:
        self.design, self.values, self.mask, self.free, self.scale = (
            design, values, mask, free, scale)
        # Parameters beyond the design's space are the coefficients of ``world``'s reading
        # patterns (M, N, K), mm per unit: they enter the readings linearly.
        self.n = len(design.space.names)
        self.world = np.zeros((len(values), len(design), 0)) if world is None else world
        self.idx = np.flatnonzero(free)
        self.s = scale[self.idx]
        with np.errstate(divide="ignore"):
            self.precision = np.where(np.isfinite(prior[self.idx]),
                                      (self.s / prior[self.idx]) ** 2, 0.0)
        # One instrument per mounting, so one weight per mounting: centring the weighted
        # residuals of a mounting is then its weighted zero.
        self.weight = 1.0 / weighting_sigma(np.broadcast_to(sigma, (len(design),)))
        self.onehot = np.eye(len(design.mountings))[design.mounting]
        # A prior that alone keeps every direction of the normal matrix at or above RETAIN
        # (as the extended fit's does) leaves none to truncate: a step is a linear solve.
        self.full_rank = bool(np.all(self.precision >= RETAIN * (1 - 1e-9)))

    def predict(self, theta: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The readings of machines ``rows`` at ``theta`` (mm)."""
        model = predict(theta[:, :self.n], self.design)
        if self.world.shape[-1]:
            model += (self.world[rows] @ theta[:, self.n:, None])[..., 0]
        return model

    def residual(self, theta: np.ndarray, rows: np.ndarray,
                 model: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Whitened data residuals (zeros eliminated) and the total cost with the prior."""
        model = self.predict(theta, rows) if model is None else model
        r = _centre((model - self.values[rows]) * self.weight, self.mask[rows], self.onehot,
                    self.design.mounting)
        phi = theta[:, self.idx] / self.s
        return r, np.sum(r**2, axis=1) + np.sum(self.precision * phi**2, axis=1)

    def jacobian(self, theta: np.ndarray, rows: np.ndarray, free: np.ndarray | None = None
                 ) -> np.ndarray:
        """Whitened Jacobian over ``free`` (default: the free parameters), scaled units."""
        free = self.free if free is None else free
        n = self.n
        jac = jacobian(theta[:, :n], self.design, free[:n], self.scale[:n])
        if free[n:].any():
            jac = np.concatenate([jac, self.world[rows][..., free[n:]] * self.scale[n:][free[n:]]],
                                 axis=-1)
        jac *= self.weight[:, None]
        return _centre(jac, self.mask[rows], self.onehot, self.design.mounting)

    def cost_resolution(self, cost: np.ndarray) -> np.ndarray:
        """What a cost comparison can resolve, with a safety factor: each reading's model
        carries round-off ~eps * L (positions of the order of the leg length), so the cost
        carries ~2 sqrt(cost) eps L / sigma."""
        roundoff = np.finfo(float).eps * self.design.machine_design.L * np.max(self.weight)
        return RESOLUTION_MARGIN * 2 * (np.sqrt(cost) + 1.0) * roundoff

    def normal(self, jac: np.ndarray, r: np.ndarray, theta: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Normal matrix with the prior, and gradient."""
        a = _t(jac) @ jac + np.eye(len(self.idx)) * self.precision
        g = (_t(jac) @ r[..., None])[..., 0] + self.precision * theta[:, self.idx] / self.s
        return a, g


def _step(a: np.ndarray, g: np.ndarray, damping: np.ndarray,
          eigen: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Damped Gauss-Newton step in the retained directions of the normal matrix ``a``: from
    its eigen-decomposition ``eigen`` (computed once for every damping tried), or by a
    linear solve where every direction is retained (``eigen`` None)."""
    if eigen is None:
        damped = a + damping[:, None, None] * np.eye(a.shape[-1])
        return -np.linalg.solve(damped, g[..., None])[..., 0]
    lam, vec = eigen
    keep = lam >= RETAIN * (1 - 1e-9)
    inv = np.where(keep, 1.0 / (np.where(keep, lam, 1.0) + damping[:, None]), 0.0)
    return -(vec @ (inv * (_t(vec) @ g[..., None])[..., 0])[..., None])[..., 0]


def _t(matrices: np.ndarray) -> np.ndarray:
    """Each matrix of a stack transposed.  The products above are matrix products of
    stacks (BLAS, one matrix at a time: a machine's numbers do not depend on its batch),
    not ``einsum`` loops, which cost ~100x more on large batches."""
    return np.swapaxes(matrices, -1, -2)


def _damped_gauss_newton(problem: _Problem, theta: np.ndarray, max_iterations: int
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Levenberg-damped Gauss-Newton, each machine with its own damping: a step that does
    not lower the cost is retried with ten times the damping.  Updates ``theta`` in place;
    returns (converged, iterations) per machine and each machine's Jacobian at its last
    iterate (for a converged one, within a step of 1e-9 of a scale of its solution)."""
    m_count = len(theta)
    idx, s = problem.idx, problem.s
    done = np.zeros(m_count, dtype=bool)
    failed = np.zeros(m_count, dtype=bool)
    iterations = np.zeros(m_count, dtype=int)
    damping = np.zeros(m_count)
    last: np.ndarray | None = None
    # The model readings at each machine's theta when known: an accepted trial step's.
    models = np.empty((m_count, len(problem.design)))
    known = np.zeros(m_count, dtype=bool)
    for _ in range(max_iterations):
        rows = np.flatnonzero(~done & ~failed)
        if not len(rows):
            break
        th = theta[rows]
        unknown = rows[~known[rows]]
        if len(unknown):
            models[unknown] = problem.predict(theta[unknown], unknown)
        model = models[rows]
        r, cost = problem.residual(th, rows, model)
        jac = problem.jacobian(th, rows)
        if last is None:
            last = np.empty((m_count, *jac.shape[1:]))
        last[rows] = jac
        a, g = problem.normal(jac, r, th)
        iterations[rows] += 1
        # Near the solution the cost cannot resolve a step (its round-off, ~1e-16 of it,
        # exceeds the decrease g A^-1 g / 2 a step brings), so there the undamped step is
        # taken untested; convergence is on the step size alone (the Gauss-Newton rate is
        # only linear where residuals and curvature meet, so a small predicted decrease
        # does not yet mean a converged parameter).
        eigen = None if problem.full_rank else np.linalg.eigh(a)
        newton = _step(a, g, np.zeros(len(rows)), eigen)
        decrease = -0.5 * np.einsum("mf,mf->m", g, newton)
        untested = decrease <= problem.cost_resolution(cost)
        theta[rows[untested][:, None], idx] += newton[untested] * s
        known[rows[untested]] = False
        done[rows[(np.max(np.abs(newton), axis=1, initial=0.0) < STEP_TOL)
                  | (decrease < DECREMENT_TOL)]] = True
        pending = ~untested
        while pending.any():
            sub = np.flatnonzero(pending)
            # Undamped, the step is the Newton step already solved for.
            step = newton[sub]
            damped = np.flatnonzero(damping[rows[sub]] > 0)
            if len(damped):
                step[damped] = _step(a[sub[damped]], g[sub[damped]], damping[rows[sub[damped]]],
                                     None if eigen is None else (eigen[0][sub[damped]],
                                                                 eigen[1][sub[damped]]))
            trial = th[sub].copy()
            trial[:, idx] += step * s
            trial_model = problem.predict(trial, rows[sub])
            _, trial_cost = problem.residual(trial, rows[sub], trial_model)
            accept = trial_cost <= cost[sub]
            ok = sub[accept]
            theta[rows[ok]] = trial[accept]
            models[rows[ok]] = trial_model[accept]
            known[rows[ok]] = True
            damping[rows[ok]] = np.where(damping[rows[ok]] > DAMPING_START,
                                         damping[rows[ok]] / 10, 0.0)
            pending[ok] = False
            grow = sub[~accept]
            damping[rows[grow]] = np.maximum(damping[rows[grow]] * 10, DAMPING_START)
            give_up = grow[damping[rows[grow]] > DAMPING_MAX]
            failed[rows[give_up]] = True
            pending[give_up] = False
    return done & ~failed, iterations, last


def _scipy_least_squares(problem: _Problem, theta: np.ndarray, max_iterations: int
                         ) -> tuple[np.ndarray, np.ndarray, None]:
    """The same cost minimised by ``scipy.optimize.least_squares`` (trust-region
    reflective), one machine at a time: a cross-check of the batched solver.  It does not
    truncate unidentifiable directions, so use it with a prior or a full-rank selection.
    Its Jacobians are not kept."""
    from scipy.optimize import least_squares

    idx, s = problem.idx, problem.s
    root = np.sqrt(problem.precision)
    converged = np.zeros(len(theta), dtype=bool)
    iterations = np.zeros(len(theta), dtype=int)
    for m in range(len(theta)):
        rows = np.array([m])
        start = theta[rows].copy()

        def at(phi: np.ndarray, start: np.ndarray = start) -> np.ndarray:
            th = start.copy()
            th[:, idx] = phi * s
            return th

        def residual(phi: np.ndarray, rows: np.ndarray = rows) -> np.ndarray:
            r, _ = problem.residual(at(phi), rows)
            return np.concatenate([r[0], root * phi])

        def jac(phi: np.ndarray, rows: np.ndarray = rows) -> np.ndarray:
            return np.vstack([problem.jacobian(at(phi), rows)[0], np.diag(root)])

        out = least_squares(residual, start[0, idx] / s, jac=jac, method="trf", xtol=1e-15,
                            ftol=1e-15, gtol=1e-15, max_nfev=4 * max_iterations)
        theta[m, idx] = out.x * s
        converged[m] = out.status > 0
        iterations[m] = out.nfev
    return converged, iterations, None


SOLVERS = {"gauss-newton": _damped_gauss_newton, "scipy": _scipy_least_squares}


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
    problem = _Problem(design, np.where(mask, values, 0.0), mask, sigma,
                       np.asarray(free, dtype=bool), np.asarray(prior, dtype=float),
                       np.asarray(scale, dtype=float), world)
    theta = np.array(theta, dtype=float)
    rows = np.arange(len(theta))
    r, _ = problem.residual(theta, rows)
    a, g = problem.normal(problem.jacobian(theta, rows), r, theta)
    eigen = None if problem.full_rank else np.linalg.eigh(a)
    theta[:, problem.idx] += _step(a, g, np.zeros(len(theta)), eigen) * problem.s
    return theta


def fit_batch(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
              sigma: float | np.ndarray,
              free: np.ndarray, fixed: np.ndarray, prior: np.ndarray, scale: np.ndarray,
              max_iterations: int = MAX_ITERATIONS, unmodelled: np.ndarray | None = None,
              solver: str = "gauss-newton", consider: Consider | None = None,
              left_out: np.ndarray | None = None, world: np.ndarray | None = None,
              start: np.ndarray | None = None) -> BatchFit:
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
    first fit's solution."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver '{solver}'; choose from {list(SOLVERS)}")
    values = np.atleast_2d(np.asarray(values, dtype=float))
    mask = np.atleast_2d(np.asarray(mask, dtype=bool)) & np.isfinite(values)
    values = np.where(mask, values, 0.0)
    m_count = len(values)
    problem = _Problem(design, values, mask, sigma, np.asarray(free, dtype=bool),
                       np.asarray(prior, dtype=float), np.asarray(scale, dtype=float), world)
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
    info = _t(jac) @ jac
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
        cov_scaled = (vec * inv[:, None, :]) @ _t(vec)
        gain_matrix = (vec * np.where(keep, inv, 0.0)[:, None, :]) @ _t(vec)
        retained = keep.sum(axis=1)
    mountings_used = (mask.astype(float) @ problem.onehot > 0).sum(axis=1)
    priored = int(np.sum(problem.precision > 0))
    dof = mask.sum(axis=1) - mountings_used - np.maximum(retained - priored, 0)
    moved = np.zeros((m_count, len(idx), 0))
    if consider is not None and not consider.empty:
        moved = _considered(problem, jac, gain_matrix, world_columns(design, consider))
        cov_scaled = cov_scaled + moved @ _t(moved)
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


def world_columns(design: ReadingLayout, consider: Consider) -> np.ndarray:
    """(M, N, K) each consider term's pattern over the readings (mm per unit coefficient):
    a carriage's pattern times the reading's derivative by that axis's encoder offset (at
    the nominal machine: the machine's errors change it by parts in 1e3 of a term of a few
    um), or a reading's own."""
    drho = np.isin(np.arange(len(design.space.names)),
                   [design.space.names.index(n) for n in ERROR_NAMES[:3]])
    derivative = jacobian(np.zeros(len(drho)), design, drho, np.ones(3))  # (N, 3), mm/mm
    return np.concatenate([np.einsum("na,mnak->mnk", derivative, consider.drive),
                           consider.reading], axis=-1)


def _considered(problem: _Problem, jac: np.ndarray, gain_matrix: np.ndarray,
                columns: np.ndarray) -> np.ndarray:
    """(M, nf, K) how far, in scaled units, each consider term moves the estimate: its
    reading pattern ``columns`` (:func:`world_columns`), whitened and centred within its
    mounting as the residuals are, moves it by ``gain J^T C`` per unit of its coefficient,
    whose second moment the pattern already carries; ``moved moved^T`` is what the terms
    add to the covariance."""
    columns = _centre(columns * problem.weight[:, None], problem.mask, problem.onehot,
                      problem.design.mounting)
    return gain_matrix @ (_t(jac) @ columns)


def _model_error(fit: BatchFit, problem: _Problem, jac: np.ndarray, gain_matrix: np.ndarray,
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
    s_free = fit.scale[idx]
    cov = fit.error_covariance
    cov[:, idx[:, None], idx] = fit.covariance
    if not len(out):
        return
    rows = np.arange(len(fit.theta))
    ju = problem.jacobian(fit.theta, rows, free=unmodelled)  # (M, N, n_out)
    # gain J_u, the gain being ``gain_matrix @ J^T`` (the pseudo-inverse over the retained
    # directions times the Jacobian).
    propagated = gain_matrix @ (_t(jac) @ ju)
    left = ju - jac @ propagated
    excess = np.where(fit.misfit, np.maximum(fit.chi2 - fit.dof, 0.0), 0.0)
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
