"""Monte-Carlo comparison of strategies: agents x estimators, on the same machines, at an
equal time budget.

Machine ``i`` of a run is drawn from seed ``seed * 1_000_003 + i``: every agent works on
the same machine (its gauge installations and noise then follow its own actions), with the
same lab time budget.  Every estimator reads each agent's notebook, and each estimate is
scored against the truth: the TCP error over the workspace grid in three frames (the
rigid one is the headline), the z-scores of the estimate along the combinations of
machine errors it determines (1 for honest error bars), and whether the error it
predicts for itself meets the target.  Work is spread over processes, local or on a Ray
cluster (:mod:`calibrators.study.engines`); results depend on neither how many nor where.
Each finished trial can be appended to a JSON-lines file as it ends, and a run can
resume from it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from contextlib import closing
from dataclasses import asdict, dataclass, field
from functools import cache, partial
from typing import Any

import gymnasium as gym
import numpy as np
from scipy import special

import orthoglide_env
from calibrators.agents import Agent, get_agent
from calibrators.estimators.base import Estimate, leaves
from calibrators.estimators.catalogue import for_study, get_estimator
from calibrators.estimators.prediction import predicted_rigid_mm
from calibrators.study.engines import results
from calibrators.study.episodes import (
    DEFAULT_BUDGET_S,
    Episode,
    machine_seed,
    measurements_of,
    run_episode,
    run_episodes,
)
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import DEFAULT_PRESET, ERROR_NAMES, MachineParams
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring import FRAMES, ScoreReport, score_batch, uncalibrated_errors
from orthoglide_env.world.conditions import IDEAL, Conditions
from orthoglide_env.world.truth import World

#: Fractions of an episode's time at which the accuracy-versus-time curve re-estimates.
CURVE_FRACTIONS: tuple[float, ...] = (0.25, 0.5, 0.75)


@dataclass(frozen=True)
class Config:
    """What a comparison runs."""

    agents: tuple[str, ...]
    estimators: tuple[str, ...]
    budget_s: float = DEFAULT_BUDGET_S
    errors: str = DEFAULT_PRESET
    sigma: float = DEFAULT_SIGMA
    resolution: float = DEFAULT_RESOLUTION
    backend: str = "exact"
    seed: int = 0
    #: Success: the TCP error after rigid motion at most this (mm), against the truth (and
    #: predicted, by the estimate itself).
    target_mm: float = 0.01
    #: The estimator re-run at fractions of each episode's time for the accuracy-versus-time
    #: curve ("": no curve).
    curve_estimator: str = ""
    #: The machines' design.
    design: MachineDesign = PROTOTYPE
    #: The world beyond the geometry.
    conditions: Conditions = IDEAL
    #: The lab has a room thermometer.
    thermometer: bool = False

    def lab_kwargs(self, agent: Agent) -> dict[str, Any]:
        """The lab env's arguments of this comparison for ``agent`` (with the tracker or
        the gauge block when it needs one)."""
        return {"errors": self.errors, "gauge_sigma": self.sigma,
                "gauge_resolution": self.resolution, "backend": self.backend,
                "tracker": agent.needs_tracker, "reference": agent.needs_reference,
                "budget_s": self.budget_s, "design": self.design,
                "conditions": self.conditions, "thermometer": self.thermometer}


@dataclass(frozen=True)
class Trial:
    """One agent and one estimator on one machine."""

    agent: str
    estimator: str
    machine: int
    failed: str = ""  # why, when the estimate could not be made
    time_s: float = float("nan")
    readings: int = 0
    tcp_before: dict[str, float] = field(default_factory=dict)  # frame -> RMS mm
    tcp_after: dict[str, float] = field(default_factory=dict)
    predicted_rigid_mm: float = float("nan")
    #: The estimator's chi-square test rejects its model on these readings (None: the
    #: estimator has no such test, or the trial failed).
    chi2_rejected: bool | None = None
    z: list[float] = field(default_factory=list)
    error: list[float] = field(default_factory=list)  # estimate - truth, 27 errors
    std: list[float] = field(default_factory=list)  # reported, NaN where fixed
    curve: list[list[float]] = field(default_factory=list)  # [seconds, rigid RMS mm]
    warnings: list[str] = field(default_factory=list)  # the estimate's

    @property
    def key(self) -> tuple[str, str, int]:
        return self.agent, self.estimator, self.machine

    @property
    def names(self) -> tuple[str, ...]:
        """The machine errors that ``error`` and ``std`` hold, in order (none if failed)."""
        return ERROR_NAMES if self.error else ()

    def to_json(self) -> str:
        """One line of strict JSON: ``names`` beside ``error`` and ``std``, and ``null``
        where a number is not one (NaN: the std of an error the fit held fixed, or what a
        failed trial never had)."""
        data = {**asdict(self), "names": list(self.names)}
        return json.dumps(leaves(data, lambda v: None if v != v else v), allow_nan=False)

    @classmethod
    def from_json(cls, line: str) -> Trial:
        """A line of :meth:`to_json`, or of an earlier version (NaN for null, no
        ``names``)."""
        data = json.loads(line)
        names = data.pop("names", None)
        # A trial holds None nowhere else.
        rejected = data.pop("chi2_rejected", None)
        trial = cls(**leaves(data, lambda v: float("nan") if v is None else v),
                    chi2_rejected=rejected)
        if names is not None and tuple(names) != trial.names:
            raise ValueError("the trial's error names are not this version's machine errors")
        return trial


@cache
def _machine_scales() -> np.ndarray:
    """The default scale of each of the 27 machine errors."""
    return default_scales(ParameterSpace())


def machine_z_scores(ests: list[Estimate], truths: list[MachineParams]) -> list[np.ndarray]:
    """(estimate - truth) / reported std of each estimate, along the combinations of the
    fitted machine errors whose reported variance is at most half their a-priori size (the
    data know them better than the prior): standard normal for honest error bars.  Only
    machine errors: an instrument's nuisances (stands, a tracker's frame) have no truth the
    comparison could hold them to in every lab.  The eigen-decompositions of estimates
    over the same parameters run in one call."""
    out: list[np.ndarray] = [np.zeros(0)] * len(ests)
    groups: dict[tuple[str, ...], list[int]] = {}
    for k, est in enumerate(ests):
        groups.setdefault(tuple(est.names), []).append(k)
    for names, members in groups.items():
        idx = [k for k, name in enumerate(names) if name in ERROR_NAMES]
        machine = [ERROR_NAMES.index(names[k]) for k in idx]
        scale = _machine_scales()[machine]
        cov = np.stack([ests[m].covariance[np.ix_(idx, idx)] for m in members]) / np.outer(
            scale, scale)
        err = np.stack([(ests[m].theta[machine] - truths[m].to_vector()[machine]) / scale
                        for m in members])
        values, vectors = np.linalg.eigh(cov)
        # Along an eigenvector the reported variance is its eigenvalue.
        along = (np.swapaxes(vectors, -1, -2) @ err[..., None])[..., 0]
        for m, value, z in zip(members, values, along, strict=True):
            known = value <= 0.5
            out[m] = z[known] / np.sqrt(value[known])
    return out


@dataclass
class _Episode:
    """The agent's episode on machine ``machine`` of the run, to score."""

    agent: str
    machine: int
    run: Episode
    #: The truth's TCP error vectors under the nominal model's commands over the scoring
    #: grid: the same for every agent and estimator on this machine, so computed once.
    before: np.ndarray | None = None


def _trials(episodes: list[_Episode], name: str, estimates: list[Estimate | Exception],
            curves: list[list[list[float]]]) -> list[Trial]:
    """Score each estimate against its machine's truth (:func:`_score`).  A failed estimate
    leaves its machine uncalibrated: its TCP error after is the one before, so that the
    accuracy over trials counts it."""
    good = [k for k, est in enumerate(estimates) if not isinstance(est, Exception)]
    fitted = [estimates[k] for k in good]
    z_scores = iter(machine_z_scores(fitted, [episodes[k].run.truth for k in good]))  # type: ignore[arg-type]
    reports = iter(_score(episodes, estimates))
    predicted = iter(predicted_rigid_mm(fitted).tolist() if good else [])  # type: ignore[arg-type]
    out = []
    for episode, est, curve in zip(episodes, estimates, curves, strict=True):
        run, count = episode.run, len(episode.run.records)
        report = next(reports)
        scored = {"tcp_before": {f: getattr(report.tcp_before, f).rms for f in FRAMES},
                  "tcp_after": {f: getattr(report.tcp_after, f).rms for f in FRAMES}}
        if isinstance(est, Exception):
            out.append(Trial(episode.agent, name, episode.machine,
                             failed=str(est).splitlines()[0] or type(est).__name__,
                             time_s=run.time_s, readings=count, **scored))
            continue
        std = np.full(len(ERROR_NAMES), np.nan)
        for k, n in enumerate(est.names):
            if n in ERROR_NAMES:
                std[ERROR_NAMES.index(n)] = np.sqrt(est.covariance[k, k])
        out.append(Trial(
            episode.agent, name, episode.machine, time_s=run.time_s, readings=count,
            predicted_rigid_mm=next(predicted), chi2_rejected=est.chi2_rejected,
            z=next(z_scores).tolist(),
            error=(est.theta[:len(ERROR_NAMES)] - run.truth.to_vector()).tolist(),
            std=std.tolist(), curve=curve, warnings=list(est.warnings), **scored,
        ))
    return out


def _curves(episodes: list[_Episode], name: str, estimates: list[Estimate | Exception],
            config: Config) -> list[list[list[float]]]:
    """Accuracy against time for each episode: re-estimates from the readings taken by
    :data:`CURVE_FRACTIONS` of its time (the uncalibrated error where there are too few),
    then the full estimate (``estimates``: the fits of the whole episodes)."""
    points: list[list[list[float]]] = [[] for _ in episodes]
    for fraction in (*CURVE_FRACTIONS, 1.0):
        datas = [measurements_of(e.run.records, e.run.time_s, until_s=fraction * e.run.time_s,
                                 design=e.run.truth.design)
                 for e in episodes]
        fitted = estimates if fraction == 1.0 else for_study(
            name, episodes[0].run.sigma, config.conditions, config.errors).fit_many(datas)
        for k, (episode, report) in enumerate(zip(episodes, _score(episodes, fitted),
                                                  strict=True)):
            points[k].append([fraction * episode.run.time_s, report.tcp_after.rigid.rms])
    return points


def _score(episodes: list[_Episode], estimates: list[Estimate | Exception]
           ) -> list[ScoreReport]:
    """Each estimate's machine, with what its controller compensates of the drives' lead
    error, scored against its episode's truth in one batched solve; a failed estimate is
    scored as the nominal machine."""
    machines = [MachineParams(design=e.run.truth.design) if isinstance(est, Exception)
                else est.machine for e, est in zip(episodes, estimates, strict=True)]
    corrections = [est.lead_correction if isinstance(est, Estimate) and est.fits_lead else None
                   for est in estimates]
    return score_batch(machines, [e.run.truth for e in episodes], before=_before(episodes),
                       worlds=_worlds(episodes), corrections=corrections)


def _before(episodes: list[_Episode]) -> np.ndarray:
    """The uncalibrated error vectors of the episodes' machines, each computed once (one
    batched solve for those not known yet)."""
    new = [e for e in episodes if e.before is None]
    if new:
        for episode, vectors in zip(new, uncalibrated_errors([e.run.truth for e in new],
                                                             worlds=_worlds(new)),
                                    strict=True):
            episode.before = vectors
    return np.stack([e.before for e in episodes])  # type: ignore[misc]


def _worlds(episodes: list[_Episode]) -> list[World] | None:
    """The episodes' worlds, for scoring (None under ideal conditions)."""
    worlds = [e.run.world for e in episodes]
    return None if any(w is None for w in worlds) else worlds  # type: ignore[return-value]


def run_chunk(config: Config, indices: list[int], skip: set[tuple[str, str, int]],
              batched: bool = True) -> list[Trial]:
    """Machines ``indices``: every agent's episode on each, then every estimator over all
    of an agent's notebooks at once (a fixed design is fitted in one batched solve).
    ``batched``: the episodes of an agent run together in the lab's native vector env (on
    the exact backend); else one machine at a time in a lone lab, step by step (the
    reference path, same numbers)."""
    trials = []
    uncalibrated: dict[int, np.ndarray] = {}  # a machine's, whichever agent worked on it
    for agent_name in config.agents:
        todo = {i: [e for e in config.estimators if (agent_name, e, i) not in skip]
                for i in indices}
        runs = [i for i in indices if todo[i]]
        if not runs:
            continue
        episodes = agent_episodes(config, agent_name, runs, batched)
        for episode in episodes:
            episode.before = uncalibrated.get(episode.machine)
        for name in config.estimators:
            mine = [e for e in episodes if name in todo[e.machine]]
            if not mine:
                continue
            # The machines' preset sizes the errors an estimator leaves out: its a-priori
            # belief of what the machine holds, not the machine itself.
            estimates = for_study(name, mine[0].run.sigma, config.conditions,
                                  config.errors).fit_many([e.run.measurements for e in mine])
            curves = (_curves(mine, name, estimates, config)
                      if name == config.curve_estimator
                      else [[] for _ in mine])
            trials += _trials(mine, name, estimates, curves)
        uncalibrated.update((e.machine, e.before) for e in episodes if e.before is not None)
    return trials


def agent_episodes(config: Config, agent_name: str, runs: list[int], batched: bool = True
                   ) -> list[_Episode]:
    """The agent's episode on each machine of ``runs`` (machine ``i`` from its seed)."""
    seeds = [machine_seed(config.seed, i) for i in runs]
    kwargs = config.lab_kwargs(get_agent(agent_name))
    if batched and config.backend == "exact":
        with closing(gym.make_vec(orthoglide_env.LAB_ENV_ID, num_envs=len(runs),
                                  vectorization_mode="vector_entry_point", **kwargs)) as envs:
            done = run_episodes(envs, [get_agent(agent_name) for _ in runs], seeds)
    else:
        with closing(gym.make(orthoglide_env.LAB_ENV_ID, **kwargs)) as env:
            done = [run_episode(env, get_agent(agent_name), seed) for seed in seeds]
    return [_Episode(agent_name, index, e) for index, e in zip(runs, done, strict=True)]


#: Machines per task: their episodes run in one lab vector env and a fixed design's fits
#: in one batched solve, whose fixed costs per step and per iteration (the outlier refits
#: of a few machines above all) are still paid down up to about 500 machines; the scoring
#: works through them in cache-sized blocks (:data:`~orthoglide_env.scoring.BLOCK`).  Few
#: enough for a live progress bar and little lost work on an interrupt.
CHUNK: int = 500


def run(config: Config, machines: int, jobs: int = 1, done: list[Trial] | None = None,
        on_trial: Callable[[Trial], None] | None = None,
        progress: Callable[[int], None] | None = None, engine: str = "local",
        address: str | None = None, chunk: int = CHUNK) -> list[Trial]:
    """Run the comparison over ``machines`` machines in chunks of at most ``chunk``
    machines spread over ``jobs`` workers of ``engine`` (:func:`calibrators.study.engines.
    results`: ``local`` processes, or ``ray`` at ``address``), skipping the trials in
    ``done``; ``on_trial`` sees each new
    trial as it ends, ``progress`` the number of machines finished.  Trials come back in
    (machine, agent, estimator) order, the same whatever ``jobs``, ``engine`` and
    ``chunk``: a machine's fits are those it gets alone.  A
    KeyboardInterrupt stops the workers at once and is raised again, every trial
    finished so far having gone to ``on_trial``."""
    for name in config.agents:
        get_agent(name)
    for name in config.estimators:
        get_estimator(name)
    if not (isinstance(chunk, int) and chunk >= 1):
        raise ValueError(f"chunk must be a whole number of machines >= 1, got {chunk!r}")
    done = list(done or [])
    skip = {t.key for t in done}
    # Every worker gets work even on short runs.
    size = max(1, min(chunk, -(-machines // jobs)))
    chunks = [list(range(i, min(i + size, machines))) for i in range(0, machines, size)]
    trials = list(done)
    with closing(results(partial(run_chunk, config, skip=skip), chunks, jobs, engine,
                         address)) as finished:
        for chunk, new in finished:
            for trial in new:
                trials.append(trial)
                if on_trial:
                    on_trial(trial)
            if progress:
                progress(len(chunk))
    order = {(a, e): k for k, (a, e) in enumerate(
        (a, e) for a in config.agents for e in config.estimators)}
    return sorted(trials, key=lambda t: (t.machine, order.get((t.agent, t.estimator), 0)))


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


def _fraction(flags: list[bool | None]) -> float | None:
    """The fraction of the tests that said yes (None: no test)."""
    tested = [f for f in flags if f is not None]
    return float(np.mean(tested)) if tested else None


def warning_kind(text: str) -> str:
    """A warning without its particulars: what it says up to its first colon, its
    numbers as N."""
    return re.sub(r"\d+", "N", text.split(":", 1)[0])


def summary(trials: list[Trial], target_mm: float = 0.01) -> list[dict]:
    """One row per agent x estimator, in the order they first appear.  Accuracy is over
    every trial: a failed one counts with its machine's uncalibrated error
    (``failed_counted_as``).  ``success_rate``: the TCP error after rigid motion, against
    the truth, is at most ``target_mm``; ``predicted_success_rate``: the error an estimate
    predicts for itself is (a failed trial succeeds at neither).  ``warnings``: how many
    trials' estimates gave each kind of warning, with the first one's text."""
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
    :func:`summary`."""
    rows = []
    agents = list(dict.fromkeys(t.agent for t in trials))
    for name in dict.fromkeys(t.estimator for t in trials):
        error = {(t.agent, t.machine): _rms(t.tcp_after, "rigid")
                 for t in trials if t.estimator == name}
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
                })
    return rows


def verify_pybullet(config: Config, machines: int) -> dict[str, float]:
    """Re-run the first ``machines`` machines of ``config`` with every agent on the
    PyBullet lab in lockstep with the exact lab (the same seed, actions and, with ideal
    gauges, no rounding to tell them apart): the largest reading and TCP differences (mm)
    over every step."""
    worst = {"reading_mm": 0.0, "tcp_mm": 0.0, "steps": 0}
    for index in range(machines):
        for name in config.agents:
            agent = get_agent(name)
            kwargs = {**config.lab_kwargs(agent), "gauge_sigma": 0.0,
                      "gauge_resolution": 0.0}
            envs = gym.vector.SyncVectorEnv([
                partial(gym.make, orthoglide_env.LAB_ENV_ID, **{**kwargs, "backend": backend})
                for backend in ("exact", "pybullet")])
            seed = machine_seed(config.seed, index)
            with closing(envs):
                run_episodes(envs, [agent], [seed, seed], lockstep=True,
                             on_step=partial(_widen_gaps, worst, envs))
    return worst


def _widen_gaps(worst: dict[str, float], envs: gym.vector.SyncVectorEnv,
                observation: dict[str, np.ndarray]) -> None:
    """Widen ``worst`` to this step's reading and TCP differences between the two labs of
    ``envs``; count the step."""
    both = (observation["valid"] == 1).all(axis=0)
    gap = np.abs(observation["gauges"][0] - observation["gauges"][1])[both]
    tcp = [env.unwrapped.tcp() for env in envs.envs]
    worst["reading_mm"] = max(worst["reading_mm"], float(gap.max(initial=0)))
    worst["tcp_mm"] = max(worst["tcp_mm"], float(np.abs(tcp[0] - tcp[1]).max()))
    worst["steps"] += 1
