"""A flat view of the lab env, for learners that take one Box of actions and observations.

``OrthoglideLab-v0`` acts with a ``Dict`` (an operation, joint targets, a stand and a
slot).  :class:`FlatLabActions` turns one ``Box(-1, 1)`` vector into that action: the
first three components scale to the joint range, and the arg-max of each following block
picks the operation, the stand and the slot.  With Gymnasium's ``FlattenObservation`` the
observation becomes one vector too; ``OrthoglideLabFlat-v0`` is the lab env with both, so
a stable-baselines3 ``PPO("MlpPolicy", "OrthoglideLabFlat-v0")`` trains on it as it is.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.wrappers import FlattenObservation


class FlatLabActions(gym.ActionWrapper):
    """``Box(-1, 1, (3 + ops + stands + slots,))`` actions for the lab env's ``Dict``."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.action_space = flat_action_space(env.action_space)

    def action(self, action: np.ndarray) -> dict[str, Any]:
        return lab_action(self.env.action_space, action)


def flat_action_space(lab_actions: spaces.Dict) -> spaces.Box:
    """The flat Box of the lab's ``Dict`` action space."""
    sizes = (int(lab_actions["op"].n), int(lab_actions["stand"].n), int(lab_actions["slot"].n))
    return spaces.Box(-1.0, 1.0, shape=(3 + sum(sizes),), dtype=np.float32)


def lab_action(lab_actions: spaces.Dict, action: np.ndarray) -> dict[str, Any]:
    """The lab action (of space ``lab_actions``) that a flat one stands for."""
    sizes = (int(lab_actions["op"].n), int(lab_actions["stand"].n), int(lab_actions["slot"].n))
    action = np.asarray(action, dtype=np.float64)
    if action.shape != (3 + sum(sizes),) or not np.all(np.isfinite(action)):
        raise ValueError(f"a flat lab action is {3 + sum(sizes)} finite numbers")
    action = np.clip(action, -1.0, 1.0)
    # The joint targets span the rho Box, the machine design's control limits.
    low, high = lab_actions["rho"].low, lab_actions["rho"].high
    middle, half = (high + low) / 2, (high - low) / 2
    blocks = np.split(action[3:], np.cumsum(sizes)[:-1])
    op, stand, slot = (int(np.argmax(b)) for b in blocks)
    return {"op": op, "rho": middle + half * action[:3], "stand": stand, "slot": slot}


def flat_lab_env(**kwargs: Any) -> gym.Env:
    """``OrthoglideLab-v0`` with flat actions and observations (``kwargs``: the lab env's)."""
    from orthoglide_env.envs.lab import OrthoglideLabEnv

    return FlattenObservation(FlatLabActions(OrthoglideLabEnv(**kwargs)))
