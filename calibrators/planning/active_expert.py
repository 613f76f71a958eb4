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

from calibrators.planning.design_expert import PlanExpert, planner_at, remount_schedule
from calibrators.planning.pricing import PricedMoves
from orthoglide_env.envs.lab import OrthoglideLabEnv
from orthoglide_env.lab.design_belief import READ_PROBABILITY, DesignBelief
from orthoglide_env.lab.operations import Op
from orthoglide_env.wrappers import DesignLab


class ActiveExpert(PlanExpert):
    """``active``'s filter following a design view's episode, its flicks and its choice
    (see the module).  Made at the episode's start from the lab's first observation and the
    view's belief after it; told every lab action and what the lab observed after it
    (:meth:`observe`)."""

    def __init__(self, lab: Any, belief: DesignBelief, observation: dict[str, np.ndarray]
                 ) -> None:
        self.planner = planner_at(lab, belief)
        self.remounts = remount_schedule(lab, belief)
        self.index = belief.index
        self._pending: PricedMoves | None = None
        self._read(observation)

    def action_mask(self, belief: DesignBelief) -> np.ndarray:
        """The view's mask (:meth:`DesignBelief.action_mask
        <orthoglide_env.lab.design_belief.DesignBelief.action_mask>`) with its moves open
        where some stand reads at least :data:`~orthoglide_env.lab.design_belief.
        READ_PROBABILITY` likely as the filter lets plungers down, not as the prior does
        (``active`` goes where its estimate lets a dial read)."""
        mask = belief.action_mask()
        seconds = belief.moves()[0]
        reads = self.planner._moves()[2]
        mask[:belief.n_postures] = ((reads.max(axis=0) >= READ_PROBABILITY)
                                    & (belief.time_s + seconds <= belief.budget_s))
        return mask

    def reach(self) -> np.ndarray:
        """Each candidate posture's expected number of dials reading there, as the filter
        lets plungers down from here, over the stands (P,): in [0, 1]."""
        reads = self.planner._moves()[2]
        return reads.sum(axis=0) / len(reads)

    def operations(self, action: int, belief: DesignBelief) -> list[dict[str, object]]:
        """The lab actions of view operation ``action``: a move's flicks as the filter lets
        plungers down (its estimate keeps the tip inside the travel), then the move; a
        re-mount or stop as the view plays them."""
        if action >= belief.n_postures:
            return belief.operations(action)
        seconds, after, reads = self.planner._moves()
        self._pending = PricedMoves(np.zeros(len(seconds)), seconds, after, reads)
        idle = {"rho": np.zeros(3), "stand": 0, "slot": 0}
        flicks = [{**idle, "op": Op.ENGAGE if down else Op.LIFT, "stand": k}
                  for k, down in enumerate(after[:, action])
                  if bool(down) != bool(belief.engaged[k])]
        return [*flicks, {**idle, "op": Op.MOVE, "rho": belief.table.postures[action].copy()}]

    def observe(self, operation: dict[str, object], observation: dict[str, np.ndarray],
                info: dict[str, Any]) -> None:
        """Take in the lab's ``observation`` after lab action ``operation`` (``info``: the
        lab's): a move's or a re-mount's readings, by value."""
        planner = self.planner
        for text in info.get("overtravel", []):
            planner.retire(int(text.split()[1]))
        if not info.get("refused"):
            if operation["op"] == Op.MOVE and self._pending is not None:
                posture = self.index[np.asarray(operation["rho"], dtype=float).tobytes()]
                planner.move(posture, self._pending)
                self._pending = None
                self._read(observation)
            elif operation["op"] == Op.REMOUNT:
                stand, slot = int(operation["stand"]), int(operation["slot"])
                if planner.slots[stand] == slot:
                    # Re-mounted where it stood: a new mounting all the same.
                    planner.retire(stand)
                planner.remount(stand, slot)
                self._read(observation)
        for stand in np.flatnonzero(observation["faulted"]):
            if planner.slots[stand] >= 0:
                planner.retire(int(stand))
        planner.time_s = float(observation["time"][0])

    def follow(self, action: int, belief: DesignBelief) -> None:
        """Nothing: the filter has seen every lab action (:meth:`observe`)."""

    def _read(self, observation: dict[str, np.ndarray]) -> None:
        planner = self.planner
        stands = [k for k in range(len(planner.slots))
                  if observation["valid"][k] and planner.slots[k] >= 0]
        planner.observe(stands, [float(observation["gauges"][k]) for k in stands])


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
        self.view.expert.observe(action, observation, info)
        return observation, reward, terminated, truncated, info


class FilteredDesignLab(DesignLab):
    """The design view (its actions and reward) whose moves let plungers down as
    ``active``'s filter does (:class:`ActiveExpert`, the episode's :attr:`expert`, which
    labels its states with ``active``'s choice), its mask opening the moves the filter lets
    a dial read (:meth:`ActiveExpert.action_mask`).  Its ``flicks`` is ``"filter"``.  With
    ``reach`` its observation also holds, after the view's, each candidate posture's dials
    that would read there, as the filter lets them down, over the stands
    (:meth:`ActiveExpert.reach`): what the values read open, which the view's observation
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
        return self.expert.operations(action, self.belief)

    def action_masks(self) -> np.ndarray:
        """Which actions are candidates now: :meth:`ActiveExpert.action_mask`."""
        return self.expert.action_mask(self.belief)

    def _observation(self) -> np.ndarray:
        seen = super()._observation()
        if not self.reach or self.expert is None:
            return seen
        return np.concatenate((seen, self.expert.reach())).astype(np.float32)


def filtered_design_lab_env(reward: str = "mse", per: str = "step", version: int = 0,
                            reach: bool = False, **kwargs: Any) -> FilteredDesignLab:
    """``OrthoglideLab-v0`` (``kwargs``: the lab env's) in the design view of ``version``
    whose moves take ``active``'s flicks, its observation with the filter's ``reach``
    or not (:class:`FilteredDesignLab`)."""
    return FilteredDesignLab(OrthoglideLabEnv(**kwargs), reward=reward, per=per,
                             version=version, reach=reach)
