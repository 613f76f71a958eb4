"""The lab's rewards: minus the time spent, the information gained per second, or the
final accuracy against the time spent."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: The accuracy reward counts the final TCP error (after the best-fit rigid motion) in
#: units of this many mm, and time in hours: -error/unit - time_weight * hours.
ACCURACY_UNIT_MM: float = 0.01
SECONDS_PER_HOUR: float = 3600.0


def step_rewards(kind: str, seconds: np.ndarray, *, gains: np.ndarray | None = None,
                 time_weight: float = 0.0, final_errors: Sequence[float] | None = None,
                 ended: np.ndarray | None = None) -> np.ndarray:
    """The reward (R,) of each step of ``seconds`` (R,) under reward ``kind``:

    * ``time``: minus the seconds;
    * ``information``: the ``gains`` (R,) of the notebooks' information (log-determinant)
      per second, 0 for a step that took no time;
    * ``accuracy``: minus the hours weighted by ``time_weight``, and for the steps that
      ``ended`` (R,) minus their ``final_errors`` (mm, one per ended step) in
      :data:`ACCURACY_UNIT_MM`."""
    if kind == "time":
        return -seconds
    if kind == "information":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(seconds > 0, gains / seconds, 0.0)  # type: ignore[operator]
    reward = -time_weight * seconds / SECONDS_PER_HOUR
    for r, error in zip(np.flatnonzero(ended), final_errors, strict=True):  # type: ignore[arg-type]
        reward[r] -= error / ACCURACY_UNIT_MM
    return reward
