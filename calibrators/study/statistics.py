"""The statistics a comparison reports: per strategy, medians with distribution-free 95 %
intervals, tail, failures, calibrated error bars (z-RMS, chi-square rejections),
success against the truth and warnings; between agents, ratios paired on the same
machines with their intervals and win rates."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from scipy import special

from calibrators.study.trials import Trial
from orthoglide_env.scoring import FRAMES


def _stats(values: list[float]) -> dict[str, Any]:
    """Median with its 95 % interval (:func:`median_interval`, None below 6 values) and
    p95 of the finite ``values``."""
    values = [v for v in values if np.isfinite(v)]
    if not values:
        return {"median": None, "ci95": None, "p95": None}
    interval = list(median_interval(values)) if len(values) >= MIN_INTERVAL else None
    return {"median": float(np.median(values)), "ci95": interval,
            "p95": float(np.percentile(values, 95))}


#: The fewest values a 95 % median interval can be had from.
MIN_INTERVAL: int = 6


def median_interval(values: Any, level: float = 0.95) -> tuple[float, float]:
    """A distribution-free interval of the median of ``values``: the order statistics k
    and n-1-k (0-based), k the largest with binomial(n, 1/2) probability of fewer than k+1
    values below the median at most (1 - level)/2, so it covers the median at least
    ``level`` of the time whatever the distribution.  ``ValueError`` when n is too small
    for that level (n < 6 at 95 %)."""
    ordered = np.sort(np.asarray(values, dtype=float))
    n = len(ordered)
    k = int(special.bdtrik((1 - level) / 2, n, 0.5)) if n else 0
    # bdtrik inverts the binomial CDF continuously: step down to an exact order statistic.
    while k >= 0 and special.bdtr(k, n, 0.5) > (1 - level) / 2:
        k -= 1
    if k < 0:
        raise ValueError(f"{n} values cannot bound a median at {level:.0%}")
    return float(ordered[k]), float(ordered[n - 1 - k])


def fraction_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The Clopper-Pearson interval of a fraction ``k`` of ``n`` trials: it covers the
    true fraction at least ``level`` of the time whatever it is (binomial trials);
    ``ValueError`` unless 0 <= k <= n and n >= 1."""
    if not (isinstance(k, (int, np.integer)) and isinstance(n, (int, np.integer))
            and 0 <= k <= n and n >= 1):
        raise ValueError(f"a fraction needs 0 <= k <= n and n >= 1, got k={k!r}, n={n!r}")
    tail = (1 - level) / 2
    low = 0.0 if k == 0 else float(special.betaincinv(k, n - k + 1, tail))
    high = 1.0 if k == n else float(special.betaincinv(k + 1, n - k, 1 - tail))
    return low, high


def _fraction(flags: list[bool | None]) -> float | None:
    """The fraction of the tests that said yes (None: no test)."""
    tested = [f for f in flags if f is not None]
    return float(np.mean(tested)) if tested else None


def warning_kind(text: str) -> str:
    """A warning without its particulars: what it says up to its first colon, its
    numbers as N."""
    return re.sub(r"\d+", "N", text.split(":", 1)[0])


def warning_title(kind: str) -> str:
    """A :func:`warning_kind` as a reader sees it: "N reading(s) the model does not fit"
    reads "readings the model does not fit" (the count is the trials', given beside it)."""
    return re.sub(r"\bN ((?:\w+ )*?)(\w+)\(s\)", r"\1\2s", kind)


#: A silent failure's threshold: an error beyond 3 sigma along one determined combination,
#: as often as a normal deviate passes 3 sigma (0.27 %) over all of a trial's combinations
#: (Bonferroni), so honest error bars give at most 0.27 % of silent failures.
SILENT_SIGMAS: float = 3.0


def named(trial: Trial, kind: str) -> bool:
    """Whether ``trial``'s estimate named a fault of ``kind`` in its warnings
    (:mod:`calibrators.estimators.faults`)."""
    return any(w.startswith("fault ") and kind in w.split(":", 1)[0] for w in trial.warnings)


def silent(trial: Trial) -> bool:
    """Whether ``trial``'s estimate is off by more than :data:`SILENT_SIGMAS` along a
    determined combination (its z-scores, the level spread over their count) with no
    warning."""
    if trial.failed or not trial.z or trial.warnings:
        return False
    # The normal distribution's tails from scipy.special (what scipy.stats.norm computes,
    # bit for bit), whose import costs a comparison a tenth of its time.
    tail = 2 * special.ndtr(-SILENT_SIGMAS) / len(trial.z)
    return bool(np.max(np.abs(trial.z)) > -special.ndtri(tail / 2))


def fault_keys(trials: list[Trial]) -> dict[str, float | None]:
    """``faults_detected``: of the trials in which a fault acted, the fraction whose
    estimate named one of their kinds (None without one); ``silent_failures``: the fraction
    of all trials that fail silently (:func:`silent`)."""
    faulted = [t for t in trials if t.faults]
    return {"faults_detected": float(np.mean([any(named(t, k) for k in t.faults)
                                              for t in faulted])) if faulted else None,
            "silent_failures": float(np.mean([silent(t) for t in trials])) if trials else None}


def summary(trials: list[Trial], target_mm: float = 0.01, faults: bool = False) -> list[dict]:
    """One row per agent x estimator, in the order they first appear.  Accuracy is over
    every trial: a failed one counts with its machine's uncalibrated error
    (``failed_counted_as``).  ``success_rate``: the TCP error after rigid motion, against
    the truth, is at most ``target_mm``; ``predicted_success_rate``: the error an estimate
    predicts for itself is (a failed trial succeeds at neither).  ``warnings``: how many
    trials' estimates gave each kind of warning, with the first one's text.  ``faults`` (a
    lab with faults): the rows hold :func:`fault_keys` too."""
    rows = []
    for agent, name in dict.fromkeys((t.agent, t.estimator) for t in trials):
        mine = [t for t in trials if t.agent == agent and t.estimator == name]
        ok = [t for t in mine if not t.failed]
        z = np.concatenate([t.z for t in ok]) if ok else np.zeros(0)
        times = [t.time_s for t in mine]
        warned: dict[str, dict[str, Any]] = {}
        for t in ok:
            for text in dict.fromkeys(t.warnings):
                # A fit's hint names its own command's options, not compare's.
                kind = warned.setdefault(warning_kind(text),
                                         {"trials": 0, "example": text.split("; try ")[0]})
                kind["trials"] += 1
        rows.append({
            "agent": agent,
            "estimator": name,
            "machines": len(mine),
            "failed": len(mine) - len(ok),
            "failure": next((t.failed for t in mine if t.failed), ""),
            "failed_counted_as": "uncalibrated",
            "time_s": {"median": float(np.median(times)), "max": float(np.max(times))},
            "readings_median": float(np.median([t.readings for t in mine])),
            "tcp_before_mm": {f: _stats([_rms(t.tcp_before, f) for t in mine])
                              for f in FRAMES},
            "tcp_after_mm": {f: _stats([_rms(t.tcp_after, f) for t in mine]) for f in FRAMES},
            "predicted_rigid_mm": _stats([t.predicted_rigid_mm for t in ok]),
            "z_rms": float(np.sqrt(np.mean(z**2))) if z.size else None,
            "chi2_rejected": _fraction([t.chi2_rejected for t in ok]),
            "success_rate": float(np.mean([_rms(t.tcp_after, "rigid") <= target_mm
                                           for t in mine])),
            "predicted_success_rate": float(np.mean([not t.failed
                                                     and t.predicted_rigid_mm <= target_mm
                                                     for t in mine])),
            "warnings": warned,
            **(fault_keys(mine) if faults else {}),
        })
    return rows


def _rms(scores: dict[str, float], frame: str) -> float:
    """A trial's TCP error in ``frame`` (NaN where it has none: a failed trial kept by a
    version that did not score failures)."""
    return scores.get(frame, float("nan"))


def paired(trials: list[Trial]) -> list[dict]:
    """Every two agents compared on the machines both ran, per estimator: the median over
    machines of the ratio of their TCP errors after rigid motion (``agent`` over
    ``against``: below 1, ``agent`` is the more accurate) with its 95 % interval, and the
    fraction of machines where ``agent``'s error is the smaller (``win_rate``; a tie
    counts a half).  Failed trials count with their uncalibrated error, as in
    :func:`summary`; ``failed`` is how many of the machines had a failed fit on either
    side."""
    rows = []
    agents = list(dict.fromkeys(t.agent for t in trials))
    for name in dict.fromkeys(t.estimator for t in trials):
        error = {(t.agent, t.machine): _rms(t.tcp_after, "rigid")
                 for t in trials if t.estimator == name}
        failed = {(t.agent, t.machine) for t in trials if t.estimator == name and t.failed}
        for k, agent in enumerate(agents):
            for against in agents[k + 1:]:
                both = sorted(m for a, m in error if a == agent
                              and np.isfinite(error[agent, m])
                              and np.isfinite(error.get((against, m), np.nan)))
                if not both:
                    continue
                mine = np.array([error[agent, m] for m in both])
                theirs = np.array([error[against, m] for m in both])
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = mine / theirs
                rows.append({
                    "estimator": name, "agent": agent, "against": against,
                    "machines": len(both),
                    "ratio_median": float(np.median(ratio)),
                    "ratio_ci95": (list(median_interval(ratio))
                                   if len(both) >= MIN_INTERVAL else None),
                    "win_rate": float(np.mean((mine < theirs) + 0.5 * (mine == theirs))),
                    "failed": sum((agent, m) in failed or (against, m) in failed
                                  for m in both),
                })
    return rows
