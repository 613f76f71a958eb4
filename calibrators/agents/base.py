"""The agent interface and its registry."""

from __future__ import annotations

import importlib
import pkgutil
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from orthoglide_env.lab import Op


class Agent:
    """Base class: ``reset`` once per episode (after the env's reset), then ``act`` until
    the episode ends.  ``needs_tracker``: the lab must have a laser tracker."""

    name: ClassVar[str] = ""
    needs_tracker: ClassVar[bool] = False

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        """Prepare an episode on ``env`` (reset already, ``observation`` its first
        observation); ``rng`` for the agent's own choices."""
        self.env = env.unwrapped
        self.rng = rng

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        raise NotImplementedError


AGENTS: dict[str, type[Agent]] = {}


def register(cls: type[Agent]) -> type[Agent]:
    """Class decorator: make an agent available by its ``name``."""
    if not cls.name or cls.name in AGENTS:
        raise ValueError(f"agent name '{cls.name}' is empty or taken")
    AGENTS[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names of every agent (imports each module of this package once)."""
    package = importlib.import_module("calibrators.agents")
    for module in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"calibrators.agents.{module.name}")
    return sorted(AGENTS)


def get_agent(name: str) -> Agent:
    names = available()
    if name not in AGENTS:
        raise ValueError(f"unknown agent '{name}'; choose from {names}")
    return AGENTS[name]()


def action(op: Op, rho: np.ndarray | None = None, stand: int = 0, slot: int = 0
           ) -> dict[str, Any]:
    """An action of the lab env (unused fields at harmless values)."""
    return {"op": int(op), "rho": np.zeros(3) if rho is None else np.asarray(rho, float),
            "stand": int(stand), "slot": int(slot)}
