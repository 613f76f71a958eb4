"""The real lab's world in an experiment's design: the planner's unknowns beyond the
geometry, under ``lab`` or ``workshop`` conditions.

The ``full`` estimator fits some of the world's effects and considers the rest
(:mod:`calibrators.estimators.consider`); a design that ignores them prices readings that
drift, lag and err as if they did not.  The planner's belief (:class:`~calibrators.planning.belief.
Belief`) then carries, with the patterns and second moments of
:mod:`~calibrators.estimators.consider` (one source of truth):

* fitted unknowns, each of unit prior in its pattern's size (a few, per axis and per
  mounting, never per reading):

  - ``warmup``: the amplitude's mean on every axis at once and its spread on each axis,
    both along the warm-up curve averaged over its time constant's range (the estimator
    fits each of the time constant's nodes too: the planner keeps the curve's mean);
  - ``backlash``: the lost motion's mean and each axis's spread, times half the sign of
    the axis's last move: the order of the moves decides what a reading says;
  - ``stands``: each mounting's creep (three time constants) and its arm's growth with
    the room, in lab time since its first reading: revisits to a posture read before
    (Zero) tell drift from geometry;

  a drive term moves a reading as the encoder offset ``drho`` of its axis does (its
  derivative at the posture, not since Zero: the mounting's zero takes the constant);
* consider terms (``dial``: each mounting's indicator error over its plunger's position,
  at the nominal reading there): the ``full`` estimator does not fit them, so the planner
  does not learn them either.  It carries ``D``, the estimate's error per unit
  coefficient, as a Schmidt-Kalman filter does: a reading's whitened rows ``r`` over the
  fitted unknowns and ``d`` over the considered ones move it by ``D + G (d - r D)`` with
  the update's gain ``G``, and the predicted mean-square TCP error is ``trace(W (C +
  D D^T))`` over the machine's errors, what the estimator's consider covariance says.
  A reading far in a plunger's travel then costs accuracy as well as buying it.

Left out: the lead error, which ``full`` fits as a pitch-error table, and the screw's
periodic error, which it considers.  Base-fixed gauges see next to nothing of them (the
one-hour ``optimal`` plan removes none of the table's variance: ``benchmarks/terms.py``),
so no choice of move changes their share of the error, and 24 more unknowns would only
slow the planner.  The planner's predicted error is therefore below the estimator's.

Readings always gain information about fitted unknowns, but a considered term can make a
reading's net gain negative, and the last minutes of a budget may buy next to nothing:
the planner stops early by :data:`STOP_SHARE` (:meth:`WorldTerms.stops`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from calibrators.estimators.consider import (
    backlash_sizes,
    dial_terms,
    drift_terms,
    warmup_curves,
    warmup_sizes,
)
from orthoglide_env.lab.slot_table import SlotTable, slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.truth import UM

#: The plan stops when the best move's gain per second, kept up for the rest of the
#: budget, would lower the predicted mean-square TCP error by less than this share of it:
#: 1 %, half a percent of the RMS error, below what 50 machines' medians resolve.
STOP_SHARE: float = 0.01
#: The drive effects the planner fits: each is a mean on every axis and a spread per axis.
AXIS_EFFECTS: tuple[str, ...] = ("warmup", "backlash")


def directions(start: np.ndarray, targets: np.ndarray, last: np.ndarray) -> np.ndarray:
    """(..., 3) each axis's direction of travel (+-1) from ``start`` to ``targets``; an
    axis that does not move keeps its ``last`` direction (the lab's rule)."""
    return np.where(targets > start, 1.0, np.where(targets < start, -1.0, last))


@dataclass
class WorldTerms:
    """The world's unknowns of one experiment being designed on ``table`` (its design's
    slots and candidate postures) with ``stands`` stands: the fitted ones are the
    planner's state's columns from ``start`` (the axes' first, then :attr:`per_stand` per
    stand), the considered ones are ``consider``'s columns (each mounting's own: a
    re-mount adds new ones, the old ones still bias the estimate)."""

    conditions: Conditions
    design: MachineDesign
    table: SlotTable
    stands: int
    start: int

    def __post_init__(self) -> None:
        on = self.conditions.__contains__
        self.axis_count = 4 * sum(on(e) for e in AXIS_EFFECTS)
        # The drive effects' sizes (mm), mean and spread, or None where they do not act.
        self.warmup: tuple[float, ...] | None = (
            warmup_sizes(self.conditions) if on("warmup") else None)
        self.backlash: tuple[float, ...] | None = tuple(
            size * UM for size in backlash_sizes(self.conditions)) if on("backlash") else None
        zero = np.zeros(1)
        self.per_stand = len(drift_terms(zero, zero, self.conditions)) if on("stands") else 0
        self.per_dial = len(dial_terms(zero, 1.0, self.conditions))
        self.approach = np.ones(3)  # the lab starts each axis as if last moved forward
        self.first_read = np.zeros(self.stands)  # each mounting's first reading, lab s
        self.dial_columns = np.arange(self.stands * self.per_dial).reshape(self.stands, -1)
        self.consider = np.zeros((self.start + self.count, self.stands * self.per_dial))
        stroke = self.design.rho_max - self.design.rho_min
        self.x = (self.table.postures - self.design.rho_min) / stroke  # (P, 3)
        # Each slot's reading's derivative over the encoder offsets (S, P, 3), mm per mm.
        self.drive = ((self.table.change[..., :3] + self.table.at_zero[:, None, :3])
                      / default_scales(ParameterSpace())[:3])

    @property
    def count(self) -> int:
        """Fitted columns."""
        return self.axis_count + self.stands * self.per_stand

    def stand_columns(self, stand: int) -> np.ndarray:
        """The state's columns of ``stand``'s fitted world unknowns."""
        first = self.start + self.axis_count + self.per_stand * stand
        return np.arange(first, first + self.per_stand)

    def copy(self) -> WorldTerms:
        out = copy.copy(self)
        out.approach, out.first_read = self.approach.copy(), self.first_read.copy()
        out.dial_columns, out.consider = self.dial_columns.copy(), self.consider.copy()
        return out

    # -- the rows of readings ---------------------------------------------------------------
    def rows(self, slots: np.ndarray, postures: np.ndarray | slice, times: np.ndarray,
             approach: np.ndarray, stands: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        """What the world adds to readings of the gauges of ``stands`` (K,) (default: every
        stand) at ``slots`` (every stand's, -1: none) taken at candidate ``postures`` (P')
        at lab ``times`` (P') with the axes last moved in ``approach`` (P', 3): the fitted
        unknowns' rows (K, P', count) and the considered ones' (K, P', consider columns),
        mm per unit coefficient: :func:`rows_many` of this belief alone."""
        postures = np.arange(len(self.table.postures))[postures]
        stands = np.arange(self.stands) if stands is None else np.asarray(stands)
        fitted, considered = rows_many([self], np.asarray(slots)[None], postures[None],
                                       np.asarray(times)[None],
                                       np.broadcast_to(approach, (len(postures), 3))[None],
                                       stands[None])
        return fitted[0], considered[0]

    # -- the state ------------------------------------------------------------------------
    def moved(self, start: np.ndarray, target: np.ndarray) -> None:
        """The carriages were driven from ``start`` to ``target``."""
        self.approach = directions(start, target, self.approach)

    def remounted(self, stand: int, cleared: np.ndarray, time_s: float) -> None:
        """``stand`` was mounted anew, its first reading at ``time_s``; the state's columns
        ``cleared`` are its new mounting's fresh unknowns (their errors owe nothing to any
        considered term yet), and its indicator's terms are new columns."""
        self.first_read[stand] = time_s
        self.consider[cleared] = 0.0
        if self.per_dial:
            old = self.consider.shape[1]
            self.consider = np.hstack([self.consider, np.zeros((len(self.consider),
                                                                self.per_dial))])
            self.dial_columns[stand] = np.arange(old, old + self.per_dial)

    def update(self, gain: np.ndarray, rows: np.ndarray, considered: np.ndarray) -> None:
        """Schmidt's update of ``D`` by readings of whitened ``rows`` (R, n) over the fitted
        unknowns and ``considered`` (R, m) over the considered ones, taken with the
        update's ``gain`` (n, R)."""
        self.consider = self.consider + gain @ (considered - rows @ self.consider)

    def bias(self, weight: np.ndarray) -> float:
        """The considered terms' share of the predicted mean-square TCP error (mm^2)."""
        d = self.consider[:len(weight)]
        return float(np.sum(d * (weight @ d)))

    def gains(self, rows: np.ndarray, considered: np.ndarray, covariance: np.ndarray,
              factor: np.ndarray) -> np.ndarray:
        """Fall of the predicted mean-square TCP error, the considered terms' part
        included, for each batch of whitened readings (B, K, n) over the fitted unknowns
        and ``considered`` (B, K, m) over the considered ones; ``factor``: ``F`` (27, r)
        of the rigid weight ``W = F F'``, so every quadratic form in ``W`` is a sum of
        squares over r columns instead of 27: :func:`gains_many` of this belief alone."""
        return gains_many(rows[None], considered[None], covariance[None],
                          self.consider[None], factor)[0]

    def stops(self, rate: float, remaining_s: float, criterion: float) -> bool:
        """Whether the plan stops: :data:`STOP_SHARE`'s rule for the best ``rate`` (per
        s) with ``remaining_s`` of the budget left and the ``criterion`` (mm^2) now."""
        return rate * remaining_s < STOP_SHARE * criterion


def rows_many(terms: list[WorldTerms], slots: np.ndarray, postures: np.ndarray,
              times: np.ndarray, approach: np.ndarray, stands: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`WorldTerms.rows` of M beliefs' world terms ``terms`` (one conditions, design
    and stand count, as many considered columns each) at once: each one's ``slots`` (M,
    K), ``postures`` (M, P'), ``times`` (M, P'), ``approach`` (M, P', 3) and ``stands``
    (M, K'); the fitted rows (M, K', P', count) and the considered ones (M, K', P', m).
    Every value is an element-wise function of its own belief's, so each is its own alone."""
    first = terms[0]
    m_count, k = stands.shape
    machines = np.arange(m_count)[:, None]
    slot = slots[machines, stands]
    mounted, slot = slot >= 0, np.maximum(slot, 0)  # (M, K')
    drho = (first.drive[slot[..., None], postures[:, None, :]]
            * mounted[..., None, None])  # (M, K', P', 3)
    p = drho.shape[2]
    fitted = np.zeros((m_count, k, p, first.count))
    column = 0
    carriage = []  # (mean size, spread size, per-axis pattern (M, P', 3))
    if first.warmup is not None:
        carriage.append((*first.warmup,
                         warmup_curves(first.x[postures], times, first.conditions)[1]))
    if first.backlash is not None:
        carriage.append((*first.backlash, -approach / 2))
    for mean, spread, pattern in carriage:
        moved = drho * pattern[:, None]  # (M, K', P', 3)
        fitted[..., column] = mean * moved.sum(axis=-1)
        fitted[..., column + 1:column + 4] = spread * moved
        column += 4
    rows = np.arange(k)[None, :]
    if first.per_stand:
        reads_from = np.stack([t.first_read for t in terms])[machines, stands]
        since = times[:, None] - reads_from[..., None]  # (M, K', P')
        for j, (_, pattern) in enumerate(drift_terms(
                since, np.broadcast_to(times[:, None], since.shape), first.conditions)):
            fitted[machines, rows, :, column + first.per_stand * stands + j] = (
                pattern * mounted[..., None])
    considered = np.zeros((m_count, k, p, first.consider.shape[1]))
    if first.per_dial:
        dials = np.stack([t.dial_columns for t in terms])[machines, stands]  # (M, K', d)
        for j, pattern in enumerate(dial_patterns(first.design, first.conditions)):
            considered[machines, rows, :, dials[..., j]] = (
                pattern[slot[..., None], postures[:, None, :]] * mounted[..., None])
    return fitted, considered


@lru_cache(maxsize=8)
def dial_patterns(design: MachineDesign, conditions: Conditions) -> np.ndarray:
    """The indicators' error patterns (d, S, P) of :func:`~calibrators.estimators.consider.
    dial_terms` at the nominal reading of every slot at every candidate posture of
    ``design``, read-only: made once, where each pricing's world rows made them anew at
    the postures it asked (the same values, element by element)."""
    table = slot_table(design)
    out = np.array([pattern for _, pattern in dial_terms(table.reading, table.travel,
                                                          conditions)])
    out.setflags(write=False)
    return out


def gains_many(rows: np.ndarray, considered: np.ndarray, covariances: np.ndarray,
               considers: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """:meth:`WorldTerms.gains` (M, B) of M beliefs at once: their whitened readings'
    rows (M, B, K, n) and ``considered`` (M, B, K, m), covariances (M, n, n) and ``D``s
    (M, n, m), with one ``factor``.  Every product and solve is stacked over the beliefs
    (BLAS and LAPACK item by item), so each belief's gains are its own alone, to the bit."""
    n = len(factor)

    def times(a: np.ndarray, matrix: np.ndarray) -> np.ndarray:
        # One BLAS product for every batch of a belief at once.
        flat = a.reshape(len(a), -1, a.shape[-1])
        return (flat @ matrix).reshape(*a.shape[:-1], -1)

    b = times(rows, covariances)
    m = np.eye(rows.shape[2]) + rows @ np.swapaxes(b, 2, 3)
    bf = times(b[..., :n], factor)
    hf = np.linalg.solve(m, bf)  # (M, B, K, r): the gain, times F
    known = np.sum(hf * bf, axis=(2, 3))
    # How the readings move D's machine rows, times F: (M, B, m, r).
    qf = np.swapaxes(considered - times(rows, considers), 2, 3) @ hf
    df = np.swapaxes(considers[:, :n], 1, 2) @ factor  # (M, m, r)
    return (known - 2 * np.sum(df[:, None] * qf, axis=(2, 3))
            - np.sum(qf * qf, axis=(2, 3)))


def world_terms(conditions: Conditions | None, design: MachineDesign, table: SlotTable,
                stands: int, start: int) -> WorldTerms | None:
    """The world's unknowns of a design under ``conditions`` after ``start`` columns of
    geometry, or None when nothing the planner models acts (``ideal``: today's planner,
    bit for bit)."""
    if conditions is None:
        return None
    terms = WorldTerms(conditions, design, table, stands, start)
    return terms if terms.count or terms.per_dial else None
