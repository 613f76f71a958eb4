"""``active``'s filter beside the design view, its lever flicks and what it lets read
(:class:`ActiveFilter`); the expert that labels with ``active``'s choice from it is
:mod:`calibrators.planning.active_expert`."""

from __future__ import annotations

from typing import Any

import numpy as np

from calibrators.agents.policy import FLICK_FILTERS
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.search import Planner
from orthoglide_env.lab.design_belief import READ_PROBABILITY, DesignBelief
from orthoglide_env.lab.operations import Op


def planner_at(lab: Any, belief: DesignBelief) -> Planner:
    """A planner (world terms included) in the state of ``belief`` as the episode opens, in
    the lab ``lab``'s conditions, no reading yet taken in."""
    planner = Planner([int(s) for s in belief.slots], [bool(e) for e in belief.engaged],
                      belief.sigma, belief.budget_s, design=belief.design,
                      conditions=lab.conditions)
    planner.time_s = belief.time_s
    return planner


class ActiveFilter:
    """``active``'s filter following a design view's episode and its flicks (see
    :mod:`calibrators.planning.active_expert`).  Made at the episode's start from the lab's
    first observation and the view's belief after it; told every lab action and what the
    lab observed after it (:meth:`observe`)."""

    def __init__(self, lab: Any, belief: DesignBelief, observation: dict[str, np.ndarray]
                 ) -> None:
        self.planner = planner_at(lab, belief)
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

    def _read(self, observation: dict[str, np.ndarray]) -> None:
        planner = self.planner
        stands = [k for k in range(len(planner.slots))
                  if observation["valid"][k] and planner.slots[k] >= 0]
        planner.observe(stands, [float(observation["gauges"][k]) for k in stands])


FLICK_FILTERS["filter"] = ActiveFilter
