"""An agent by its name: a registered one, ``policy:PATH`` (a learned policy's file), or
either with ``+reference`` (the length reference's procedure after it)."""

from __future__ import annotations

from calibrators.agents.base import AGENT_REGISTRY, Agent
from calibrators.agents.reference import REFERENCE_SUFFIX, with_reference

#: ``get_agent(POLICY_PREFIX + path)`` plays the learned policy saved in ``path``.
POLICY_PREFIX: str = "policy:"


def get_agent(name: str) -> Agent:
    """A new agent: one registered by ``name``, or ``policy:PATH``, the learned policy saved
    in the file PATH (:mod:`calibrators.agents.policy`); either with ``+reference``, followed
    by the length reference's procedure (:mod:`calibrators.agents.reference`)."""
    if name.endswith(REFERENCE_SUFFIX) and len(name) > len(REFERENCE_SUFFIX):
        return with_reference(get_agent(name[:-len(REFERENCE_SUFFIX)]))
    if name.startswith(POLICY_PREFIX):
        # Imported when a policy plays: its views and beliefs are not the other agents'.
        from calibrators.agents.policy import policy_agent

        return policy_agent(name[len(POLICY_PREFIX):])
    return AGENT_REGISTRY.get(name)
