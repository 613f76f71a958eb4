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

from collections.abc import Callable
from contextlib import closing
from dataclasses import dataclass, field
from functools import cache, partial
from typing import TYPE_CHECKING, Any, NamedTuple

import gymnasium as gym
import numpy as np

from calibrators.agents import Agent, get_agent
from calibrators.agents.names import POLICY_PREFIX
from calibrators.estimators.base import Estimate
from calibrators.estimators.catalogue import for_study, get_estimator
from calibrators.estimators.prediction import predicted_rigid_mm
from calibrators.estimators.world_sizes import DETERMINED
from calibrators.study.engines import results
from calibrators.study.episodes import (
    DEFAULT_BUDGET_S,
    Episode,
    agent_rng,
    machine_seed,
    measurements_of,
    run_episode,
    run_episodes,
)
from calibrators.study.labs import lab_id, lab_kwargs
from calibrators.study.trials import Trial
from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    GaugeNoise,
    weighting_sigma,
)
from orthoglide_env.lab.operations import PAPER_SLOTS
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import DEFAULT_PRESET, ERROR_NAMES, MachineParams
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring import (
    FRAMES,
    ScoreReport,
    commands_many,
    score_batch,
    uncalibrated_errors,
    workspace_grid,
)
from orthoglide_env.scoring.grid import blocks
from orthoglide_env.world.conditions import DEFAULT_CONDITIONS, Conditions
from orthoglide_env.world.faults import NO_FAULTS, Faults, happened
from orthoglide_env.world.truth import World

if TYPE_CHECKING:
    from calibrators.planning.bound import Bound

#: The statistics that lived here (:mod:`calibrators.study.statistics`), which scripts
#: import from this module still (:func:`__getattr__`).
_STATISTICS: frozenset[str] = frozenset(
    ("MIN_INTERVAL", "median_interval", "paired", "summary", "warning_kind"))


def __getattr__(name: str) -> Any:
    """The statistics of :data:`_STATISTICS`, imported at their first use: a sweep's
    processes compute none, and SciPy's special functions, which they load, cost each
    process a third of its start-up."""
    if name in _STATISTICS:
        from calibrators.study import statistics

        return getattr(statistics, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

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
    conditions: Conditions = field(default_factory=lambda: Conditions(DEFAULT_CONDITIONS))
    #: The lab has a room thermometer.
    thermometer: bool = False
    #: What the lab owns (empty: today's lab, see :func:`~calibrators.study.labs.
    #: lab_kwargs`).
    instruments: tuple[str, ...] = ()
    #: What can go wrong in the lab (orthoglide_env.world.faults).
    faults: Faults = NO_FAULTS
    #: The world the fits are told, when not ``conditions``: other conditions, or
    #: ``"auto"``, which has the fit estimate it from the readings.
    fit_conditions: Conditions | str | None = None
    #: The fits test whether the readings show a world worse than the one they were told
    #: (a warning of kind ``world``).
    world_check: bool = False
    #: The rows carry the bound any plan of the lab's instruments and budget must respect
    #: (``bound_mm``, :func:`study_bound`).
    bound: bool = False

    @property
    def told(self) -> Conditions | str:
        """The world the fits are told."""
        return self.conditions if self.fit_conditions is None else self.fit_conditions

    @property
    def world(self) -> str:
        """The world the comparison's numbers hold in, in words, as every output names it:
        the error preset, the conditions (and their effects when not all act), the
        thermometer, the gauges' sigma, the budget, the back-end and a custom design."""
        design = "" if self.design == PROTOTYPE else f", design L {self.design.L:g} mm"
        told = ("" if self.fit_conditions is None else
                f" (the fit told {getattr(self.told, 'label', self.told)})")
        owned = f", instruments {'+'.join(self.instruments)}" if self.instruments else ""
        faults = f", faults {self.faults.label}" if self.faults.active else ""
        return (f"{self.errors} errors, {self.conditions.label} conditions{told}"
                f"{', a thermometer' if self.thermometer else ''}{owned}, gauge sigma "
                f"{self.sigma} mm, "
                f"budget {self.budget_s:g} s, {self.backend} backend{design}{faults}")

    def lab_kwargs(self, agent: Agent) -> dict[str, Any]:
        """The lab env's arguments of this comparison for ``agent`` (with the tracker or
        the gauge block when it needs one)."""
        return lab_kwargs(agent, errors=self.errors, gauge_sigma=self.sigma,
                          gauge_resolution=self.resolution, backend=self.backend,
                          budget_s=self.budget_s, design=self.design,
                          conditions=self.conditions, thermometer=self.thermometer,
                          instruments=self.instruments,
                          **({"faults": self.faults} if self.faults.active else {}))


def study_bound(config: Config, machine: MachineParams | None = None,
                installed: np.ndarray | None = None) -> Bound:
    """The bound (:func:`calibrators.planning.bound.lower_bound`) of the comparison's lab:
    its design, world, dials (their weighting sigma), stands, instruments and budget,
    the same for every machine; with ``machine`` (and its stands' ``installed``
    parameters), the bound linearised at that machine (a yardstick read off the truth,
    ``benchmarks/machine_bound.py``)."""
    # Imported here: the bound (and scipy.linalg) is for runs that ask for it.
    from calibrators.planning.bound import lower_bound

    noise = GaugeNoise(config.sigma, config.resolution)
    return lower_bound(config.design, config.conditions,
                       float(weighting_sigma(noise.effective_sigma)), config.budget_s,
                       config.instruments or ("dial",), len(PAPER_SLOTS),
                       machine=machine, installed=installed)


@cache
def _machine_scales() -> np.ndarray:
    """The default scale of each of the 27 machine errors."""
    return default_scales(ParameterSpace())


@cache
def _machine_columns(names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Which of an estimate's parameters ``names`` are machine errors, and their places in
    :data:`~orthoglide_env.model.errors.ERROR_NAMES`, found once per parameter set and
    read-only (every caller shares them)."""
    idx = np.array([k for k, name in enumerate(names) if name in ERROR_NAMES], dtype=int)
    places = np.array([ERROR_NAMES.index(names[k]) for k in idx], dtype=int)
    for array in (idx, places):
        array.setflags(write=False)
    return idx, places


def machine_z_scores(ests: list[Estimate], truths: list[MachineParams],
                     truth_vectors: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """(estimate - truth) / reported std of each estimate, along the combinations of the
    fitted machine errors whose reported variance is at most half their a-priori size (the
    data know them better than the prior): standard normal for honest error bars.  Only
    machine errors: an instrument's nuisances (stands, a tracker's frame) have no truth the
    comparison could hold them to in every lab.  The eigen-decompositions of estimates
    over the same parameters run in one call.  ``truth_vectors``: the truths'
    :meth:`~orthoglide_env.model.errors.MachineParams.to_vector`, when the caller has them."""
    out: list[np.ndarray] = [np.zeros(0)] * len(ests)
    n = len(ERROR_NAMES)
    truth_vectors = [t.to_vector() for t in truths] if truth_vectors is None else truth_vectors
    groups: dict[tuple[str, ...], list[int]] = {}
    for k, est in enumerate(ests):
        groups.setdefault(tuple(est.names), []).append(k)
    for names, members in groups.items():
        idx, machine = _machine_columns(names)
        scale = _machine_scales()[machine]
        # The group's covariances, thetas and truths stacked, then taken from once each
        # (into C order, the layout the products below were given machine by machine).
        cov = np.take(np.take(np.stack([ests[m].covariance for m in members]), idx, axis=1),
                      idx, axis=2) / np.outer(scale, scale)
        err = (np.take(np.stack([ests[m].theta[:n] for m in members]), machine, axis=1)
               - np.take(np.stack([truth_vectors[m] for m in members]), machine, axis=1)
               ) / scale
        values, vectors = np.linalg.eigh(cov)
        # Along an eigenvector the reported variance is its eigenvalue.
        along = (np.swapaxes(vectors, -1, -2) @ err[..., None])[..., 0]
        for m, value, z in zip(members, values, along, strict=True):
            known = value <= DETERMINED
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
    truth_vectors = [e.run.truth.to_vector() for e in episodes]
    z_scores = iter(machine_z_scores(fitted, [episodes[k].run.truth for k in good],  # type: ignore[arg-type]
                                     [truth_vectors[k] for k in good]))
    batch, machines = _machines(episodes, estimates)
    # The estimated machines' commands over the grid, which the scoring and the predicted
    # error both start from, solved once.
    grid = workspace_grid(design=episodes[0].run.truth.design)
    commands = np.concatenate([commands_many(machines[b], grid, batch[b])
                               for b in blocks(len(machines))])
    reports = iter(_score(episodes, estimates, machines, commands))
    predicted = iter(predicted_rigid_mm(fitted, [machines[k] for k in good],  # type: ignore[arg-type]
                                        commands[good]).tolist() if good else [])
    out = []
    for episode, est, curve, truth in zip(episodes, estimates, curves, truth_vectors,
                                          strict=True):
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
        idx, machine = _machine_columns(tuple(est.names))
        std[machine] = np.sqrt(np.diagonal(est.covariance)[idx])
        out.append(Trial(
            episode.agent, name, episode.machine, time_s=run.time_s, readings=count,
            faults=happened(run.faults),
            predicted_rigid_mm=next(predicted), chi2_rejected=est.chi2_rejected,
            z=next(z_scores).tolist(),
            error=(est.theta[:len(ERROR_NAMES)] - truth).tolist(),
            std=std.tolist(), curve=curve, warnings=list(est.warnings), **scored,
        ))
    return out


def scored_trials(episodes: list[_Episode], name: str,
                  estimates: list[Estimate | Exception]) -> list[Trial]:
    """The trials of ``estimates`` (estimator ``name``'s fits of the whole ``episodes``),
    scored as a comparison scores them, without accuracy curves: for studies that fit one
    agent's readings several ways."""
    return _trials(episodes, name, estimates, [[] for _ in episodes])


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
            name, episodes[0].run.sigma, config.told, config.errors,
            config.world_check).fit_many(datas)
        for k, (episode, report) in enumerate(zip(episodes, _score(episodes, fitted),
                                                  strict=True)):
            points[k].append([fraction * episode.run.time_s, report.tcp_after.rigid.rms])
    return points


def _machines(episodes: list[_Episode], estimates: list[Estimate | Exception]
              ) -> tuple[MachineParams, list[MachineParams]]:
    """Each estimate's machine (:attr:`~calibrators.estimators.base.Estimate.machine`),
    the nominal machine for a failed estimate, as one batch of the episodes' design and
    as its rows: made and checked from their vectors at once, where a machine made and
    checked per estimate cost a sweep 1.5 % of its time."""
    n = len(ERROR_NAMES)
    vectors = np.zeros((len(estimates), n))
    for k, est in enumerate(estimates):
        if not isinstance(est, Exception):
            vectors[k] = est.theta[:n]
    batch = MachineParams.from_vector(vectors, episodes[0].run.truth.design)
    return batch, [batch[k] for k in range(len(estimates))]


def _score(episodes: list[_Episode], estimates: list[Estimate | Exception],
           machines: list[MachineParams] | None = None, commands: np.ndarray | None = None
           ) -> list[ScoreReport]:
    """Each estimate's machine (``machines``: :func:`_machines`, and ``commands`` their
    commands over the scoring grid, when the caller has them), with what its controller
    compensates of the drives' lead error, scored against its episode's truth in one
    batched solve; a failed estimate is scored as the nominal machine."""
    machines = _machines(episodes, estimates)[1] if machines is None else machines
    corrections = [est.lead_correction if isinstance(est, Estimate) and est.fits_lead else None
                   for est in estimates]
    return score_batch(machines, [e.run.truth for e in episodes], before=_before(episodes),
                       worlds=_worlds(episodes), corrections=corrections, commands=commands)


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
              batched: bool = True, start: StartUp | None = None) -> list[Trial]:
    """Machines ``indices``: every agent's episode on each, then every estimator over all
    of an agent's notebooks at once (a fixed design is fitted in one batched solve).
    ``batched``: the episodes of an agent run together in the lab's native vector env (on
    the exact backend); else one machine at a time in a lone lab, step by step (the
    reference path, same numbers).  ``start``: what the agents would make at their
    start, made already (:func:`shared_start`)."""
    if start is not None:
        # Only a sweep of planning agents is handed a start, and only it needs the planner.
        from calibrators.agents.optimal import handed_plans
        from orthoglide_env.lab.slot_table import handed_tables
        handed_plans(start.plans)
        handed_tables(start.tables)
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
            estimates = for_study(name, mine[0].run.sigma, config.told, config.errors,
                                  config.world_check).fit_many(
                [e.run.measurements for e in mine])
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
    if agent_name.startswith(POLICY_PREFIX):
        # Registers the filters that policy files of flicks "filter", "shortlist" and
        # "ranked" play their moves with (the short list's module imports the filter's);
        # only a policy needs the planner they bring.
        import calibrators.planning.shortlist  # noqa: F401
    kwargs = config.lab_kwargs(get_agent(agent_name))
    if batched and config.backend == "exact":
        with closing(gym.make_vec(lab_id(kwargs), num_envs=len(runs),
                                  vectorization_mode="vector_entry_point", **kwargs)) as envs:
            done = run_episodes(envs, [get_agent(agent_name) for _ in runs], seeds)
    else:
        with closing(gym.make(lab_id(kwargs), **kwargs)) as env:
            done = [run_episode(env, get_agent(agent_name), seed) for seed in seeds]
    return [_Episode(agent_name, index, e) for index, e in zip(runs, done, strict=True)]


class StartUp(NamedTuple):
    """What each process of a sweep would make before its first machine, made once
    (:func:`shared_start`)."""

    #: The planning agents' plans (:func:`~calibrators.agents.optimal.made_plans`).
    plans: dict[tuple, Any]
    #: The slot tables they plan on (:func:`~orthoglide_env.lab.slot_table.made_tables`).
    tables: dict[MachineDesign, Any]


def _planners(config: Config) -> list[Agent]:
    """The comparison's agents that make a plan of the lab's set-up at reset
    (:attr:`~calibrators.agents.base.Agent.shares_a_plan`)."""
    return [agent for agent in map(get_agent, config.agents) if agent.shares_a_plan]


def shared_start(config: Config, machine: int, processes: int) -> StartUp:
    """The plans of the lab's set-up that the comparison's agents make at reset
    (:attr:`~calibrators.agents.base.Agent.shares_a_plan`), each made once here on
    ``machine``'s lab, its re-mounts screened over ``processes`` processes
    (:func:`~calibrators.planning.search.screening_over`): what each worker would make
    alone, by all of the set-up's arguments (:func:`~calibrators.agents.optimal.
    made_plans`); and the slot tables they were made on.  Nothing when no agent shares
    a plan."""
    planners = _planners(config)
    if not planners:
        return StartUp({}, {})
    # The planner is imported only by a comparison with an agent that plans.
    from calibrators.agents.optimal import made_plans
    from calibrators.planning.search import screening_over
    from orthoglide_env.lab.slot_table import made_tables
    seed = machine_seed(config.seed, machine)
    with screening_over(processes):
        for agent in planners:
            kwargs = config.lab_kwargs(agent)
            with closing(gym.make(lab_id(kwargs), **kwargs)) as env:
                observation, _ = env.reset(seed=seed)
                agent.reset(env, observation, agent_rng(seed))
    return StartUp(made_plans(), made_tables())


def _started_chunk(config: Config, skip: set[tuple[str, str, int]], start: StartUp,
                   indices: list[int]) -> list[Trial]:
    """:func:`run_chunk` of ``indices`` handed ``start``, in the order a sweep's engine
    calls it (:func:`~calibrators.study.engines.results`' ``prepare``: what was made
    first, then the item)."""
    return run_chunk(config, indices, skip, start=start)


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
    trial as it ends, ``progress`` the number of machines finished that had no trial in
    ``done`` (a bar that starts at those which had one ends at ``machines``).  Trials come
    back in
    (machine, agent, estimator) order, the same whatever ``jobs``, ``engine`` and
    ``chunk``: a machine's fits are those it gets alone.  A
    KeyboardInterrupt (or another exception raised here, as the command line's SIGTERM
    handler raises one) stops the workers at once and is raised again, every trial
    finished so far having gone to ``on_trial``."""
    for name in config.agents:
        get_agent(name)
    for name in config.estimators:
        get_estimator(name)
    if not (isinstance(chunk, int) and chunk >= 1):
        raise ValueError(f"chunk must be a whole number of machines >= 1, got {chunk!r}")
    done = list(done or [])
    skip = {t.key for t in done}
    begun = {t.machine for t in done}
    # Every worker gets work even on short runs.
    size = max(1, min(chunk, -(-machines // jobs)))
    chunks = [list(range(i, min(i + size, machines))) for i in range(0, machines, size)]
    trials = list(done)
    # Each worker would make the agents' shared plans and their slot tables (seconds of a
    # core each): made once instead, on the first worker while the others start, the
    # plans' screening spread over the cores they all take; in a worker, whose BLAS runs
    # on one thread: beside the screening's forks, this process's own threads spent three
    # times the CPU and wall time (17 CPU-s against 51 for the one-hour ``lab`` plan on 2
    # cores).
    shared = jobs > 1 and len(chunks) > 1 and bool(_planners(config))
    with closing(results(partial(_started_chunk, config, skip) if shared
                         else partial(run_chunk, config, skip=skip), chunks, jobs, engine,
                         address, prepare=partial(shared_start, config, chunks[0][0], jobs)
                         if shared else None)) as finished:
        for chunk, new in finished:
            for trial in new:
                trials.append(trial)
                if on_trial:
                    on_trial(trial)
            if progress:
                progress(sum(i not in begun for i in chunk))
    order = {(a, e): k for k, (a, e) in enumerate(
        (a, e) for a in config.agents for e in config.estimators)}
    return sorted(trials, key=lambda t: (t.machine, order.get((t.agent, t.estimator), 0)))
