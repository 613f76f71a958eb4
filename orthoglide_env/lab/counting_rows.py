"""A chunk of design beliefs that count readings (view 2's, without the covariance), kept as
rows of arrays, so that a chunk of machines takes in its lab steps, observes and finds its
masks in a few array calls per step, not a few per machine.

A belief of view 2 that does not follow the covariance
(:class:`~orthoglide_env.lab.design_belief.DesignBelief` with ``covariance=False``) is its
stands' states, its posture, its clock, the readings in a row here and the readings taken
at every candidate posture.  :class:`CountingRows` keeps those of N beliefs as arrays of
N rows, takes in a lab step of any of them at once (:meth:`CountingRows.observe`, the
beliefs' own :meth:`~orthoglide_env.lab.design_belief.DesignBelief.observe`), and groups
the rows whose states are equal (:meth:`CountingRows.groups`): their observations, masks
and operations are the same, found once per group.  The view's observation never holds a
value read, so machines played alike (one policy, one lab's clock, no refusal) pass the
same states, and a chunk's decision then costs about one machine's.  While all rows are
one state (:attr:`CountingRows.alike`) and every lab's step is the same, the step is taken
in on one row and given to all; what a state's stands and posture alone decide (its
candidate moves, the stands' part of its observation, its mask) is found once per such
state (:meth:`CountingRows.parts`: the shipped one-hour policy decides 484 times an
episode in 77 of them).

Which rows read the same readings is followed exactly, without comparing the counts: rows
of one family (the column :data:`FAMILY` of :attr:`CountingRows.state`) have equal
counts, and two of them stay in one family while each step either reads at the same
posture in both or in neither (a count changes only where a reading is taken, by one).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache, partial

import numpy as np

from orthoglide_env.lab.design_belief import (
    MOVES_KEPT,
    DesignBelief,
    Moves,
    close_late,
    open_masks,
    operations_of,
    remount_seconds,
    stands_of,
    tails_of,
)
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign

#: The columns of :attr:`CountingRows.state` before the stands': the row's family (see the
#: module), its posture's index, its readings in a row here, its clock and budget (s), its
#: posture's joint targets (3); then each stand's slot (-1: none), plunger down, out of
#: service (K each).
FAMILY, HERE, RUN, CLOCK, BUDGET, RHO = 0, 1, 2, 3, 4, slice(5, 8)
STANDS_FROM: int = 8
#: The entries of a lab observation that a row takes in (each of one shape and dtype in
#: every lab of a chunk).
TAKEN: tuple[str, ...] = ("slot", "engaged", "faulted", "time")


@dataclass(frozen=True)
class StateParts:
    """What a state's stands and posture alone decide (:meth:`CountingRows.parts`): its
    candidate moves, the stands' part of its observation (1, K (S + 3)) (float64,
    :func:`~orthoglide_env.lab.design_belief.stands_of`), its mask with all the budget left
    (read-only, :func:`~orthoglide_env.lab.design_belief.open_masks`), a re-mount's
    seconds from its posture, and the longest operation's it may open (a readable move
    or a re-mount): while that one ends within the budget, the mask is the kept one."""

    moves: Moves
    stands: np.ndarray
    mask: np.ndarray
    remount_s: float
    longest: float


class CountingRows:
    """The bookkeeping of ``beliefs`` (counting beliefs of one design, stands, budget and
    view 2, in that order) as rows of arrays; the beliefs themselves are left as they are
    (:meth:`write_back` brings one up to date)."""

    def __init__(self, beliefs: list[DesignBelief]) -> None:
        first = beliefs[0]
        if any(b.follows or b.version != 2 or b.design != first.design
               or b.n_stands != first.n_stands for b in beliefs):
            raise ValueError("counting rows are of view-2 beliefs that count readings "
                             "(covariance=False), of one design and stand count")
        self.first = first
        k = first.n_stands
        self.slots = slice(STANDS_FROM, STANDS_FROM + k)
        self.engaged = slice(STANDS_FROM + k, STANDS_FROM + 2 * k)
        self.faulted = slice(STANDS_FROM + 2 * k, STANDS_FROM + 3 * k)
        #: Each row's state but its counts (N, :data:`STANDS_FROM` + 3 K), in float64
        #: (integers and flags exactly): one array, so that a chunk's rows are compared
        #: and gathered in one call each.
        self.state = np.array([[0.0, b.here, b.run, b.time_s, b.budget_s, *b.rho, *b.slots,
                                *b.engaged, *b.faulted] for b in beliefs])
        self.counts = np.stack([b.readings_at for b in beliefs])
        self.state[:, FAMILY] = _families(self.counts)
        #: Whether all rows are one state (counts included: one family), so that a step
        #: that is the same in every lab is taken in on one row.
        self.alike = _uniform(self.state.view(np.int64))
        #: :meth:`parts` of a state, by its posture and stands (a one-hour episode of the
        #: shipped policy decides 484 times in 77 such states): every chunk's of this
        #: design and stand count (:func:`state_parts`).
        self._parts = state_parts(first.design, k)

    def observe(self, rows: np.ndarray, operations: list[dict[str, object]],
                taken: Mapping[str, np.ndarray], refused: Sequence[bool]) -> None:
        """:meth:`DesignBelief.observe` of the beliefs of ``rows`` (distinct) after their
        lab ``operations``, from their labs' observations' :data:`TAKEN` entries ``taken``,
        each stacked a row per lab (a vector env's arrays, or :func:`taken_of` lone labs'
        observations); a refused operation changes nothing but the clock."""
        if self._one_step(rows, operations, refused, taken):
            # Every row is one state and takes one step: one row's, for all of them.
            state = self.state[:1].copy()
            reads, to = self._step(state, operations[:1], refused[:1],
                                   {key: taken[key][:1] for key in TAKEN})
            self.state[:] = state
            for posture in to.tolist():
                self.counts[:, posture] += 1
            return
        state = self.state[rows]
        reads, to = self._step(state, operations, refused, taken)
        family = self.state[:, FAMILY] * (self.first.n_postures + 1)
        if reads.size:
            self.counts[rows[reads], to] += 1
            family[rows[reads]] += to + 1
        self.state[rows] = state
        self.state[:, FAMILY] = _numbered_values(family)
        self.alike = _uniform(self.state.view(np.int64))

    def _one_step(self, rows: np.ndarray, operations: list[dict[str, object]],
                  refused: Sequence[bool], taken: Mapping[str, np.ndarray]) -> bool:
        """Whether all rows, one state (:attr:`alike`), take one step: each row's
        operation the same (one dict: a group's), refused alike, and their labs' entries
        the same (a clock, never NaN, equal to the bit)."""
        if not self.alike or len(rows) != len(self.state):
            return False
        if len(set(map(id, operations))) > 1 or not _uniform(np.asarray(refused)):
            return False
        return all(_uniform(taken[key]) for key in TAKEN)

    def _step(self, state: np.ndarray, operations: list[dict[str, object]],
              refused: Sequence[bool], taken: Mapping[str, np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray]:
        """``state``'s rows (in place) after their ``operations`` and labs' entries
        ``taken`` (their stands, clocks, postures and stays); the positions of the rows
        that read (R,) and the postures where (R,), whose counts are the caller's."""
        first = self.first
        # Each operation's reading found once: the rows of a group share its dicts.
        readings: dict[int, tuple[int, bool]] = {}
        reads, to, anew = [], [], []
        for row, (operation, no) in enumerate(zip(operations, refused, strict=True)):
            if no:
                continue
            reading = readings.get(id(operation))
            if reading is None:
                reading = readings[id(operation)] = _reading(first, operation)
            if reading[0] >= 0:
                reads.append(row)
                to.append(reading[0])
                anew.append(reading[1])
        state[:, CLOCK] = taken["time"][:, 0]
        held = state[:, self.slots]
        held[:] = taken["slot"]
        # A stand at a slot beyond the design's catalogue (or none) holds no slot here.
        held[held >= first.n_slots] = -1
        state[:, self.engaged] = (taken["engaged"] != 0) & (held >= 0)
        state[:, self.faulted] = taken["faulted"] != 0
        if anew:
            # Every row reads (a chunk's rows played alike): its columns as they are.
            at = slice(None) if len(reads) == len(state) else reads
            # A stay ends where the reading is elsewhere, or after a re-mount (at Zero with
            # another set of mountings); row by row in Python, a handful of rows' floats
            # (a chunk's, or its one row played alike) costing less than array calls.
            state[at, RUN] = [run + 1 if posture == here and not new else 1.0
                              for posture, here, run, new in zip(
                                  to, state[at, HERE].tolist(), state[at, RUN].tolist(),
                                  anew, strict=True)]
            state[at, HERE] = to
            state[at, RHO] = first.table.postures.take(to, axis=0)
        reads, to = np.array(reads, dtype=np.int64), np.array(to, dtype=np.int64)
        return reads, to

    def groups(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rows of ``rows`` whose states are equal, grouped: one row of each group
        (G,) and each row's group (len(rows),).  Equal states are equal counts (one
        family), stands, posture, clock, budget and readings in a row."""
        if self.alike:
            # One state, the rows of machines played alike (a row's floats to the bit).
            return rows[:1], np.zeros(len(rows), dtype=np.int64)
        state = self.state[rows]
        # Rows compared by their bytes, a row's floats to the bit.
        flat, width = state.tobytes(), state.itemsize * state.shape[1]
        firsts, inverse = _numbered(flat[start:start + width]
                                    for start in range(0, len(flat), width))
        return rows[firsts], inverse

    def parts(self, rows: np.ndarray) -> list[StateParts]:
        """The :class:`StateParts` of the states of ``rows`` (their candidate moves from
        the design's cache of states, :func:`~orthoglide_env.lab.design_belief.
        candidate_moves`)."""
        state = self.state.take(rows, axis=0)
        return [self._parts(here, stands.tobytes()) for here, stands in zip(
            state[:, HERE].tolist(), state[:, STANDS_FROM:], strict=True)]

    def observations(self, rows: np.ndarray, parts: list[StateParts]) -> np.ndarray:
        """:meth:`DesignBelief.observation` (len(rows), n) of the beliefs of ``rows``,
        whose :meth:`parts` are ``parts``, the same floats."""
        state, counts = self.state.take(rows, axis=0), self.counts.take(rows, axis=0)
        total = counts[np.arange(len(rows)), state[:, HERE].astype(np.int64)]
        stands = parts[0].stands if len(parts) == 1 else np.concatenate(
            [p.stands for p in parts])
        return tails_of(self.first, stands, state[:, RHO], state[:, CLOCK] / state[:, BUDGET],
                        (state[:, RUN], total, None), counts).astype(np.float32)

    def masks(self, rows: np.ndarray, parts: list[StateParts]) -> np.ndarray:
        """:meth:`DesignBelief.action_mask` (len(rows), ``n_actions``) of the beliefs of
        ``rows``, whose :meth:`parts` are ``parts``: each state's kept mask, with the
        operations that would end past the budget closed near its end."""
        state = self.state.take(rows, axis=0)
        clock, budget = state[:, CLOCK], state[:, BUDGET]
        masks = np.array([p.mask for p in parts])
        if all(at + p.longest <= end for at, end, p in zip(clock.tolist(), budget.tolist(),
                                                           parts, strict=True)):
            return masks
        return close_late(self.first, masks, [p.moves for p in parts], clock, budget,
                          np.array([p.remount_s for p in parts]))

    def operations(self, row: int, action: int, moves: Moves) -> list[dict[str, object]]:
        """:meth:`DesignBelief.operations` of ``action`` for the belief of ``row``, whose
        candidate moves are ``moves``."""
        first = self.first
        return operations_of(first.table, first.n_stands, first.n_slots, action, moves[1],
                             self.state[row, self.engaged] != 0)

    def write_back(self, row: int, belief: DesignBelief) -> None:
        """Bring ``belief``, the belief of ``row``, up to this row's state (its own arrays,
        copied out)."""
        state = self.state[row]
        belief.slots = state[self.slots].astype(np.int64)
        belief.engaged, belief.faulted = state[self.engaged] != 0, state[self.faulted] != 0
        belief.rho, belief.readings_at = state[RHO].copy(), self.counts[row].copy()
        belief.here, belief.run = int(state[HERE]), int(state[RUN])
        belief.time_s, belief.fall = float(state[CLOCK]), 0.0
        belief._moves = None


@lru_cache(maxsize=2)
def state_parts(design: MachineDesign, stands: int) -> Callable[[float, bytes], StateParts]:
    """:class:`StateParts` of the states of ``design`` with ``stands`` stands, by a state's
    posture and the bytes of its stands' columns of :attr:`CountingRows.state`, the last
    :data:`~orthoglide_env.lab.design_belief.MOVES_KEPT` kept: shared by every chunk of
    them (each chunk of the shipped one-hour policy found its 77 states' parts again, 1.6 %
    of its decisions' instructions)."""
    # A belief of the design and stands, whose tables alone are read.
    return lru_cache(maxsize=MOVES_KEPT)(partial(_parts_of, DesignBelief(
        design, stands, 1.0, 1.0, 2, covariance=False)))


def _parts_of(first: DesignBelief, here: float, stands: bytes) -> StateParts:
    """:class:`StateParts` of the state of beliefs like ``first`` (its design and stands) at
    posture ``here`` whose stands' columns of :attr:`CountingRows.state` are the bytes
    ``stands``."""
    k = first.n_stands
    columns = np.frombuffer(stands).reshape(1, 3, k)
    held, engaged, faulted = columns[:, 0].astype(np.int64), columns[:, 1], columns[:, 2]
    at = int(here)
    moves = first._moves_of(held[0].tobytes(), (faulted[0] != 0).tobytes(),
                            (engaged[0] != 0).tobytes(), at)
    mask = open_masks(first, [moves], held)[0]
    mask.flags.writeable = False
    remount_s = float(remount_seconds(first, [at])[0])
    return StateParts(moves, stands_of(first, held, engaged, faulted), mask, remount_s,
                      max(moves[4], remount_s))


def _reading(first: DesignBelief, operation: dict[str, object]) -> tuple[int, bool]:
    """Where lab ``operation`` (not refused) reads, as the posture's index (-1: nowhere),
    and whether it starts a new stay wherever it reads (a re-mount)."""
    if operation["op"] == Op.MOVE:
        return first.index[operation["rho"].tobytes()], False
    if operation["op"] == Op.REMOUNT:
        return first.table.zero, True
    return -1, False


def taken_of(seen: list[dict[str, np.ndarray]]) -> np.ndarray:
    """The :data:`TAKEN` entries of lone labs' observations ``seen`` (of one env), stacked
    a row per lab (a record of their fields) in one pass over their bytes."""
    first = seen[0]
    record = np.dtype([(key, first[key].dtype, first[key].shape) for key in TAKEN])
    return np.frombuffer(b"".join([o[key] for o in seen for key in TAKEN]), record)


def _uniform(values: np.ndarray) -> bool:
    """Whether the rows of ``values`` (N, ...) are all equal to the bit (N >= 1): their
    bytes compared, a few calls of Python's where an array comparison and its reduction
    cost a chunk's step about as much as the step's own arithmetic."""
    raw = values.tobytes()
    return raw[:len(raw) // len(values)] * len(values) == raw


def _numbered_values(keys: np.ndarray) -> np.ndarray:
    """:func:`_numbered`'s numbers of ``keys`` (N,), without a pass in Python when all
    are equal."""
    if _uniform(keys):
        return np.zeros(len(keys), dtype=np.int64)
    return _numbered(keys.tolist())[1]


def _numbered(keys: Iterable[Hashable]) -> tuple[list[int], np.ndarray]:
    """Equal ``keys`` numbered alike, in the order of their first: the first's position
    of each number, and each key's number."""
    numbers: dict[Hashable, int] = {}
    firsts: list[int] = []
    numbered = []
    for position, key in enumerate(keys):
        number = numbers.setdefault(key, len(numbers))
        if number == len(firsts):
            firsts.append(position)
        numbered.append(number)
    return firsts, np.array(numbered, dtype=np.int64)


def _families(counts: np.ndarray) -> np.ndarray:
    """Each row's family (N,) of readings' ``counts`` (N, P): rows of equal counts share
    one, numbered in their first row's order."""
    family = np.full(len(counts), -1, dtype=np.int64)
    for row in range(len(counts)):
        if family[row] < 0:
            family[(family < 0) & (counts == counts[row]).all(axis=1)] = family.max() + 1
    return family
