"""Wrappers of the lab env for learners: a flat view, and a view of the experiment's design.

Flat view.  ``OrthoglideLab-v0`` acts with a ``Dict`` (an operation, joint targets, a
stand and a slot).  :class:`FlatLabActions` turns one ``Box(-1, 1)`` vector into that
action: the first three components scale to the joint range, and the arg-max of each
following block picks the operation, the stand and the slot.  With Gymnasium's
``FlattenObservation`` the observation becomes one vector too; ``OrthoglideLabFlat-v0`` is
the lab env with both, so a stable-baselines3 ``PPO("MlpPolicy", "OrthoglideLabFlat-v0")``
trains on it as it is.

Design view.  :class:`DesignLab` (``OrthoglideLabDesign-v0`` and ``-v1``) offers the experiment
planner's candidate operations as one ``Discrete`` action with a mask, observes what the
readings so far determine and rewards the fall of the predicted TCP error: the set-up of
amortised experiment design (a state that summarises what is known, a dense information
reward), for sb3-contrib's ``MaskablePPO`` as it is.  Its vector form is
:class:`DesignLabVector` (``gymnasium.make_vec("OrthoglideLabDesign-v0", num_envs=N)``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import SyncVectorEnv
from gymnasium.wrappers import FlattenObservation

from orthoglide_env.envs.lab import OrthoglideLabEnv
from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.lab.design_belief import VIEW_VERSIONS, DesignBelief
from orthoglide_env.lab.rewards import ACCURACY_UNIT_MM


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
    return FlattenObservation(FlatLabActions(OrthoglideLabEnv(**kwargs)))


#: The design view's rewards (``reward=``) and what they are counted per (``per=``).
DESIGN_REWARDS: tuple[str, ...] = ("mse", "log_mse")
DESIGN_PER: tuple[str, ...] = ("step", "second")


class DesignLab(gym.Wrapper):
    """The lab env (``OrthoglideLab-v0``, unchanged inside) as an experiment's design:
    choose the next operation among the planner's candidates, seeing what the readings so
    far determine.

    The wrapper keeps a :class:`~orthoglide_env.lab.design_belief.DesignBelief`: the
    Gaussian belief about the machine's 27 errors and each stand's mounting at the nominal
    machine, updated by a rank-one step per reading from the lab's observations (where
    and by which mounting each reading was taken; never the truth, nor the values read).
    A step costs a lab step and microseconds more.

    Action space
    ------------
    ``Discrete(P + K S + 1)`` over the slot table's candidate operations
    (:mod:`orthoglide_env.lab.slot_table`; ``P`` = 1500 postures, ``S`` = 39 slots on the
    prototype, ``K`` stands):

    ==================  ==========================================================
    action              operation
    ==================  ==========================================================
    ``p < P``           move to candidate posture ``p`` (Zero among them), with the
                        lever flicks a fixed plan makes: a plunger goes down where it
                        is safe both here and there, up where it is not safe there
                        (3 s each, each a lab step)
    ``P + k S + s``     re-mount stand ``k`` at slot ``s`` of the design's catalogue
    ``P + K S``         stop
    ==================  ==========================================================

    :meth:`action_masks` (as sb3-contrib's ``MaskablePPO`` asks for it) is False on the
    operations that are not candidates now: a move where no stand reads a priori more likely
    than not, or that would end past the budget; a re-mount at a slot a stand holds (the
    lab refuses one held by another stand), or past the budget.  Stop is always open.  A
    masked action is still done as the lab does it (a refused re-mount costs its lever
    flick), so the action space's every element is a valid action.

    Observation space (``Box``, float32)
    ------------------------------------
    ==========================  ===============================================  ========
    part                        meaning                                          length
    ==========================  ===============================================  ========
    error spectrum (v0, v1)     ``log10`` of the eigenvalues, largest first, of   r (12)
                                the predicted TCP error's covariance after the
                                best-fit rigid motion, in (0.01 mm)^2, plus
                                :data:`~orthoglide_env.lab.design_belief.
                                LOG_FLOOR`
    predicted error (v0, v1)    ``log10`` of their sum (the mean square)          1
    stands                      per stand: its slot one-hot (``S`` slots, then    K (S + 3)
                                "not mounted"), engaged, out of service
    posture                     the joint targets scaled to [-1, 1]               3
    time                        seconds used / ``budget_s``                       1
    readings here (v1)          readings taken at the present posture in a row    3
                                and in all, over :data:`~orthoglide_env.lab.
                                design_belief.COUNT_SCALE`; ``log10`` of the
                                last reading's relative fall of the predicted
                                mean square plus :data:`~orthoglide_env.lab.
                                design_belief.FALL_FLOOR`
    readings here (v2)          v1's first two (no fall)                         2
    readings everywhere (v2)    the readings taken at each candidate posture,    P
                                over ``COUNT_SCALE``
    ==========================  ===============================================  ========

    Reward
    ------
    ``reward="mse"`` (default): the fall of the predicted mean-square TCP error after the
    best-fit rigid motion over the step, in (0.01 mm)^2 (the belief's; an episode's sum is
    the prior's less the last); ``"log_mse"``: the fall of its natural log.  With
    ``per="second"`` each is divided by the step's seconds.  The lab's own reward is not
    used.

    Termination, truncation and info are the lab's (of its last step), and ``info`` adds
    ``lab_steps`` (the lab steps of this operation) and ``predicted_rigid_mm`` (the
    belief's predicted TCP error after rigid motion).  Reset options are the lab's.

    Arguments: ``env``, an ``OrthoglideLab-v0`` (without ``reference``: the gauge block's
    slots are not among the candidates), ``reward``, ``per``, ``version`` (of the view, 0,
    1 or 2).  ``design_lab_env(reward=, per=, version=, **lab_kwargs)`` builds both;
    ``gymnasium.make("OrthoglideLabDesign-v0", ...)`` is version 0, ``-v1`` version 1,
    ``-v2`` version 2.

    Version history
    ---------------
    * v0 (first release): the design view of ``OrthoglideLab-v0``.
    * v1: the observation ends with the readings taken at the present posture (in a row
      and in all) and the last reading's relative fall of the predicted error.  On an
      hour's budget an expert reads one posture up to 20 times in a row, and v0's
      observation moves by about a thousandth between two of those readings (the clock's
      5 s of 3600): a policy could not tell a re-reading from the next.  Actions, mask and
      reward are v0's.
    * v2: the observation holds the readings taken at every candidate posture in place
      of v1's spectrum and fall.  At the nominal machine the predicted covariance is a
      function of where and by which mountings readings were taken, never of their
      values, so the counts with the stands' states carry what the spectrum carried; a
      policy then decides without the belief's Woodbury steps and eigen-solve (the
      wrapper still follows the covariance, for its reward and ``predicted_rigid_mm``).
      Actions, mask and reward are v0's.
    """

    #: How its moves let plungers down: as the fixed plan does, where the a-priori spread
    #: keeps the tip safe (:meth:`operations`).
    flicks: str = "prior"

    def __init__(self, env: gym.Env, reward: str = "mse", per: str = "step",
                 version: int = 0) -> None:
        super().__init__(env)
        lab = env.unwrapped
        if not isinstance(lab, OrthoglideLabEnv):
            raise ValueError(f"DesignLab wraps an OrthoglideLab-v0 env, got {type(lab).__name__}")
        if reward not in DESIGN_REWARDS:
            raise ValueError(f"reward must be one of {DESIGN_REWARDS}, got {reward!r}")
        if per not in DESIGN_PER:
            raise ValueError(f"per must be one of {DESIGN_PER}, got {per!r}")
        if version not in VIEW_VERSIONS:
            raise ValueError(f"version must be one of {VIEW_VERSIONS}, got {version!r}")
        if lab.reference:
            raise ValueError("reference: the design view offers no gauge block's slots; "
                             "use reference=False")
        self.reward_mode, self.per = reward, per
        sigma = float(lab.noise.effective_sigma)
        self.version = version
        self.belief = DesignBelief(lab.design, lab.n_stands, weighting_sigma(sigma),
                                   lab.budget_s, version)
        self.action_space = spaces.Discrete(self.belief.n_actions)
        low, high = self.belief.observation_bounds(lab.settings.longest_step())
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self.belief.start(observation)
        return self._observation(), {**info, "lab_steps": 0,
                                     "predicted_rigid_mm": self._predicted_mm()}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"an action is an integer in [0, {self.action_space.n}), "
                             f"got {action!r}")
        return self._play(int(action))

    def _play(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:meth:`step` of view operation ``action`` (checked): its lab actions, the
        belief's update, the reward.  A subclass whose actions name the view's operations
        otherwise (a rank in a short list) plays the operation its action names here."""
        belief = self.belief
        before, start_s = belief.predicted_mse(), belief.time_s
        terminated = truncated = False
        info: dict[str, Any] = {}
        count = 0
        for operation in self.operations(action):
            observation, _, terminated, truncated, info = self.env.step(operation)
            count += 1
            belief.observe(operation, observation, bool(info.get("refused")))
            if terminated or truncated:
                break
        after = belief.predicted_mse()
        if self.reward_mode == "mse":
            reward = (before - after) / ACCURACY_UNIT_MM**2
        else:
            reward = float(np.log(before) - np.log(after))
        if self.per == "second":
            reward /= belief.time_s - start_s
        info = {**info, "lab_steps": count, "predicted_rigid_mm": self._predicted_mm()}
        return self._observation(), float(reward), terminated, truncated, info

    def operations(self, action: int) -> list[dict[str, Any]]:
        """The lab actions that operation ``action`` is (the belief's: a move's flicks as
        the fixed plan lets plungers down; a subclass may let them down otherwise)."""
        return self.belief.operations(action)

    def action_masks(self) -> np.ndarray:
        """Which actions are candidates now (bool, ``action_space.n``): see the class."""
        return self.belief.action_mask()

    def _predicted_mm(self) -> float:
        return float(np.sqrt(self.belief.predicted_mse()))

    def _observation(self) -> np.ndarray:
        return self.belief.observation()


def design_lab_env(reward: str = "mse", per: str = "step", version: int = 0, **kwargs: Any
                   ) -> DesignLab:
    """``OrthoglideLab-v0`` (``kwargs``: the lab env's) in its design view of ``version``
    (:class:`DesignLab`)."""
    return DesignLab(OrthoglideLabEnv(**kwargs), reward=reward, per=per, version=version)


class DesignLabVector(SyncVectorEnv):
    """``num_envs`` design views (:class:`DesignLab`) stepped in turn: env ``i`` is
    ``design_lab_env(**kwargs)`` reset with seed ``seed + i``, as Gymnasium's
    ``SyncVectorEnv`` does (its autoreset, its spaces), with :meth:`action_masks` for all
    of them."""

    def __init__(self, num_envs: int, **kwargs: Any) -> None:
        if not (isinstance(num_envs, int) and num_envs >= 1):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        super().__init__([lambda: design_lab_env(**kwargs) for _ in range(num_envs)])

    def action_masks(self) -> np.ndarray:
        """Each env's :meth:`DesignLab.action_masks` (num_envs, n)."""
        return np.stack(self.call("action_masks"))
