"""Agents: what is done in the lab, through ``OrthoglideLab-v0`` only.

An agent sees observations and the lab notebook (``env.unwrapped.records``), plans with
the nominal model if it wants, and returns actions; it never reads the machine's truth.
Agents register themselves by name (:func:`register`); a new agent is one new module in
this package.  :func:`calibrators.study.episodes.run_episodes` runs them.
"""

from __future__ import annotations

from calibrators.agents.base import AGENTS, Agent, available, register
from calibrators.agents.names import get_agent

__all__ = ["AGENTS", "Agent", "available", "get_agent", "register"]
