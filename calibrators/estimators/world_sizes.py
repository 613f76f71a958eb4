"""How bad the world is, from the readings: the sizes of the lab's effect families as
variance components.

The consider terms (:mod:`calibrators.estimators.consider`) carry each effect's pattern
over the readings with a coefficient whose second moment the conditions' table gives.  A
fit told a better world than the one its readings came from carries them too small, and
its error bars are too narrow.  The readings show it: what the geometry cannot absorb of
each family's patterns is left in the residuals.

Here every family ``f`` of :data:`~calibrators.estimators.consider.TERM_FAMILIES` gets
one scale ``lambda_f`` on the second moments of its terms under a *base* world, the
table's worst (``workshop``): the readings, whitened and with each mounting's zero
eliminated, are ``y = J delta + C x + e`` with the geometry ``delta`` a fixed effect,
``x_k ~ N(0, lambda_f(k))`` and ``e ~ N(0, I)``.  Projecting out ``J`` leaves the
restricted (REML) likelihood of the ``lambda``; its maximum is found by expectation-
maximisation over the terms' coefficients (each step raises the likelihood, and a scale
that the readings do not support goes to zero instead of below it).

The told world is a point of the same family, ``lambda_f = rho_f``: its terms' energy over
the base's (0 for ``ideal``).  The test that the readings show a worse world is the
likelihood ratio of the best scales at least as large as the told ones (the same
expectation-maximisation, each scale held at or above its told value) against the told
ones.  The alternative lies on one side of the told point in each of the F families the
readings see, so under the told world the ratio is not chi-square with F degrees of
freedom but a mixture (Self and Liang 1987): with probability ``binom(F, k) / 2^F``
chi-square with k degrees, each family's scale falling at its bound or above it with
even odds.  Its threshold at :data:`WORLD_LEVEL` is that mixture's (:func:`threshold`).
The families named are those whose scale held back at its told value alone costs more
than the one-sided test of one family at that level; none passing, the one that costs
most.

Everything the test reads is a function of the readings' geometry, not of their noise:
the readings enter only through the residuals.  The mountings' gains and the indicators'
error curves are patterns over the readings, so they are taken at the readings the fitted
geometry predicts (:func:`noiseless_readings`): a pattern of the noisy readings carries
their noise, and on a design that repeats its postures (whose repetitions the geometry
cannot fit) that noise is the residuals' own, which then shows as a world several times
the workshop's on every machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibrators.estimators.consider import TERM_FAMILIES, Consider, term_family
from calibrators.estimators.solvers import centre, transposed
from orthoglide_env.reading_model import ReadingLayout, jacobian, predict

#: Significance of the test that the readings show a world worse than the one told: the
#: share of experiments taken in the told world that it flags (issue 38 asks for at most
#: 2 % false alarms).
WORLD_LEVEL: float = 0.01
#: Expectation-maximisation steps: the scales move by under 1 % per step after ~30 on the
#: designs of the study (a family the readings see well converges in a few).
ITERATIONS: int = 60
#: A scale below this (of the base world's second moment) is taken as none: 1e-6 of the
#: workshop's is below a nanometre on every term.
FLOOR: float = 1e-6
#: A term is weighed when at least this share of its pattern's energy is left off the
#: geometry and the mountings' zeros: a small remainder magnifies the model's own errors
#: (a gain on a gauge's readings, which its stand's geometry does not hold) into a huge
#: size of the term (a dial's error curve over a short stroke is nearly linear in the
#: reading).  Assumption: 5 %.
VISIBLE: float = 0.05
#: The largest scale the readings may give a family, over the base world's: the table
#: sizes no world beyond the workshop, and the readings of a misfit of the model's own
#: can ask for any.  Assumption: twice the workshop's size (four times its second moment).
CEILING: float = 4.0
#: Directions of the geometry's Jacobian below this fraction of its largest singular value
#: squared are not projected out: they are round-off, not parameters.
RANK_TOL: float = 1e-12
#: The top of the honesty band of issue 38: error bars whose z-RMS a harsher named world's
#: effects would raise above this are too narrow to hand out unsaid.
HONEST_RATIO: float = 1.25
#: The world test's power against a family at a harsher world's size below which its
#: silence does not say that the family is smaller: the issue's share of understated
#: experiments the check must flag (90 %).
SEEN_POWER: float = 0.9
#: How a blind-spot warning (:func:`blind_spot`) starts: a warning of kind ``world`` that
#: says what the readings cannot show, not what they show.
BLIND_SPOT: str = "world: blind spot:"
#: A combination of the machine errors is determined where its reported variance is at
#: most this share of its a-priori one (the data know it better than the prior): the
#: combinations whose z-scores a study pools.
DETERMINED: float = 0.5


@dataclass(frozen=True)
class WorldSizes:
    """The readings' world against the told one, per machine (M) and family (F =
    ``families``): ``estimated`` each family's second moment over the base world's (the
    restricted likelihood's maximum), ``told`` the told world's, ``statistic`` twice the
    log likelihood ratio of the scales at least the told ones against them, ``named``
    (M, F) the families whose own ratio passes the test, ``worse`` (M,) the test."""

    families: tuple[str, ...]
    estimated: np.ndarray
    told: np.ndarray
    statistic: np.ndarray
    named: np.ndarray
    worse: np.ndarray


def restricted_statistics(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                          weight: np.ndarray, theta: np.ndarray, free: np.ndarray,
                          scale: np.ndarray, columns: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """``G = C^T P C`` (M, K, K) and ``b = C^T P y`` (M, K), zero on a term less than
    :data:`VISIBLE` of whose energy is left off the geometry: the terms' reading patterns
    ``columns`` (M, N, K, mm per unit coefficient) and the readings ``values`` (M, N) less
    the geometry at ``theta`` (M, P over ``design.space``), whitened by ``weight`` (N,),
    each mounting's zero eliminated over ``mask``, and ``P`` the projector off the
    geometry's Jacobian over ``free`` (scaled by ``scale``)."""
    n = len(design.space.names)
    rows = (mask, np.eye(len(design.mountings))[design.mounting], design.mounting)
    predicted = predict(theta[:, :n], design)
    y = centre((values - predicted) * weight, *rows)
    # Each mounting's gain goes with the geometry: a remounted gauge's lever and cosine
    # error scale its readings, which a stand's parameters hold only for its first
    # mounting, and a dial's error curve over a short stroke is nearly such a gain.  It
    # scales the readings the geometry predicts: a column of the readings themselves
    # carries their noise, whose part left off the geometry (a design's repetitions)
    # would be projected out of the residuals with it, and the scales read as too large.
    gains = (predicted * weight)[..., None] * rows[1][None]
    jac = centre(np.concatenate([jacobian(theta[:, :n], design, free[:n], scale[:n])
                                 * weight[:, None], gains], axis=-1), *rows)
    c = centre(columns * weight[:, None], *rows)
    values_, vectors = np.linalg.eigh(transposed(jac) @ jac)
    keep = values_ > RANK_TOL * values_[:, -1:]
    # An orthonormal basis of the Jacobian's columns: J V / sqrt(lambda) where kept.
    basis = (jac @ vectors) / np.sqrt(np.where(keep, values_, 1.0))[:, None, :] * keep[:, None]
    py = y - (basis @ (transposed(basis) @ y[..., None]))[..., 0]
    pc = c - basis @ (transposed(basis) @ c)
    gram, b = transposed(c) @ pc, (transposed(c) @ py[..., None])[..., 0]
    energy = np.einsum("mnk,mnk->mk", c, c)
    seen = np.diagonal(gram, axis1=1, axis2=2) >= VISIBLE * energy
    return gram * seen[:, :, None] * seen[:, None, :], b * seen


def _inner(gram: np.ndarray, root: np.ndarray) -> np.ndarray:
    """``I + S G S`` (M, K, K) of ``gram`` (M, K, K), ``S`` the terms' prior roots ``root``
    (M, K), in one array: three temporaries of 4000 machines' (K, K) cost a third of the
    inverse the expectation-maximisation takes of it at each step."""
    inner = root[:, :, None] * gram
    inner *= root[:, None, :]
    inner += np.eye(gram.shape[-1])
    return inner


def log_likelihood(gram: np.ndarray, b: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """(M,) the restricted log likelihood (up to a constant) of the terms' ``variances``
    (M, K): ``-1/2 [log det(I + S G S) - b S (I + S G S)^-1 S b]`` with ``S`` their roots."""
    root = np.sqrt(variances)
    inner = _inner(gram, root)
    _, logdet = np.linalg.slogdet(inner)
    sb = root * b
    solved = np.linalg.solve(inner, sb[..., None])[..., 0]
    return -0.5 * (logdet - np.einsum("mk,mk->m", sb, solved))


def noiseless_readings(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                       theta: np.ndarray) -> np.ndarray:
    """(M, N) the readings the geometry ``theta`` (M, P over ``design.space``) predicts,
    each mounting's zero the mean of its used readings' (``mask``) residuals: the readings
    ``values`` without their noise, where a pattern over the readings is evaluated."""
    predicted = predict(theta[:, :len(design.space.names)], design)
    onehot = np.eye(len(design.mountings))[design.mounting]
    used = mask.astype(float)
    zero = (((values - predicted) * used) @ onehot) / np.maximum(used @ onehot, 1.0)
    return predicted + zero[:, design.mounting]


def estimate_scales(gram: np.ndarray, b: np.ndarray, member: np.ndarray, count: int,
                    start: np.ndarray, lowest: np.ndarray | float = FLOOR) -> np.ndarray:
    """(M, F) each family's scale at the restricted likelihood's maximum, by
    expectation-maximisation from ``start`` (M, F); ``member`` (K,) each term's family
    index.  Each step sets a family's scale to its terms' mean posterior second moment,
    within [``lowest``, :data:`CEILING`] (``lowest`` at least :data:`FLOOR`; (M, F) or one
    number): the step maximises the expected complete likelihood, unimodal in each scale,
    so the bounded step is the bounded maximum's and the likelihood still rises."""
    lowest = np.maximum(lowest, FLOOR)
    scales = np.clip(start, lowest, CEILING)
    sizes = np.bincount(member, minlength=count).astype(float)
    present = sizes > 0
    for _ in range(ITERATIONS):
        root = np.sqrt(scales[:, member])
        # Posterior of the coefficients in units of their prior: (I + S G S)^-1.
        cov = np.linalg.inv(_inner(gram, root))
        mean = (cov @ (root * b)[..., None])[..., 0]
        moment = (mean**2 + np.diagonal(cov, axis1=1, axis2=2)) * root**2
        summed = np.zeros_like(scales)
        np.add.at(summed.T, member, moment.T)
        scales = np.where(present, np.clip(summed / np.maximum(sizes, 1.0), lowest, CEILING),
                          0.0)
    return scales


def threshold(families: int, level: float = WORLD_LEVEL) -> float:
    """The ``level`` quantile from above of the likelihood ratio of scales at least the
    told ones against them, in ``families`` families under the told world: the mixture of
    chi-square with k = 0 .. ``families`` degrees, weights ``binom(families, k) / 2^families``
    (0 for no family: no ratio can pass)."""
    from scipy import optimize, special, stats

    if families == 0:
        return float("inf")
    k = np.arange(1, families + 1)
    weights = special.comb(families, k) / 2.0**families

    def excess(c: float) -> float:
        return float(np.sum(weights * stats.chi2.sf(c, k))) - level

    # At 0 every component but chi-square 0 passes; at the largest component's quantile
    # each passes at most ``level`` of the time, and they weigh less than one together.
    return float(optimize.brentq(excess, 0.0, stats.chi2.isf(level, families)))


def thresholds(seen: np.ndarray) -> np.ndarray:
    """(M,) :func:`threshold` of each machine's count of families seen (``seen`` (M, F)),
    solved once per distinct count: the root-finding over the chi-square mixture costs
    milliseconds a call, and a batch of machines has a handful of counts."""
    counts, index = np.unique(seen.sum(axis=1), return_inverse=True)
    return np.array([threshold(int(n)) for n in counts])[index.reshape(-1)]


def family_index(names: tuple[str, ...]) -> np.ndarray:
    """(K,) each term's family's index in :data:`TERM_FAMILIES`; ``ValueError`` naming a
    term of another family (an instrument's own terms, such as the ballbar's scale or the
    platform's deflection under it, whose sizes the readings are not asked to judge)."""
    other = sorted({term_family(n) for n in names} - set(TERM_FAMILIES))
    if other:
        raise ValueError(f"the world's sizes are estimated for {', '.join(TERM_FAMILIES)} "
                         f"only, not yet for readings with {', '.join(other)} terms")
    return np.array([TERM_FAMILIES.index(term_family(n)) for n in names], dtype=int)


def told_scales(base: Consider, told: Consider, base_columns: np.ndarray,
                told_columns: np.ndarray) -> np.ndarray:
    """(M, F) the told world's second moment over the base world's, per family: the energy
    of its terms' reading patterns over the base's (0 where it has none)."""
    out = np.zeros((len(base_columns), len(TERM_FAMILIES)))
    for f in range(len(TERM_FAMILIES)):
        mine = family_index(base.names) == f
        theirs = (family_index(told.names) == f if len(told.names)
                  else np.zeros(0, dtype=bool))
        energy = np.sum(base_columns[..., mine] ** 2, axis=(1, 2))
        out[:, f] = np.divide(np.sum(told_columns[..., theirs] ** 2, axis=(1, 2)), energy,
                              out=np.zeros(len(energy)), where=energy > 0)
    return out


def seen_families(gram: np.ndarray, member: np.ndarray, count: int) -> np.ndarray:
    """(M, ``count``) whether the readings see a term of each family: one weighed by
    :func:`restricted_statistics` (``gram`` (M, K, K), ``member`` (K,) each term's family)."""
    diagonal = np.diagonal(gram, axis1=1, axis2=2) > 0
    return np.stack([diagonal[:, member == f].any(axis=1) for f in range(count)], axis=1)


def judge(gram: np.ndarray, b: np.ndarray, member: np.ndarray, told: np.ndarray
          ) -> WorldSizes:
    """The restricted likelihood's scales (:func:`estimate_scales`, started at the told
    ones and at the base's, the better kept) and the test of the ``told`` ones (M, F)
    against those at least as large, at :data:`WORLD_LEVEL` (:func:`threshold`, over the
    families with a term the readings see)."""
    from scipy import stats

    count = told.shape[1]
    present = np.bincount(member, minlength=count) > 0
    candidates = [estimate_scales(gram, b, member, count, start)
                  for start in (np.maximum(told, FLOOR), np.ones_like(told))]
    likelihoods = [log_likelihood(gram, b, c[:, member]) for c in candidates]
    estimated = np.where((likelihoods[0] >= likelihoods[1])[:, None], *candidates)
    above = estimate_scales(gram, b, member, count, np.maximum(estimated, told), told)
    at_told = log_likelihood(gram, b, told[:, member])
    best = log_likelihood(gram, b, above[:, member])
    statistic = np.maximum(2 * (best - at_told), 0.0)
    # A family the readings do not see has no say in the ratio, nor a degree in its law.
    seen = seen_families(gram, member, count)
    flagged = statistic > thresholds(seen)
    cost = np.zeros(told.shape)
    for f in np.flatnonzero(present):
        back = above.copy()
        back[:, f] = told[:, f]
        cost[:, f] = 2 * (best - log_likelihood(gram, b, back[:, member]))
    named = (cost > stats.chi2.isf(2 * WORLD_LEVEL, 1)) & seen
    strongest = np.eye(count, dtype=bool)[np.argmax(np.where(seen, cost, -np.inf), axis=1)]
    named = np.where(named.any(axis=1, keepdims=True), named, strongest) & flagged[:, None]
    return WorldSizes(TERM_FAMILIES, estimated, told, statistic, named, flagged)


def power_against(gram: np.ndarray, member: np.ndarray, told: np.ndarray,
                  alternative: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """(M, F) a lower bound of the world test's power (:func:`judge`) against each family
    alone at its ``alternative`` scale (M, F), the others at the ``told`` ones (M, F);
    ``seen`` (M, F) the families the readings see (the test's degrees).

    The test's ratio is at least the ratio of that one alternative against the told world,
    whose law there is ``sum(mu_i chi2_1) - sum(log(1 + mu_i))`` (``mu`` the family's
    excess terms' eigenvalues over the told covariance of the projected readings), so the
    chance that this one passes the test's threshold (:func:`threshold`) bounds its power
    from below.  The weighted sum of chi-squares is taken as Satterthwaite's scaled
    chi-square of the same mean and variance.  A family the readings do not see, or not
    larger than told, gets 0."""
    from scipy import stats

    machines, families = told.shape
    root = np.sqrt(told[:, member])
    inner = _inner(gram, root)
    # C^T (I + C L C^T)^-1 C over the projected readings, by Woodbury.
    spread = gram - gram @ (root[:, :, None] * np.linalg.solve(
        inner, root[:, :, None] * gram))
    limit = thresholds(seen)
    out = np.zeros((machines, families))
    for f in np.flatnonzero(np.isin(np.arange(families), member)):
        terms = member == f
        excess = np.clip(alternative[:, f] - told[:, f], 0.0, None)
        mu = np.clip(np.linalg.eigvalsh(spread[:, terms][:, :, terms]
                                        * excess[:, None, None]), 0.0, None)
        first, second = mu.sum(axis=1), (mu**2).sum(axis=1)
        on = seen[:, f] & (first > 0) & np.isfinite(limit)
        gain = np.where(on, second, 1.0) / np.where(on, first, 1.0)
        degrees = np.where(on, first**2, 1.0) / np.where(on, second, 1.0)
        beyond = limit + np.sum(np.log1p(mu), axis=1)
        out[:, f] = np.where(on, stats.chi2.sf(np.where(on, beyond, 0.0) / gain, degrees),
                             0.0)
    return out


def widening(covariance: np.ndarray, moved: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(M,) the z-RMS the estimates' error bars would show along their determined
    combinations (:data:`DETERMINED`) were terms that move them by ``moved`` (M, P, K, per
    unit coefficient) acting: ``sqrt(mean(1 + |d^T moved|^2 / lambda))`` over the
    eigenvectors ``d`` of ``covariance`` (M, P, P) in units of the a-priori ``scale``
    (P,), ``lambda`` their eigenvalues."""
    values, vectors = np.linalg.eigh(covariance / np.outer(scale, scale))
    along = transposed(vectors) @ (moved / scale[:, None])
    extra = np.sum(along**2, axis=-1) / np.where(values > 0, values, np.inf)
    known = values <= DETERMINED
    ratio = np.sum((1.0 + extra) * known, axis=1) / np.maximum(known.sum(axis=1), 1)
    return np.sqrt(ratio)


def blind_spot(told_name: str, harsher_name: str, families: tuple[str, ...],
               factors: np.ndarray, power: np.ndarray) -> str | None:
    """The words of one machine's blind-spot warning, or None: the families (F) the told
    world ``told_name`` carries smaller than the harsher named world ``harsher_name``,
    each with its ``factors`` (F,: the z-RMS that family at the harsher world's size would
    give the error bars, 1 where it is not smaller) and the world test's ``power`` against
    it (F,).  Those the test sees in fewer than :data:`SEEN_POWER` of experiments are
    blind spots; when together they would widen the error bars beyond
    :data:`HONEST_RATIO` (the excesses of ``z^2`` add), the words name the fewest of
    them, largest first, that do, with the factor."""
    excess = np.where(power < SEEN_POWER, factors**2 - 1.0, 0.0)
    if np.sqrt(1.0 + excess.sum()) <= HONEST_RATIO:
        return None
    order = np.argsort(-excess)
    needed = int(np.searchsorted(np.cumsum(excess[order]), HONEST_RATIO**2 - 1.0)) + 1
    named = ", ".join(f"{families[f]} ({factors[f]:.2f}x, seen in {power[f]:.0%})"
                      for f in order[:needed])
    return (f"{BLIND_SPOT} the fit was told the {told_name} conditions, smaller than the "
            f"{harsher_name}'s in effects these readings cannot show (the world test "
            f"sees them in fewer than {SEEN_POWER:.0%} of experiments that have them): "
            f"{named}; if the {harsher_name}'s effects act, its error bars are "
            f"{np.sqrt(1.0 + excess.sum()):.2f}x too narrow along the combinations it "
            f"determines; the readings do not say the world is worse, only that they "
            f"cannot rule it out; fit with --conditions {harsher_name}, or add readings "
            "of an instrument that sees them")


def scaled(consider: Consider, scales: np.ndarray) -> Consider:
    """``consider`` with each term's pattern times the root of its family's scale, per
    machine (``scales`` (M, F))."""
    root = np.sqrt(scales[:, family_index(consider.names)])  # (M, K + J)
    k = consider.drive.shape[-1]
    return Consider(consider.names, consider.drive * root[:, None, None, :k],
                    consider.reading * root[:, None, k:],
                    None if consider.pivot is None else consider.pivot * root[:, None, None, :k])


def warning(sizes: WorldSizes, m: int, told_name: str) -> str | None:
    """The words of machine ``m``'s test: None unless the readings show a world worse
    than ``told_name``'s, else which effects and by how much."""
    if not sizes.worse[m]:
        return None
    parts = []
    for f in np.flatnonzero(sizes.named[m]):
        est, told = sizes.estimated[m, f], sizes.told[m, f]
        size = (f"about {np.sqrt(est / told):.1f}x the told size" if told > 0
                else f"about {np.sqrt(est):.1f}x the workshop's size")
        parts.append(f"{sizes.families[f]} ({size})")
    return (f"world: the readings show a world worse than the {told_name} conditions the "
            f"fit was told (likelihood ratio {sizes.statistic[m]:.0f}, test at "
            f"{WORLD_LEVEL:g}): {', '.join(parts)}; its error bars are too narrow; fit "
            "with --conditions auto, or name the conditions the readings were taken in")
