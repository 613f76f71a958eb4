"""Running an agent in the lab, and what its estimators make of the notebook.

An experiment is an agent's episode in ``OrthoglideLab-v0``; its result is the lab
notebook (``env.unwrapped.records``) as :class:`~calibrators.measurements.Measurements`,
which any estimator reads exactly as it reads a measurement file.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from calibrators.agents import Agent, get_agent
from calibrators.agents.base import PlannedAgent
from calibrators.estimators.base import Estimate, get_strategy
from calibrators.measurements import Measurement, Measurements
from orthoglide_env.envs.lab import Record
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import PAPER_POSTURES, paper_posture

#: Paper postures by their control coordinates, to label the notebook's readings.
_PAPER_RHO: dict[tuple[float, ...], str] = {
    tuple(float(v) for v in paper_posture(p)): p for p in PAPER_POSTURES}


def measurements_of(records: list[Record], time_s: float = 0.0,
                    until_s: float | None = None, design: MachineDesign = PROTOTYPE
                    ) -> Measurements:
    """The notebook as measurements (only what was read by ``until_s`` seconds, if given)
    of a machine of ``design``.  A reading at a paper posture of the prototype is labelled
    with its name (a measurement file's paper postures are the prototype's)."""
    labels = _PAPER_RHO if design == PROTOTYPE else {}
    items = [Measurement.recorded(r.spec, labels.get(r.rho, ""), r.reading, r.rho, r.mounting)
             for r in records if until_s is None or r.time_s <= until_s]
    return Measurements(items, time_s if until_s is None else min(time_s, until_s), design)


@dataclass(frozen=True)
class EstimatorSpec:
    """An estimator of the comparison: a strategy's estimate with its options."""

    strategy: str
    params: str
    prior: str = "auto"


#: The estimators ``compare`` offers, by name.
ESTIMATORS: dict[str, EstimatorSpec] = {
    "paper": EstimatorSpec("paper", "paper6", "none"),
    "paper6": EstimatorSpec("gauss-newton", "paper6", "none"),
    "extended": EstimatorSpec("gauss-newton", "extended", "auto"),
    "extended-base": EstimatorSpec("gauss-newton", "extended", "none"),
}


def get_estimator(name: str) -> EstimatorSpec:
    if name not in ESTIMATORS:
        raise ValueError(f"unknown estimator '{name}'; choose from {list(ESTIMATORS)}")
    return ESTIMATORS[name]


def estimate(data: Measurements, name: str, sigma: float) -> Estimate:
    """Estimate with the named estimator of :data:`ESTIMATORS`."""
    spec = get_estimator(name)
    return get_strategy(spec.strategy).estimate(data, spec.params, sigma, verify=False,
                                                prior=spec.prior)


def estimate_many(datas: list[Measurements], name: str, sigma: float
                  ) -> list[Estimate | Exception]:
    """:func:`estimate` of many experiments, batched where the estimator can (experiments
    of one design are fitted together, without the words on what the data determine); a
    failure comes back in place of its estimate."""
    spec = get_estimator(name)
    strategy = get_strategy(spec.strategy)
    if hasattr(strategy, "estimate_many"):
        # A comparison scores estimates; it has no reader for their words.
        return strategy.estimate_many(datas, spec.params, sigma, verify=False,
                                      prior=spec.prior, explain=False)
    out: list[Estimate | Exception] = []
    for data in datas:
        try:
            out.append(strategy.estimate(data, spec.params, sigma, verify=False,
                                         prior=spec.prior))
        except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
            out.append(exc)
    return out


def make_estimator(name: str = "extended", design: MachineDesign = PROTOTYPE
                   ) -> Callable[[list[Record], float], MachineParams]:
    """The lab env's ``estimator`` for its accuracy reward: notebook and sigma to the
    estimated machine (of ``design``)."""
    get_estimator(name)

    def estimator(records: list[Record], sigma: float) -> MachineParams:
        return estimate(measurements_of(records, design=design), name, sigma).machine

    return estimator


@dataclass(frozen=True)
class Episode:
    """What an agent left in one lab: the notebook, the time used, and (for scoring only)
    the machine's truth."""

    records: list[Record]
    time_s: float
    sigma: float  # effective noise of a gauge reading (mm)
    truth: MachineParams


def run_episodes(envs: gym.vector.VectorEnv, agent: str, seeds: list[int],
                 rngs: list[np.random.Generator]) -> list[Episode]:
    """One episode of the named agent in each env of a lab vector env (autoreset
    ``NEXT_STEP``), env ``i`` reset with ``seeds[i]``: each env has its own agent, which
    acts on its own observation with ``rngs[i]``, exactly as :func:`run_episode` runs it
    in a lone lab.  An env whose episode has ended is kept busy with lever flicks (never
    refused: stand 0 is always mounted) until every episode has ended."""
    lab = envs.unwrapped
    observation, info = envs.reset(seed=list(seeds))
    agents = [get_agent(agent) for _ in seeds]
    for i, (one, rng) in enumerate(zip(agents, rngs, strict=True)):
        one.reset(lab.sub_env(i), _row(observation, i), rng)
    idle = {"op": int(Op.LIFT), "rho": np.zeros(3), "stand": 0, "slot": 0}
    # Plans decided at reset are played as arrays, every machine's step t at once.
    plans = (_plan_arrays([a.plan for a in agents], idle)  # type: ignore[attr-defined]
             if all(type(a).act is PlannedAgent.act for a in agents) else None)
    out: list[Episode | None] = [None] * len(seeds)
    step = 0
    while True:
        if plans is not None:
            if step >= len(plans["op"][0]):
                raise RuntimeError(f"agent '{agent}' ran out of plan before its episode ended")
            actions = {key: value[:, step] for key, value in plans.items()}
        else:
            moves = [idle if out[i] is not None else agents[i].act(_row(observation, i),
                                                                   _InfoRow(info, i))
                     for i in range(len(seeds))]
            actions = {key: np.array([m[key] for m in moves]) for key in idle}
        observation, _, terminated, truncated, info = envs.step(actions)
        step += 1
        for i in np.flatnonzero(terminated | truncated):
            if out[i] is None:
                out[i] = Episode(list(lab.records[i]), float(observation["time"][i, 0]),
                                 lab.noise.effective_sigma, lab.true_machines[i])
        if all(e is not None for e in out):
            return out  # type: ignore[return-value]


def _plan_arrays(plans: list[list[dict[str, Any]]], idle: dict[str, Any]
                 ) -> dict[str, np.ndarray]:
    """Every machine's plan as arrays ``(machines, steps, ...)`` per action field, a short
    plan padded with ``idle`` (what an ended episode is kept busy with)."""
    length = max(len(plan) for plan in plans)
    return {key: np.array([[a[key] for a in plan] + [idle[key]] * (length - len(plan))
                           for plan in plans]) for key in idle}


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


def run_episode(env: gym.Env, agent: Agent, seed: int, rng: np.random.Generator | None = None,
                options: dict | None = None) -> tuple[Measurements, dict]:
    """Reset ``env`` with ``seed`` (and ``options``), let ``agent`` work until the episode
    ends, and return the notebook as measurements and the last step's info."""
    observation, info = env.reset(seed=seed, options=options)
    agent.reset(env, observation, rng if rng is not None else np.random.default_rng(seed))
    while True:
        observation, _, terminated, truncated, info = env.step(agent.act(observation, info))
        if terminated or truncated:
            break
    lab = env.unwrapped
    return measurements_of(lab.records, float(observation["time"][0]),
                           design=lab.design), info
