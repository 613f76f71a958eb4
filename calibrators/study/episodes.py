"""The one agent <-> lab episode loop, and the notebook it leaves as measurements.

An experiment is an agent's episode in ``OrthoglideLab-v0``; its result is the lab
notebook (``env.unwrapped.records``) as :class:`~calibrators.measurements.Measurements`,
which any estimator reads exactly as it reads a measurement file.  :func:`run_episodes`
is the one episode runner: on a lab vector env (many machines stepped together) or, by
:func:`run_episode`, on a lone lab as a batch of one; a :class:`Watcher` sees each step
before the agent does (the workflow's plan writes its steps down, its session asks for
the readings).  Every command draws machine ``i`` of seed ``s`` from :func:`machine_seed`
and its agent's choices from :func:`agent_rng`, so ``calibrate --seed s`` runs the
experiment of ``compare --seed s``'s first machine.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from calibrators.agents import Agent
from calibrators.agents.base import LabRows, PlannedAgent

# The catalogue moved to calibrators.estimators.catalogue; its names stay here for
# earlier scripts.
from calibrators.estimators.catalogue import CATALOGUE as ESTIMATORS  # noqa: F401
from calibrators.estimators.catalogue import estimate as estimate
from calibrators.estimators.catalogue import estimate_many as estimate_many
from calibrators.estimators.catalogue import for_study, get_estimator
from calibrators.measurements import ZERO_RHO, Measurement, Measurements, paper_rhos
from orthoglide_env.envs.lab import Record
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S as DEFAULT_BUDGET_S  # every command's
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.world.truth import World


def measurements_of(records: list[Record], time_s: float = 0.0,
                    until_s: float | None = None, *, design: MachineDesign
                    ) -> Measurements:
    """The notebook as measurements (only what was read by ``until_s`` seconds, if given)
    of a machine of ``design``.  A reading at a paper posture of ``design`` is labelled
    with its name (a measurement file's paper postures are its design's); each Zero
    reading of a mounting opens its next repetition (the file format's meaning), so the
    paper's procedure is numbered as the paper numbers it."""
    kept = records if until_s is None else [r for r in records if r.time_s <= until_s]
    return NotebookReadings(design).of(kept, time_s if until_s is None else min(time_s,
                                                                                 until_s))


class NotebookReadings:
    """:func:`measurements_of` a notebook that grows, each record converted once: an agent
    that refits its whole notebook every few minutes of lab time (``active``) converted
    every earlier record again at each refit, 2 % of its sweep's CPU."""

    def __init__(self, design: MachineDesign) -> None:
        self.design = design
        self._labels = {rho: name for name, rho in paper_rhos(design).items()}
        self._zeros: dict[str, int] = {}  # Zero readings so far, by mounting
        self._items: list[Measurement] = []
        self._last: Record | None = None

    def of(self, records: list[Record], time_s: float = 0.0) -> Measurements:
        """The measurements of ``records``, the notebook this reader has read so far
        grown by any records since, at experiment time ``time_s``."""
        done = len(self._items)
        if done and (len(records) < done or records[done - 1] is not self._last):
            raise ValueError("a notebook's readings are of the notebook they have read, "
                             "grown by later records only")
        labels, zeros, items = self._labels, self._zeros, self._items
        recorded = Measurement.recorded
        # Each field read once per record: a sweep's notebooks hold tens of thousands.
        for r in records[done:]:
            rho, mounting = r.rho, r.mounting
            if rho == ZERO_RHO:
                repetition = zeros[mounting] = zeros.get(mounting, 0) + 1
            else:
                repetition = zeros.get(mounting, 0) or 1
            items.append(recorded(r.spec, labels.get(rho, ""), r.reading, rho, mounting,
                                  repetition, r.time_s, r.temperature_c))
        if len(records) > done:
            self._last = records[-1]
        return Measurements(list(self._items), time_s, self.design)


def make_estimator(name: str = "extended", design: MachineDesign = PROTOTYPE
                   ) -> Callable[[list[Record], float], MachineParams]:
    """The lab env's ``estimator`` for its accuracy reward: notebook and sigma to the
    estimated machine (of ``design``)."""
    get_estimator(name)

    def estimator(records: list[Record], sigma: float) -> MachineParams:
        return for_study(name, sigma).fit(measurements_of(records, design=design)).machine

    return estimator


def machine_seed(seed: int, index: int) -> int:
    """The lab's reset seed of machine ``index`` of a run seeded ``seed``: every command
    and agent of that run works on the machine it draws."""
    return seed * 1_000_003 + index


def agent_rng(seed: int) -> np.random.Generator:
    """The stream of an agent's own choices in the episode reset with ``seed``."""
    return np.random.default_rng([seed, 1])


@dataclass(frozen=True)
class Episode:
    """What an agent left in one lab: the notebook, the time used, the last step's info,
    and (for scoring only) the machine's truth."""

    records: list[Record]
    time_s: float
    sigma: float  # effective noise of a gauge reading (mm)
    truth: MachineParams
    info: dict[str, Any]
    world: World | None = None  # the machine's world beyond its geometry (None: ideal)
    #: The faults that happened (``FaultEvent.to_dict``; none in a lab without faults).
    faults: list[dict[str, Any]] = field(default_factory=list)

    @property
    def measurements(self) -> Measurements:
        """The notebook as an estimator reads it."""
        return measurements_of(self.records, self.time_s, design=self.truth.design)


class Watcher(Protocol):
    """What sees each lab of :func:`run_episodes` between its steps, before its agent
    does: it may change the observation (in place) and the lab's notebook, as a person
    typing in a real machine's readings does."""

    def reset(self, i: int, observation: dict[str, np.ndarray]) -> None:
        """Env ``i`` was reset to ``observation``; its agent has not seen it yet."""

    def step(self, i: int, action: Mapping[str, Any], observation: dict[str, np.ndarray],
             info: Mapping[str, Any]) -> None:
        """Env ``i`` took ``action`` and shows ``observation`` and ``info`` (every step
        until its episode ends, that step included)."""


def run_episodes(envs: gym.vector.VectorEnv, agents: list[Agent], seeds: list[int],
                 options: dict | None = None, *, lockstep: bool = False,
                 on_step: Callable[[dict[str, np.ndarray]], None] | None = None,
                 watch: Watcher | None = None) -> list[Episode]:
    """One episode in each env of a lab vector env (autoreset ``NEXT_STEP``; the native
    one, or ``SyncVectorEnv`` of lone labs), env ``i`` reset with ``seeds[i]`` (and
    ``options``) and worked by ``agents[i]``, which acts on its own observation with
    :func:`agent_rng` of its seed.  ``lockstep``: ``agents[0]`` alone decides, on env 0's
    observation, and every env takes its action (labs compared step by step).
    ``on_step`` sees every step's observations; ``watch`` sees each lab's reset and steps
    (:class:`Watcher`).  An env whose episode has ended is kept busy with lever flicks
    (never refused: stand 0 is always mounted) until every episode has ended."""
    if len(agents) != (1 if lockstep else len(seeds)):
        raise ValueError(f"{len(agents)} agents for {len(seeds)} labs"
                         + (" in lockstep (one decides)" if lockstep else ""))
    observation, info = envs.reset(seed=list(seeds), options=options)
    labs = _labs(envs)
    if watch is not None:
        for i in range(len(seeds)):
            watch.reset(i, _row(observation, i))
    for i, agent in enumerate(agents):
        agent.reset(labs[i], _row(observation, i), agent_rng(seeds[i]))
    idle = {"op": int(Op.LIFT), "rho": np.zeros(3), "stand": 0, "slot": 0}
    for key, default in (("axis", 0), ("bar", 0), ("laser", 1)):
        if key in envs.single_action_space.spaces:
            # OrthoglideLab-v1's and -v2's: only an align (a pivot) uses it, and an
            # agent's other actions leave it out; -v4's laser left out reads the laser, as
            # every move of the earlier versions does.
            idle[key] = default
    # Plans decided at reset are played as arrays, every machine's step t at once.
    plans = (_plan_arrays([a.plan for a in agents], idle)  # type: ignore[attr-defined]
             if all(type(a).act is PlannedAgent.act for a in agents) else None)
    out: list[Episode | None] = [None] * len(seeds)
    step = 0
    while True:
        moves: list[Mapping[str, Any]] | None = None
        if plans is not None:
            if step >= len(plans["op"][0]):
                raise RuntimeError(f"agent '{agents[0].name}' ran out of plan before its "
                                   "episode ended")
            actions = {key: value[:, step] for key, value in plans.items()}
        else:
            running = [i for i in range(len(agents)) if out[i] is None]
            index = np.array(running, dtype=np.int64)
            acted = iter(_act_all([agents[i] for i in running],
                                  LabRows([_row(observation, i) for i in running],
                                          observation, index),
                                  LabRows([_InfoRow(info, i) for i in running], info, index)))
            moves = [idle if out[i] is not None else next(acted) for i in range(len(agents))]
            actions = {key: np.array([m.get(key, idle[key]) for m in moves])
                       for key in idle}
        if lockstep:
            actions = {key: np.repeat(value[:1], len(seeds), axis=0)
                       for key, value in actions.items()}
            moves = None
        observation, _, terminated, truncated, info = envs.step(actions)
        step += 1
        if on_step is not None:
            on_step(observation)
        if watch is not None:
            for i in (i for i in range(len(seeds)) if out[i] is None):
                # The agent's own action where it made one, else the plan's step.
                watch.step(i, moves[i] if moves is not None else _row(actions, i),
                           _row(observation, i), _InfoRow(info, i))
        for i in np.flatnonzero(terminated | truncated):
            if out[i] is None:
                lab = labs[i].unwrapped
                truth, world = _truth(envs, i)
                out[i] = Episode(list(lab.records), float(observation["time"][i, 0]),
                                 lab.noise.effective_sigma, truth, dict(_InfoRow(info, i)),
                                 world, _faults(envs, i))
        if all(e is not None for e in out):
            return out  # type: ignore[return-value]


def run_episode(env: gym.Env, agent: Agent, seed: int, options: dict | None = None,
                watch: Watcher | None = None) -> Episode:
    """:func:`run_episodes` on a lone lab ``env``, a batch of one: reset with ``seed``
    (and ``options``), worked by ``agent`` until the episode ends, seen by ``watch``."""
    return run_episodes(gym.vector.SyncVectorEnv([lambda: env]), [agent], [seed], options,
                        watch=watch)[0]


def _act_all(agents: list[Agent], observations: list[dict[str, np.ndarray]],
             infos: list[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Each agent's action, by its class's :meth:`~calibrators.agents.base.Agent.act_all`
    where all are of one class (a chunk of one strategy's machines), else one by one."""
    kind = type(agents[0]) if agents else Agent
    if not all(type(a) is kind for a in agents):
        kind = Agent
    return kind.act_all(agents, observations, infos)


def _faults(envs: gym.vector.VectorEnv, i: int) -> list[dict[str, Any]]:
    """The faults that happened in env ``i``'s episode, for scoring only."""
    if isinstance(envs, gym.vector.SyncVectorEnv):
        return envs.envs[i].unwrapped.true_faults
    return envs.unwrapped.true_faults(i)


def _labs(envs: gym.vector.VectorEnv) -> list[Any]:
    """Each env of ``envs`` as its agent sees a lone lab."""
    if isinstance(envs, gym.vector.SyncVectorEnv):
        return list(envs.envs)
    return [envs.unwrapped.sub_env(i) for i in range(envs.num_envs)]


def _truth(envs: gym.vector.VectorEnv, i: int) -> tuple[MachineParams, World | None]:
    """Env ``i``'s true machine and world (None: ideal), for scoring only."""
    if isinstance(envs, gym.vector.SyncVectorEnv):
        lab = envs.envs[i].unwrapped
        return lab.true_machine, lab.true_world
    worlds = envs.unwrapped.true_worlds
    return envs.unwrapped.true_machines[i], None if worlds is None else worlds[i]


def _plan_arrays(plans: list[list[dict[str, Any]]], idle: dict[str, Any]
                 ) -> dict[str, np.ndarray]:
    """Every machine's plan as arrays ``(machines, steps, ...)`` per action field, a short
    plan padded with ``idle`` (what an ended episode is kept busy with)."""
    length = max(len(plan) for plan in plans)
    return {key: np.array([[a.get(key, idle[key]) for a in plan]
                           + [idle[key]] * (length - len(plan)) for plan in plans])
            for key in idle}


def _row(observation: dict[str, np.ndarray], i: int) -> dict[str, np.ndarray]:
    """Env ``i``'s observation of a vector env's."""
    return {key: value[i] for key, value in observation.items()}


class _InfoRow(Mapping[str, Any]):
    """Env ``i``'s info of a vector env's (Gymnasium's vector form: an array and a mask
    per key), read only where an agent reads it."""

    def __init__(self, info: dict[str, Any], i: int) -> None:
        self._info, self._i = info, i

    def __getitem__(self, key: str) -> Any:
        if key.startswith("_") or not self._info[f"_{key}"][self._i]:
            raise KeyError(key)
        return self._info[key][self._i]

    def __iter__(self) -> Iterator[str]:
        return (k for k in self._info if not k.startswith("_") and self._info[f"_{k}"][self._i])

    def __len__(self) -> int:
        return sum(1 for _ in self)
