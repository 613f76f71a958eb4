"""The agent interface and its registry."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from calibrators.registry import Registry
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign


class Agent:
    """Base class: ``reset`` once per episode (after the env's reset), then ``act`` until
    the episode ends.  ``needs_tracker``: the lab must have a laser tracker;
    ``needs_reference``: the gauge block; ``needs_instruments``: the other instruments the
    lab must own (``interferometer``).  ``reserved_s``: seconds of the budget an agent
    that plans to the budget leaves to what follows it (:mod:`calibrators.agents.reference`).
    :meth:`check_budget` refuses a budget the agent's procedure cannot be played in."""

    name: ClassVar[str] = ""
    needs_tracker: ClassVar[bool] = False
    needs_reference: ClassVar[bool] = False
    needs_instruments: ClassVar[tuple[str, ...]] = ()
    #: Whether ``reset`` makes a plan of the lab's set-up alone, the same on every machine
    #: of a sweep (:func:`calibrators.agents.optimal.fixed_plan`): a sweep makes it once,
    #: before its workers start, and hands it to them.
    shares_a_plan: ClassVar[bool] = False
    reserved_s: float = 0.0

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        """Prepare an episode on ``env`` (reset already, ``observation`` its first
        observation); ``rng`` for the agent's own choices."""
        self.env = env.unwrapped
        self.rng = rng

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        raise NotImplementedError

    def check_budget(self, budget_s: float, design: MachineDesign, stands: int) -> None:
        """``ValueError`` in one line, naming the least budget, when ``budget_s`` seconds
        of lab time cannot hold what the agent must do on ``design`` with ``stands`` gauge
        stands; an agent that fits its experiment to any budget accepts every one."""

    @classmethod
    def act_all(cls, agents: list[Agent], observations: list[dict[str, np.ndarray]],
                infos: list[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """``act`` of each of ``agents`` (all of this class, one per lab of a chunk) on its
        own observation and info, in turn.  A class whose agents decide cheaper together
        (one network pass for the chunk) overrides it, with the same actions."""
        return [a.act(o, i) for a, o, i in zip(agents, observations, infos, strict=True)]


class LabRows(list):
    """The observations, or the infos, of labs of one vector env, lab by lab, as
    :meth:`Agent.act_all` takes them (a list of each lab's own), that also hand over the
    vector env's: ``batch``, its dict of arrays of one row per lab (its observation, or its
    info in Gymnasium's vector form, an array and a ``_key`` mask per key), and ``index``,
    each lab's row of it (int64), so that agents deciding together read a field of all
    their labs in one call instead of one per lab."""

    def __init__(self, rows: list[Any], batch: Mapping[str, np.ndarray],
                 index: np.ndarray) -> None:
        super().__init__(rows)
        self.batch, self.index = batch, index


class PlannedAgent(Agent):
    """An agent whose whole experiment is decided at reset: ``plan``, the list of actions
    :meth:`make_plan` makes of the first observation, is played in order."""

    plan: list[dict[str, Any]]

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        super().reset(env, observation, rng)
        self.plan = self.make_plan(observation)

    def make_plan(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        raise NotImplementedError

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        return self.plan.pop(0)


AGENT_REGISTRY: Registry[Agent] = Registry("agent", "calibrators.agents")
AGENTS = AGENT_REGISTRY.classes
register = AGENT_REGISTRY.register
available = AGENT_REGISTRY.available
def action(op: Op, rho: np.ndarray | None = None, stand: int = 0, slot: int = 0,
           **keys: int) -> dict[str, Any]:
    """An action of the lab env (unused fields at harmless values); ``keys``: those of a
    later version's operations (``axis`` of ``-v1``'s align, ``bar`` of ``-v2``'s pivot)."""
    return {"op": int(op), "rho": np.zeros(3) if rho is None else np.asarray(rho, float),
            "stand": int(stand), "slot": int(slot), **{k: int(v) for k, v in keys.items()}}
