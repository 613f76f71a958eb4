"""The least-squares problem of an exact-model fit and its solvers: a batched damped
Gauss-Newton (Levenberg), and scipy's ``least_squares`` as a cross-check.

What is minimised, per machine, in units where every free parameter is divided by its
scale (:func:`calibrators.estimators.parameters.scales`) and every reading by the gauge sigma::

    sum over readings (y - f(theta) - zero[mounting])^2 / sigma^2  +  sum over priors phi^2

The zero of each mounting (a gauge's dial is set where it was set) is eliminated exactly
by centring residuals and Jacobian within each mounting.  Every machine of a sweep that
ran the same design is solved in the same numpy calls, each with its own damping,
convergence and failure flag; one machine is a batch of one.  Directions of the normal
matrix whose information is below :data:`RETAIN` are not moved (a base-parameter fit).
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.reading_model import (
    GaugeSight,
    ReadingLayout,
    gauge_sight,
    jacobian,
    predict,
)

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
#: the cost (see :meth:`Problem.cost_resolution`).
RESOLUTION_MARGIN: float = 100.0
MAX_ITERATIONS: int = 50
DAMPING_START: float = 1e-3
DAMPING_MAX: float = 1e10


def centre(values: np.ndarray, mask: np.ndarray, onehot: np.ndarray,
           mounting: np.ndarray) -> np.ndarray:
    """Subtract each mounting's mean over its used readings (axis 1 of ``values``, which
    may carry a trailing parameter axis; ``onehot`` (N, K) and ``mounting`` (N,): each
    reading's mounting); unused readings become 0.  ``values`` is overwritten (the fits'
    arrays are large, and fresh): it is returned."""
    weights = mask.astype(float)
    counts = np.maximum(weights @ onehot, 1.0)  # (M, K)
    # Where every reading is used (most fits), a weight of one leaves each value's bits.
    every = bool(mask.all())
    if values.ndim == 3:
        weights = weights[..., None]
        counts = counts[..., None]
    if not every:
        values *= weights
    if values.ndim == 2:
        mean = (values @ onehot) / counts
    else:
        mean = (onehot.T @ values) / counts
    values -= mean[:, mounting]
    if not every:
        values *= weights
    return values


class StartModel:
    """The model readings and Jacobian (before weighting and centring) at one parameter
    vector, kept across the fits of one reading layout, free set and scales that start
    there: the refits that leave one outlier out after another (a ballbar's three hours:
    about 60 refits of each fit) differ only in which readings they use, so their first
    iteration's model and derivatives are the same bits each time, and are made once."""

    def __init__(self) -> None:
        self.theta: np.ndarray | None = None
        self.model: np.ndarray | None = None
        self.jac: np.ndarray | None = None

    def holds(self, theta: np.ndarray) -> bool:
        """Whether every row of ``theta`` (the design's parameters) is the kept point; the
        first all-equal batch asked about becomes it."""
        if not len(theta) or not bool((theta == theta[0]).all()):
            return False
        if self.theta is None:
            self.theta = theta[0].copy()
        return bool(np.array_equal(theta[0], self.theta))


class Problem:
    """The least-squares problem of :func:`fit_batch`, for a subset ``rows`` of machines;
    ``shared``: model readings and derivatives shared with the other fits of the group."""

    def __init__(self, design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                 sigma: float | np.ndarray,
                 free: np.ndarray, prior: np.ndarray, scale: np.ndarray,
                 world: np.ndarray | None = None, shared: StartModel | None = None) -> None:
        self.design, self.values, self.mask, self.free, self.scale = (
            design, values, mask, free, scale)
        self.shared = shared
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
        # The last gauge sight each machine's readings were predicted from, and where: a
        # Jacobian at the same parameters (the next iteration's, after an accepted or
        # untested step) starts from it instead of solving the gauges' geometry again.
        self._sights: GaugeSight | None = None
        self._seen_at = np.full((len(values), self.n), np.nan)

    def predict(self, theta: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The readings of machines ``rows`` at ``theta`` (mm)."""
        th = theta[:, :self.n]
        kept = self.shared is not None and self.shared.holds(th)
        if kept and self.shared.model is not None:
            model = np.repeat(self.shared.model[None], len(th), axis=0)
        else:
            model = predict(th, self.design, self._sight(theta, rows))
            if kept:
                self.shared.model = model[0].copy()
        if self.world.shape[-1]:
            model += (self.world[rows] @ theta[:, self.n:, None])[..., 0]
        return model

    def _sight(self, theta: np.ndarray, rows: np.ndarray) -> GaugeSight | None:
        """The gauge sight of machines ``rows`` at ``theta`` (None without dial gauges),
        kept for them; all machines alike (a fit's start) are solved as one."""
        if not self.design.space.gauges:
            return None
        th = theta[:, :self.n]
        same = len(th) > 1 and bool((th == th[0]).all())
        sight = gauge_sight(th[:1] if same else th, self.design)
        if self._sights is None:
            self._sights = GaugeSight(sight.aim, *(np.empty((len(self.values), *x.shape[1:]))
                                                   for x in sight[1:]))
        for kept, new in zip(self._sights[1:], sight[1:], strict=True):
            kept[rows] = new
        self._seen_at[rows] = th
        return sight.rows(np.zeros(len(th), dtype=int)) if same else sight

    def _kept_sight(self, theta: np.ndarray, rows: np.ndarray) -> GaugeSight | None:
        """The gauge sight of machines ``rows`` at ``theta``: kept where they were last
        predicted at ``theta``, solved for the others."""
        if self._sights is None:
            return None
        th = theta[:, :self.n]
        kept = (self._seen_at[rows] == th).all(axis=1)
        sight = self._sights.rows(rows)
        if not kept.all():
            fresh = np.flatnonzero(~kept)
            solved = gauge_sight(th[fresh], self.design)
            for out, new in zip(sight[1:], solved[1:], strict=True):
                out[fresh] = new
        return sight

    def residual(self, theta: np.ndarray, rows: np.ndarray,
                 model: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Whitened data residuals (zeros eliminated) and the total cost with the prior."""
        model = self.predict(theta, rows) if model is None else model
        r = centre((model - self.values[rows]) * self.weight, self.mask[rows], self.onehot,
                   self.design.mounting)
        phi = theta[:, self.idx] / self.s
        return r, np.sum(r**2, axis=1) + np.sum(self.precision * phi**2, axis=1)

    def jacobian(self, theta: np.ndarray, rows: np.ndarray, free: np.ndarray | None = None
                 ) -> np.ndarray:
        """Whitened Jacobian over ``free`` (default: the free parameters), scaled units."""
        kept = free is None and self.shared is not None and self.shared.holds(theta[:, :self.n])
        free = self.free if free is None else free
        n = self.n
        if kept and self.shared.jac is not None:
            jac = np.repeat(self.shared.jac[None], len(theta), axis=0)
        else:
            jac = jacobian(theta[:, :n], self.design, free[:n], self.scale[:n],
                           self._kept_sight(theta, rows))
            if kept:
                self.shared.jac = jac[0].copy()
        if free[n:].any():
            jac = np.concatenate([jac, self.world[rows][..., free[n:]] * self.scale[n:][free[n:]]],
                                 axis=-1)
        jac *= self.weight[:, None]
        return centre(jac, self.mask[rows], self.onehot, self.design.mounting)

    def cost_resolution(self, cost: np.ndarray) -> np.ndarray:
        """What a cost comparison can resolve, with a safety factor: each reading's model
        carries round-off ~eps * L (positions of the order of the leg length), so the cost
        carries ~2 sqrt(cost) eps L / sigma."""
        roundoff = np.finfo(float).eps * self.design.machine_design.L * np.max(self.weight)
        return RESOLUTION_MARGIN * 2 * (np.sqrt(cost) + 1.0) * roundoff

    def normal(self, jac: np.ndarray, r: np.ndarray, theta: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Normal matrix with the prior, and gradient."""
        a = transposed(jac) @ jac + np.eye(len(self.idx)) * self.precision
        g = (transposed(jac) @ r[..., None])[..., 0] + self.precision * theta[:, self.idx] / self.s
        return a, g


def damped_step(a: np.ndarray, g: np.ndarray, damping: np.ndarray,
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
    return -(vec @ (inv * (transposed(vec) @ g[..., None])[..., 0])[..., None])[..., 0]


def transposed(matrices: np.ndarray) -> np.ndarray:
    """Each matrix of a stack transposed.  The products above are matrix products of
    stacks (BLAS, one matrix at a time: a machine's numbers do not depend on its batch),
    not ``einsum`` loops, which cost ~100x more on large batches."""
    return np.swapaxes(matrices, -1, -2)


def _damped_gauss_newton(problem: Problem, theta: np.ndarray, max_iterations: int
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
        newton = damped_step(a, g, np.zeros(len(rows)), eigen)
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
                step[damped] = damped_step(a[sub[damped]], g[sub[damped]],
                                           damping[rows[sub[damped]]],
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


def _scipy_least_squares(problem: Problem, theta: np.ndarray, max_iterations: int
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


