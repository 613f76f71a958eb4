"""The faults of a lab's episodes (``faults=``): their schedules, what each has done so far
and how it changes what the dials show and what the notebook holds.

A fault acts at the first look at the machine at or after its time: ``knock`` moves a
stand's mounting (its readings shift until it is re-mounted), ``stick`` holds a dial at
its previous value for a few readings, ``sign`` writes one reading with the wrong sign,
``skip`` writes a stand's readings one row late from then on (each against the next
posture; the last is lost), ``thermal-step`` steps the room's temperature and
``lost-steps`` moves one carriage away from its command.  The dials show knocks and
sticks; sign slips and skipped rows are on the sheet only.  Every draw comes from the
episode's fault stream (:func:`~orthoglide_env.world.faults.fault_stream`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from orthoglide_env.world.faults import (
    FaultEvent,
    Faults,
    draw_size,
    schedule,
)


class LabFaults:
    """What the faults of ``size`` episodes with ``stands`` stands have done so far."""

    def __init__(self, faults: Faults, condition: str, horizon_s: float, size: int,
                 stands: int) -> None:
        self.faults, self.condition, self.horizon_s = faults, condition, horizon_s
        n, s = size, stands
        self.streams: list[np.random.Generator | None] = [None] * n
        self.pending: list[list[tuple[float, str]]] = [[] for _ in range(n)]
        #: The truth: each episode's faults so far (scoring only).
        self.log: list[list[FaultEvent]] = [[] for _ in range(n)]
        self.offset = np.zeros((n, s))  # mm, each mounting moved by knocks
        self.lost = np.zeros((n, 3))  # mm, each carriage off its command
        self.stuck = np.zeros((n, s), dtype=np.int64)  # readings a dial still holds
        self.sign = np.zeros((n, s), dtype=bool)  # the next reading is written negated
        self.late = np.zeros((n, s), dtype=bool)  # written one row late
        self.last = np.full((n, s), np.nan)  # each dial's last shown value
        self.previous = np.full((n, s), np.nan)  # the one before the latest reading

    def reset(self, rows: np.ndarray, streams: list[np.random.Generator]) -> None:
        """New episodes ``rows`` with their fault ``streams``
        (:func:`~orthoglide_env.world.faults.fault_stream` of the episodes' streams before
        these draw)."""
        for r, i in enumerate(rows.tolist()):
            own = streams[r]
            self.streams[i] = own
            self.pending[i] = schedule(self.faults, own, self.condition, self.horizon_s)
            self.log[i] = []
        for array, value in ((self.offset, 0.0), (self.lost, 0.0), (self.stuck, 0),
                             (self.sign, False), (self.late, False), (self.last, np.nan),
                             (self.previous, np.nan)):
            array[rows] = value

    def remounted(self, rows: np.ndarray, stand: np.ndarray) -> None:
        """Stands ``stand`` of ``rows`` are new installations: their faults end."""
        self.offset[rows, stand] = 0.0
        self.stuck[rows, stand] = 0
        self.sign[rows, stand] = self.late[rows, stand] = False
        self.last[rows, stand] = self.previous[rows, stand] = np.nan

    def fire(self, batch: Any, rows: np.ndarray, when: np.ndarray) -> None:
        """Let the faults of ``rows`` due by lab time ``when`` act on ``batch`` (the
        :class:`~orthoglide_env.lab.engine.LabBatch` that holds these faults)."""
        for r, i in enumerate(rows.tolist()):
            while self.pending[i] and self.pending[i][0][0] <= when[r]:
                _, kind = self.pending[i].pop(0)
                self._act(batch, i, kind, float(when[r]))

    def _act(self, batch: Any, i: int, kind: str, when: float) -> None:
        stream: np.random.Generator = self.streams[i]  # type: ignore[assignment]
        size = draw_size(kind, stream, self.condition)
        event = FaultEvent(kind, when, int(batch.steps[i]), size=size)
        if kind == "lost-steps":
            event.joint = int(stream.integers(3))
            self.lost[i, event.joint] += size
        elif kind == "thermal-step":
            world = batch.world[[i]]  # type: ignore[index]
            batch.world = batch.world.with_rows(  # type: ignore[union-attr]
                np.array([i]), world.replace(offset=world.offset + size))
        else:
            working = np.flatnonzero((batch.slot[i] >= 0) & batch.engaged[i]
                                     & ~batch.faulted[i])
            if not len(working):
                return  # no dial to act on: nothing happens
            k = int(working[stream.integers(len(working))])
            event.stand, event.mounting = k, batch.mounting[i][k]
            if kind == "knock":
                self.offset[i, k] += size
            elif kind == "stick":
                self.stuck[i, k] = max(1, int(size))
            elif kind == "sign":
                self.sign[i, k] = True
            else:
                self.late[i, k] = True
        self.log[i].append(event)

    def moved(self, at: np.ndarray) -> np.ndarray:
        """The carriages' positions ``at`` (every episode's) with the steps they lost."""
        return at + self.lost

    def shown(self, rows: np.ndarray, values: np.ndarray) -> np.ndarray:
        """What the dials of ``rows`` show when they read ``values`` (NaN: none): knocked
        mountings moved, stuck dials held."""
        shown = values + self.offset[rows]
        stuck = (self.stuck[rows] > 0) & np.isfinite(shown) & np.isfinite(self.last[rows])
        shown = np.where(stuck, self.last[rows], shown)
        self.stuck[rows] -= stuck
        read = np.isfinite(shown)
        self.previous[rows] = np.where(read, self.last[rows], self.previous[rows])
        self.last[rows] = np.where(read, shown, self.last[rows])
        return shown

    def written(self, rows: np.ndarray, valid: np.ndarray, values: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """What the sheet of ``rows`` holds of the shown ``values`` (``valid``): sign slips
        negated, late stands' values one reading behind (none where there is none)."""
        flip = self.sign[rows] & valid
        values = np.where(flip, -values, values)
        self.sign[rows] &= ~flip
        late = self.late[rows] & valid
        values = np.where(late, self.previous[rows], values)
        return valid & np.isfinite(values), values
