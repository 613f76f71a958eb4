"""``active``'s filter beside the design view: its lever flicks and its greedy choice.

The design view (:class:`~orthoglide_env.wrappers.DesignLab`) plays a move with the lever
flicks of a fixed plan: a plunger goes down only where its a-priori spread keeps it safe.
``active`` lets a plunger down wherever *its estimate*, filtered from the values read, keeps
the tip inside the travel, so it reads more dials at a posture and more postures per dial
(at 330 s about 3.0 readings a posture against the plan's 2.7, on 20 postures against 17);
a policy that imitates ``active`` has to be able to do that.  :class:`ActiveExpert` keeps
``active``'s filter (:class:`~calibrators.planning.search.Planner` with
:meth:`~calibrators.planning.belief.Belief.observe`: the values read, as ``active`` takes
them, never the truth) beside the view, gives a move's flicks from it
(:meth:`ActiveExpert.operations`) and labels any state with ``active``'s next operation
(:meth:`ActiveExpert.choose`: a due re-mount of the ``optimal`` plan, else the filter's
best move, else stop).  :class:`FilteredDesignLab` is the design view whose moves take
those flicks, the view a policy trained with ``examples/train_masked.py --expert active``
acts in; its observation, actions and mask are the view's.  The policy file says so
(:attr:`calibrators.agents.policy.PolicySpec.flicks`), and ``policy:FILE`` plays its moves
with the same filter.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from calibrators.planning.active_filter import ActiveFilter
from calibrators.planning.design_expert import PlanExpert, remount_schedule
from orthoglide_env.envs.lab import OrthoglideLabEnv
from orthoglide_env.lab.design_belief import DesignBelief
from orthoglide_env.wrappers import DesignLab


class ActiveExpert(PlanExpert):
    """``active``'s choice from any state of the filtered view: its filter
    (:class:`~calibrators.planning.active_filter.ActiveFilter`, :attr:`filter`), the
    ``optimal`` plan's re-mounts once due, else the filter's best open move, else stop.
    Made at the episode's start from the lab's first observation and the view's belief
    after it."""

    def __init__(self, lab: Any, belief: DesignBelief, observation: dict[str, np.ndarray]
                 ) -> None:
        self.filter = ActiveFilter(lab, belief, observation)
        self.planner = self.filter.planner
        self.remounts = remount_schedule(lab, belief)

    def action_mask(self, belief: DesignBelief) -> np.ndarray:
        """The filter's (:meth:`ActiveFilter.action_mask`)."""
        return self.filter.action_mask(belief)

    def follow(self, action: int, belief: DesignBelief) -> None:
        """Nothing: the filter has seen every lab action (:meth:`ActiveFilter.observe`)."""


class _Feed(gym.Wrapper):
    """Between the view and the lab: tells the view's :class:`ActiveExpert` every lab
    action and what the lab observed after it."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.view: FilteredDesignLab | None = None
        self.first: dict[str, np.ndarray] | None = None

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        self.first, info = self.env.reset(**kwargs)
        return self.first, info

    def step(self, action: dict[str, Any]) -> tuple[Any, ...]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.view.expert.filter.observe(action, observation, info)
        return observation, reward, terminated, truncated, info


class FilteredDesignLab(DesignLab):
    """The design view (its actions and reward) whose moves let plungers down as
    ``active``'s filter does (:class:`ActiveExpert`, the episode's :attr:`expert`, which
    labels its states with ``active``'s choice), its mask opening the moves the filter lets
    a dial read (:meth:`ActiveFilter.action_mask`).  Its ``flicks`` is ``"filter"``.  With
    ``reach`` its observation also holds, after the view's, each candidate posture's dials
    that would read there, as the filter lets them down, over the stands
    (:meth:`ActiveFilter.reach`): what the values read open, which the view's observation
    does not carry."""

    flicks = "filter"

    def __init__(self, env: gym.Env, reward: str = "mse", per: str = "step",
                 version: int = 0, reach: bool = False) -> None:
        feed = _Feed(env)
        super().__init__(feed, reward=reward, per=per, version=version)
        feed.view = self
        self.reach = reach
        self.expert: ActiveExpert | None = None
        if reach:
            n = self.belief.n_postures
            space = self.observation_space
            self.observation_space = spaces.Box(
                np.r_[space.low, np.zeros(n)].astype(np.float32),
                np.r_[space.high, np.ones(n)].astype(np.float32), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        _, info = super().reset(seed=seed, options=options)
        self.expert = ActiveExpert(self.env.unwrapped, self.belief, self.env.first)
        return self._observation(), info

    def operations(self, action: int) -> list[dict[str, object]]:
        return self.expert.filter.operations(action, self.belief)

    def action_masks(self) -> np.ndarray:
        """Which actions are candidates now: :meth:`ActiveExpert.action_mask`."""
        return self.expert.action_mask(self.belief)

    def _observation(self) -> np.ndarray:
        seen = super()._observation()
        if not self.reach or self.expert is None:
            return seen
        return np.concatenate((seen, self.expert.filter.reach())).astype(np.float32)


def filtered_design_lab_env(reward: str = "mse", per: str = "step", version: int = 0,
                            reach: bool = False, **kwargs: Any) -> FilteredDesignLab:
    """``OrthoglideLab-v0`` (``kwargs``: the lab env's) in the design view of ``version``
    whose moves take ``active``'s flicks, its observation with the filter's ``reach``
    or not (:class:`FilteredDesignLab`)."""
    return FilteredDesignLab(OrthoglideLabEnv(**kwargs), reward=reward, per=per,
                             version=version, reach=reach)
