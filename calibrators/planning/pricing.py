"""The price of every candidate move: its seconds in lab time, the plungers it flicks, how
likely each stand reads after it, and what its readings gain.

A move costs its drive and settle with the lab's time table
(:data:`~orthoglide_env.lab.operations.TIME`), and a lever flick for every plunger lifted
first (a bar could press it past its travel there) or let down (safe both here and
there); a re-mount costs its two minutes (:meth:`~calibrators.planning.belief.Belief.
remount`).

Choosing a move prices exactly only the moves that may win: a move where no stand reads
gains nothing, and every other one's gain has a cheap upper bound
(:meth:`Pricer.top_rates`), so the choice is the one pricing every move makes.

Under ``lab`` or ``workshop`` conditions the world's gain has no cheap bound, so the
geometry's bounds shortlist the moves and the world prices only those and Zero
(:data:`WORLD_SHORTLIST`): a heuristic, like the greedy choice itself.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

from calibrators.planning.belief import (
    N_MACHINE,
    Belief,
    entries,
    move_reaches,
    reading_rows_many,
    rigid_factor,
)
from calibrators.planning.world_terms import directions, gains_many, rows_many
from orthoglide_env.lab.operations import TIME
from orthoglide_env.lab.slot_table import slot_table
from orthoglide_env.model.design import MachineDesign

#: :meth:`Pricer.top_rates` prices at least this many moves of the highest bounds first,
#: then only those whose bound can still beat the best of them.
FIRST_PRICED: int = 8
#: Relative widening of a gain's upper bound for the rounding of the gain and the bound
#: (both ~1e-15 relative; a real difference between two moves is far larger).
BOUND_SLACK: float = 1e-9
#: Under the world's terms, the moves priced with them at each step: this many of the
#: highest geometric gain bounds per second (:meth:`Pricer._gain_bounds`), and Zero,
#: whose revisit buys the world's drift and next to no geometry.  The world's gain has
#: no cheap bound (a reading may add to or take from the considered terms' bias), so
#: the geometry's bound shortlists and the world prices.  Measured with
#: ``benchmarks/world_plans.py``-style plans from the paper's stands (predicted TCP error
#: after rigid motion under the plan's world, pricing every move against this): lab, one
#: hour, 4.80 against 5.25 µm; workshop, one hour, 4.99 against 4.95; lab, 330 s, 24.9
#: against 24.3.  A greedy plan is a heuristic either way.  32 did a little better at
#: 330 s (24.3) and cost the ``active`` sweep a quarter more time; 8 costs it nothing
#: over the geometry's alone.
WORLD_SHORTLIST: int = 8


@lru_cache(maxsize=2048)
def drive_seconds(design: MachineDesign, rho: tuple[float, float, float]) -> np.ndarray:
    """Seconds (P,) to drive from ``rho`` to each of the design's candidate postures and
    settle (:meth:`~orthoglide_env.lab.operations.TimeTable.move`), read-only: a plan
    starts its moves from the same few postures again and again."""
    seconds = TIME.move(np.array(rho)[None], slot_table(design).postures)
    seconds.flags.writeable = False
    return seconds


class PricedMoves(NamedTuple):
    """Every candidate move priced (P postures, K stands)."""

    gain: np.ndarray  # (P,) (NaN: not priced, see Pricer.top_rates)
    seconds: np.ndarray  # (P,)
    engaged: np.ndarray  # (K, P) plungers down after the move
    reads: np.ndarray  # (K, P) probability that each of them reads there


#: The earlier name of :class:`PricedMoves`, kept for earlier scripts.
Options = PricedMoves


class Pricer(Belief):
    """A belief that prices the moves open to it (:class:`PricedMoves`)."""

    def priced_moves(self) -> PricedMoves:
        """Every candidate move priced: its gain, its seconds, the plungers down after it
        and how likely each reads."""
        seconds, after, reads = self._moves()
        gain = np.zeros(len(seconds))
        live = np.flatnonzero(reads.any(axis=0))
        gain[live] = self._price(reads, seconds, live)
        return PricedMoves(gain, seconds, after, reads)

    #: The earlier name of :meth:`priced_moves`, kept for earlier scripts.
    options = priced_moves

    def _price(self, reads: np.ndarray, seconds: np.ndarray, postures: np.ndarray
               ) -> np.ndarray:
        """Gain (L,) of the moves to ``postures`` (L,) (``reads`` as in :meth:`_rows`,
        ``seconds`` of every move): the geometry's alone, or with the world's terms their
        rows too, at the time and from the direction each move arrives, and for I the
        considered terms' bias (:meth:`~calibrators.planning.world_terms.WorldTerms.gains`)."""
        if self.world is None:
            return self._gains(self._rows(reads, postures))
        fitted, considered = self.world.rows(np.array(self.slots), postures,
                                             *self._arrival(seconds, postures))
        rows, considered = self._world_rows(reads, postures, fitted, considered)
        if self.criterion == "D":
            return self._gains(rows)
        return self.world.gains(rows, considered, self.covariance, rigid_factor(self.design))

    def _arrival(self, seconds: np.ndarray, postures: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """The lab time (L,) at which each move to ``postures`` (L,) arrives (``seconds``
        of every move) and each axis's direction of travel there (L, 3)."""
        return self.time_s + seconds[postures], directions(
            self.rho, self.table.postures[postures], self.world.approach)

    def _world_rows(self, reads: np.ndarray, postures: np.ndarray, fitted: np.ndarray,
                    considered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whitened rows (L, K, n) of the readings of the moves to ``postures`` (L,), the
        world's rows ``fitted`` (K, L, count) of them added, and over the considered terms
        (L, K, m) from their rows ``considered`` (K, L, m) (:meth:`_price`'s)."""
        rows, considered = world_rows_many([self], postures[None],
                                           np.sqrt(reads.T[postures])[None], fitted[None],
                                           considered[None])
        return rows[0], considered[0]

    def _moves(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seconds (P,) of every candidate move, the plungers down after it (K, P) and
        how likely each reads there (K, P).  A plunger is let down only where it is safe
        both here and there (let down here, it reads there), and lifted where it is not
        safe there."""
        return self._moves_from(*self._reach())

    def _moves_from(self, safe: np.ndarray, contact: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_moves` from the stands' reach at every posture (:meth:`_reach`)."""
        seconds, after, reads = moves_many([self], safe[None], contact[None])
        return seconds[0], after[0], reads[0]

    def _rows(self, reads: np.ndarray, postures: np.ndarray) -> np.ndarray:
        """Whitened rows (L, K, n) of the readings at ``postures`` (L,), each stand's
        weighted by its probability of reading (``reads``, K by every posture).

        Only postures where some stand reads need pricing: elsewhere every row is zero,
        the update nil and the gain exactly 0 (``_gains`` would give ``trace(solve(I,
        0))`` or ``slogdet(I)``, zeros that differ at most in their sign).  A posture's
        gain is computed alone (stacked products and solves work item by item), so it is
        the same to the bit whichever others are priced with it."""
        return self.rows_at(postures, weight=np.sqrt(reads.T[postures]))

    def _gains(self, rows: np.ndarray) -> np.ndarray:
        """Gain of adding each batch of whitened rows (B, K, n) to the covariance."""
        b = rows @ self.covariance
        m = np.eye(rows.shape[1]) + rows @ np.swapaxes(b, 1, 2)
        if self.criterion == "D":
            return np.linalg.slogdet(m)[1]
        bm = b[..., :N_MACHINE]
        return np.trace(np.linalg.solve(m, (bm @ self.weight) @ np.swapaxes(bm, 1, 2)),
                        axis1=1, axis2=2)

    def _gain_bounds(self, reads: np.ndarray, postures: np.ndarray) -> np.ndarray:
        """An upper bound (L,) on the gain of the readings at ``postures`` (L,) (``reads``
        as in :meth:`_rows`), valid for any rows and covariance, at a fraction of the
        price of the gain.

        With a posture's whitened rows ``R``, ``G = R C R'`` and, for I, ``Q = R C V C
        R'`` (``V``: the rigid weight padded with zeros to every unknown, positive
        semi-definite): I's gain is ``trace((1 + G)^-1 Q)``, and since ``G >= 0`` makes
        ``(1 + G)^-1 <= 1`` and ``Q >= 0``, it is at most ``trace(Q)``; D's gain is ``log
        det(1 + G)``, the sum of ``log(1 + g)`` over the eigenvalues ``g >= 0`` of ``G``,
        at most ``trace(G)``.  Either trace is a sum of one quadratic form per row (of
        ``C V C`` or ``C``): a stand's whitened row is its row scaled by ``sqrt(reads) /
        sigma``, so its form is that of its row over the unknowns it touches, times
        ``reads / sigma^2``.  The bound is tight where a posture's readings pin down
        little of what is left (``G`` small), as they do after the first minutes.  For I
        the form is ``(C F)(C F)'`` (``F``: :func:`rigid_factor`), so a row's is the
        square of its product with ``C F``, r columns instead of every unknown's."""
        c, cols = self.covariance, self.touched_columns  # (K, T)
        part = self.touched_at(postures)  # (K, L, T)
        if self.criterion == "D":
            left, right = part @ c[cols[:, :, None], cols[:, None, :]], part
        else:
            left = right = part @ (c[:, :N_MACHINE] @ rigid_factor(self.design))[cols]
        return np.sum(reads[:, postures] * np.sum(left * right, axis=-1), axis=0) / self.sigma**2

    def affordable_rates(self, priced: PricedMoves) -> np.ndarray:
        """Gain per second of every move that fits in the budget (-inf otherwise)."""
        fits = self.time_s + priced.seconds <= self.budget_s
        return np.where(fits, priced.gain / priced.seconds, -np.inf)

    def top_rates(self, count: int) -> tuple[np.ndarray, PricedMoves]:
        """Gain per second (P,) of the affordable moves that may be among the ``count``
        best, exactly as :meth:`affordable_rates` over :meth:`priced_moves` has them, and -inf
        for the others, whose rates are below the ``count``-th best (NaN gains in the
        priced moves: not priced).

        Each move's gain has an upper bound (:meth:`_gain_bounds`), widened by
        :data:`BOUND_SLACK` for the rounding of both.  The moves of the highest bounds
        per second are priced first; then every move whose bound per second reaches the
        ``count``-th best rate found, which can only rise as more are priced, so a move
        left out can neither beat nor tie it.  A move where no stand reads gains nothing
        (its rate 0) and is not priced either.

        With the world's terms only the :data:`WORLD_SHORTLIST` moves of the highest
        bounds per second and Zero are priced, with the world's terms
        (:meth:`_price`): their rates are returned, -inf for the others."""
        return top_rates_many([self], count)[0]

    @staticmethod
    def _take_prices(rate: np.ndarray, priced: PricedMoves, moves: np.ndarray,
                     gain: np.ndarray) -> None:
        """Enter the world's prices ``gain`` of ``moves`` in :meth:`_top_rates_open`'s."""
        priced.gain[moves] = gain
        rate[moves] = gain / priced.seconds[moves]

    def _top_rates_open(self, count: int, seconds: np.ndarray, after: np.ndarray,
                        reads: np.ndarray, fits: np.ndarray, live: np.ndarray
                        ) -> tuple[np.ndarray, PricedMoves, np.ndarray | None]:
        """:meth:`top_rates`, but with the world's terms the moves of the shortlist
        are left for the caller to price (:meth:`_price`, then :meth:`_take_prices`):
        the rates, the priced moves, and those moves (None: nothing left to price).
        ``fits`` and ``live``: the moves that fit in the budget and, of those, the
        postures where some stand reads (:func:`_live`)."""
        wanted = count if self.world is None else max(count, WORLD_SHORTLIST)
        gain = np.full(len(seconds), np.nan)
        rate = np.full(len(seconds), -np.inf)

        def price(moves: np.ndarray) -> None:
            postures = live[moves]
            gain[postures] = self._gains(self._rows(reads, postures))
            rate[postures] = gain[postures] / seconds[postures]

        if live.size:
            bound = self._gain_bounds(reads, live)
            size = np.abs(bound)
            bound = bound + BOUND_SLACK * (size + np.max(size))
            ceiling = bound / seconds[live]
            if self.world is not None:
                zero, moves = self.table.zero, live[_first_of_stable_order(-ceiling, wanted)]
                # Zero when it is live: a test of its own entries, not a search of ``live``.
                if fits[zero] and reads[:, zero].any() and zero not in moves:
                    moves = np.append(moves, zero)
                return rate, PricedMoves(gain, seconds, after, reads), np.sort(moves)
            first, rest = np.split(np.argsort(-ceiling, kind="stable"),
                                   [max(FIRST_PRICED, wanted)])
            price(first)
            if rest.size:
                price(rest[ceiling[rest] >= np.sort(rate[live[first]])[-wanted]])
        return rate, PricedMoves(gain, seconds, after, reads), None


def _first_of_stable_order(values: np.ndarray, count: int) -> np.ndarray:
    """The indices of the first ``count`` of ``values`` (L,) in ascending order, ties by
    index and NaN last, as the start of ``np.argsort(values, kind="stable")`` has them,
    in increasing order: found by a partition, not a sort of every value."""
    if count >= len(values):
        return np.arange(len(values))
    last = np.partition(values, count - 1)[count - 1]  # the count-th value (NaN last)
    below, tied = (~np.isnan(values), np.isnan(values)) if np.isnan(last) else (
        values < last, values == last)
    below = np.flatnonzero(below)
    # Apart, so their sorted concatenation is their union.
    return np.sort(np.concatenate((below, np.flatnonzero(tied)[:count - len(below)])))


def top_rates_many(pricers: list[Pricer], count: int
                   ) -> list[tuple[np.ndarray, PricedMoves]]:
    """:meth:`Pricer.top_rates` of each of ``pricers`` (one per machine of a chunk, or the
    re-mounts a plan screens), the same arrays to the bit: the stands' reach of filters of
    one design and stand count stacked over them (:func:`~calibrators.planning.belief.
    reaches`; a plan's is its table's), the world's prices of the shortlists too
    (:func:`price_many`)."""
    if not pricers:
        return []
    if all(p.mean is not None and p.table is pricers[0].table
           and len(p.slots) == len(pricers[0].slots) for p in pricers):
        stacked = moves_many(pricers, *move_reaches(pricers))
        moved = list(zip(*stacked, strict=True))
        lives = _live(pricers, stacked[0], stacked[2])
    else:
        moved = [pricer._moves() for pricer in pricers]
        lives = [_live([pricer], seconds[None], reads[None])[0]
                 for pricer, (seconds, _, reads) in zip(pricers, moved, strict=True)]
    opened = []
    for pricer, moves, live in zip(pricers, moved, lives, strict=True):
        opened.append((*pricer._top_rates_open(count, *moves, *live), moves))
    asked = [i for i, (_, _, shortlist, _) in enumerate(opened) if shortlist is not None]
    gains = price_many([pricers[i] for i in asked],
                       [(opened[i][3][2], opened[i][3][0], opened[i][2]) for i in asked])
    for i, gain in zip(asked, gains, strict=True):
        Pricer._take_prices(opened[i][0], opened[i][1], opened[i][2], gain)
    return [(rate, priced) for rate, priced, _, _ in opened]


def _live(pricers: list[Pricer], seconds: np.ndarray, reads: np.ndarray
          ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Of each of ``pricers``' moves (stacked: their seconds (M, P) and how likely each
    stand reads after them (M, K, P)), those that fit in its budget (P,) and, of those,
    the postures where some stand reads (L,): worked out for every pricer at once."""
    fits = (np.array([p.time_s for p in pricers])[:, None] + seconds
            <= np.array([p.budget_s for p in pricers])[:, None])
    machines, postures = entries(fits & reads.any(axis=1))
    ends = np.cumsum(np.bincount(machines, minlength=len(pricers)))[:-1]
    return list(zip(fits, np.split(postures, ends), strict=True))


def moves_many(pricers: list[Pricer], safe: np.ndarray, contact: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`Pricer._moves` of each of ``pricers`` (as many stands each) from their
    stands' reach at every posture, stacked (M, K, P): the seconds (M, P), the plungers
    down after each move (M, K, P) and how likely each reads there (M, K, P), each
    pricer's entries worked out from its own alone.  ``contact`` becomes the last (its
    entries where a plunger stays up zeroed in place: megabytes, made for this)."""
    here = safe[np.arange(len(pricers)), :, [p.here for p in pricers]]  # (M, K)
    engaged = np.array([p.engaged for p in pricers], dtype=bool)
    after = safe & (engaged | here)[..., None]
    reads = contact
    np.copyto(reads, 0.0, where=~after)
    # Counted in bytes (at most a few stands): a sixth of the price of a sum of booleans.
    flicks = np.add.reduce((after != engaged[..., None]).view(np.uint8), axis=1,
                           dtype=np.uint8)
    drive = np.stack([drive_seconds(p.design, tuple(float(v) for v in p.rho))
                      for p in pricers])
    seconds = drive + TIME.lift_s * flicks
    for row, pricer in enumerate(pricers):
        if pricer.dwell_s:
            seconds[row] += pricer.dwell_s  # a laser left set up reads at every move
    return seconds, after, reads


def world_rows_many(pricers: list[Pricer], postures: np.ndarray, root: np.ndarray,
                    fitted: np.ndarray, considered: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Pricer._world_rows` of each of ``pricers`` (one design, as many stands,
    unknowns and world terms each) at its ``postures`` (M, L), stacked: the whitened rows
    (M, L, K, n) of the readings there, each stand's weighted by the square root ``root``
    (M, L, K) of its probability of reading, the world's rows ``fitted`` (M, K, L, count)
    added, and over the considered terms (M, L, K, m) from their rows ``considered`` (M,
    K, L, m): each entry as each pricer alone has it."""
    world = pricers[0].world
    rows = reading_rows_many(pricers, np.arange(len(pricers[0].slots)), postures, root)
    weight = root[..., None] / np.array([p.sigma for p in pricers])[:, None, None, None]
    rows[..., world.start:world.start + world.count] += np.swapaxes(fitted, 1, 2) * weight
    return rows, np.swapaxes(considered, 1, 2) * weight


def price_many(pricers: list[Pricer], asked: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
               ) -> list[np.ndarray]:
    """:meth:`Pricer._price` of each of ``pricers`` with its ``(reads, seconds, postures)``
    of ``asked``.  The gains of beliefs with the world's terms under criterion I, as many
    postures, stands, unknowns and considered terms each, in one stacked computation
    (:func:`~calibrators.planning.world_terms.gains_many`): each its own to the bit."""
    out: list[np.ndarray | None] = [None] * len(pricers)
    groups: dict[tuple, list[int]] = {}
    for i, (pricer, (_, _, postures)) in enumerate(zip(pricers, asked, strict=True)):
        if pricer.world is None or pricer.criterion != "I":
            out[i] = pricer._price(*asked[i])
            continue
        key = (len(postures), len(pricer.slots), pricer.world.consider.shape,
               pricer.design, pricer.conditions)
        groups.setdefault(key, []).append(i)
    for members in groups.values():
        group = [pricers[i] for i in members]
        postures = np.stack([asked[i][2] for i in members])
        times, approach = (np.stack(a) for a in zip(
            *(p._arrival(asked[i][1], asked[i][2]) for p, i in zip(group, members,
                                                                  strict=True)),
            strict=True))
        fitted, considered = rows_many(
            [p.world for p in group], np.array([p.slots for p in group]), postures, times,
            approach, np.tile(np.arange(len(group[0].slots)), (len(group), 1)))
        # Each stand's weight at each posture asked, gathered member by member (their
        # reads are each a slice of megabytes).
        root = np.sqrt(np.stack([asked[i][0].T[asked[i][2]] for i in members]))
        rows, considered = world_rows_many(group, postures, root, fitted, considered)
        first = group[0]
        gains = gains_many(rows, considered,
                           np.stack([pricers[i].covariance for i in members]),
                           np.stack([pricers[i].world.consider for i in members]),
                           rigid_factor(first.design))
        for i, gain in zip(members, gains, strict=True):
            out[i] = gain
    return out  # type: ignore[return-value]
