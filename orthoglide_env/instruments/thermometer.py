"""The lab's room thermometer: what it reads of the room's temperature.

A lab may have one (``thermometer=True``): every reading's record then carries the room's
temperature as it read it at that time (C).  Under conditions with the ``thermometer``
effect it reads with a fixed offset of the lab's, drawn within its tolerance, and rounds
to its resolution (:data:`~orthoglide_env.world.table.EFFECTS`); otherwise it reads the
true temperature.  The room itself is the world's (:meth:`~orthoglide_env.world.truth.
World.temperature`): without the ``room`` effect it is at the 20 C reference.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.truth import REFERENCE_C, draw_range


def draw_offset(conditions: Conditions, stream: np.random.Generator) -> float:
    """The thermometer's offset (K) in a lab of ``conditions``, drawn from a jump of
    ``stream``: the stream itself does not move, so a lab with a thermometer draws the
    same machine, world and noise as one without (the two compare machine by machine).
    Zero without the ``thermometer`` effect."""
    if "thermometer" not in conditions:
        return 0.0
    own = np.random.Generator(stream.bit_generator.jumped())
    return float(draw_range(own, conditions.size("thermometer", "tolerance"), (), True))


def read(conditions: Conditions, temperature: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """What the thermometer reads (C) of the room at ``temperature`` (K from the 20 C
    reference) with its ``offset`` (K): rounded to its resolution under the
    ``thermometer`` effect."""
    value = REFERENCE_C + np.asarray(temperature) + offset
    if "thermometer" not in conditions:
        return value
    step = conditions.size("thermometer", "resolution")[0]
    return np.round(value / step) * step
