"""Experiment design on the linearised model: which readings, at what price in lab time,
tell the most about the tool's accuracy.

The unknowns are Gaussian, each in units of its a-priori size: the machine's 27 errors
and each stand's installation (the realistic preset's sigmas, the estimators' priors),
and each dial's zero (:data:`ZERO_SCALE`, diffuse: the estimators eliminate it).  A
reading is a row of derivatives at the nominal machine divided by the gauge's sigma, so
the covariance after any set of readings follows by Bayesian (Woodbury) updates: the
error a design leaves is known before anything is read.  Two criteria:

============  ==================================================================
criterion     the gain of a set of readings
============  ==================================================================
I (default)   the fall of the predicted mean-square TCP error over the scoring
              grid after the best-fit rigid motion (what a user has after
              touching off the workpiece; :mod:`orthoglide_env.scoring`)
D             the rise of log det of the information about every unknown, in
              units of its a-priori size (the lab env's ``information`` reward)
============  ==================================================================

:class:`Planner` holds an experiment being designed (where each stand is, whose plunger
is down, the posture, the clock, the covariance) and prices every candidate operation
with the lab's time table (:data:`~orthoglide_env.lab.operations.TIME`): a move costs its drive and
settle, and a lever flick for every plunger lifted first (a bar could press it past its
travel there) or let down (safe both here and there); a re-mount costs its two minutes.
A reading counts with the probability that the tip touches (it may leave the bar's reach
at the far end of the travel); a plunger goes down only where the tip stays
:data:`~calibrators.planning.slot_table.SAFETY_SIGMAS` of its predicted spread plus
:data:`~calibrators.planning.slot_table.END_GAP` off the pushed-in end (the candidates and
what a gauge does there: :mod:`calibrators.planning.slot_table`).
A fixed plan knows each reading only a priori, so its margins are wide (up to ~3 mm);
a planner that has seen readings (:meth:`Planner.observe`) predicts them to microns and
may use the whole travel: that is what the ``active`` agent buys with its feedback.

Choosing a move prices exactly only the moves that may win: a move where no stand reads
gains nothing, and every other one's gain has a cheap upper bound
(:meth:`Planner.top_rates`), so the choice is the one pricing every move makes.

Under ``lab`` or ``workshop`` conditions the state also holds the world's unknowns, and
the indicators' curves bias the estimate (:mod:`calibrators.planning.world_terms`).  The
world's gain has no cheap bound, so the geometry's bounds shortlist the moves and the
world prices only those and Zero (:data:`WORLD_SHORTLIST`): a heuristic, like the greedy
choice itself.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from calibrators.planning.slot_table import END_GAP, reach, slot_table
from calibrators.planning.world_terms import directions, world_terms
from orthoglide_env.lab.operations import TIME, Op, slot_catalogue
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import ERROR_NAMES, MachineParams
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring import rigid_weights
from orthoglide_env.world.conditions import Conditions

N_MACHINE = len(ERROR_NAMES)
#: Unknowns of one mounting besides the machine's: four of its stand, then its zero.
N_STAND = 5
#: A dial's zero, a priori (mm): wide enough to be eliminated by the first reading, as the
#: estimators do exactly.
ZERO_SCALE: float = 10.0
CRITERIA: tuple[str, ...] = ("I", "D")
#: Re-mounts are weighed against staying every this many seconds of the plan, each option
#: by the gain per second of its next :data:`LOOKAHEAD_MOVES` moves (after the re-mount).
REMOUNT_CHECK_S: float = 300.0
LOOKAHEAD_MOVES: int = 24
SCREENED: int = 6
#: :meth:`Planner.top_rates` prices at least this many moves of the highest bounds first,
#: then only those whose bound can still beat the best of them.
FIRST_PRICED: int = 8
#: Widening (mm) of a remembered spread before it is taken for an upper bound of the
#: present one (:meth:`Planner._reach`): far above the rounding of a spread (under 1e-6
#: mm even where it is nearly zero) and far below the microns that decide a margin.
SPREAD_SLACK: float = 1e-5
#: Relative widening of a gain's upper bound for the rounding of the gain and the bound
#: (both ~1e-15 relative; a real difference between two moves is far larger).
BOUND_SLACK: float = 1e-9
#: Under the world's terms, the moves priced with them at each step: this many of the
#: highest geometric gain bounds per second (:meth:`Planner._gain_bounds`), and Zero,
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


@lru_cache(maxsize=2)
def rigid_weight(design: MachineDesign = PROTOTYPE) -> np.ndarray:
    """``W`` (27, 27): ``trace(W C)`` is the predicted mean-square TCP error over the
    scoring grid after the best-fit rigid motion (mm^2) for machine errors off by
    ``N(0, C)`` in units of their scale (the quadratic form of
    :func:`orthoglide_env.scoring.predicted_frame_errors`)."""
    scale = default_scales(ParameterSpace())
    return rigid_weights([MachineParams(design=design)])[0] * np.outer(scale, scale)


@lru_cache(maxsize=2)
def rigid_factor(design: MachineDesign = PROTOTYPE) -> np.ndarray:
    """``F`` (27, r) with ``F F' = W`` (:func:`rigid_weight`): ``W`` has rank ``r``, 12 on
    the prototype, as many errors only move the tool rigidly or as others do.  The
    eigenvalues below 1e-12 of the largest are the rounding of those zeros."""
    value, vector = np.linalg.eigh(rigid_weight(design))
    keep = value > 1e-12 * value[-1]
    return vector[:, keep] * np.sqrt(value[keep])


class Step(NamedTuple):
    """One lab operation of a plan (the fields of the lab env's action) and the lab time
    at which the plan starts it."""

    op: Op
    rho: tuple[float, float, float] = (0.0, 0.0, 0.0)
    stand: int = 0
    slot: int = 0
    time_s: float = 0.0


class Options(NamedTuple):
    """Every candidate move priced (P postures, K stands)."""

    gain: np.ndarray  # (P,) (NaN: not priced, see Planner.top_rates)
    seconds: np.ndarray  # (P,)
    engaged: np.ndarray  # (K, P) plungers down after the move
    reads: np.ndarray  # (K, P) probability that each of them reads there


@dataclass
class Planner:
    """An experiment being designed: stands, plungers, posture, clock, and the covariance
    (in units of each unknown's scale) of the 27 machine errors, then :data:`N_STAND`
    unknowns per stand's current mounting (a mounting left behind by a re-mount is
    marginalised out: nothing reads it again).

    ``slots``: each stand's index in the design's slot catalogue (:func:`~orthoglide_env.
    lab.operations.slot_catalogue`, the lab's) (-1: none);
    ``engaged``: whose plunger is down; ``sigma``: a reading's standard deviation (mm).
    ``observe`` turns it into a filter: it then also holds the mean of the unknowns and
    predicts the tips from them.  ``design``: the machine's design (its candidate postures,
    slot table and scoring grid).  ``conditions``: the lab's world; under ``lab`` or
    ``workshop`` the state also holds the world's unknowns (:mod:`~calibrators.planning.
    world_terms`: drift, backlash, the indicators' curves) and the plan may stop early;
    None or ``ideal``: the geometry alone."""

    slots: list[int]
    engaged: list[bool]
    sigma: float
    budget_s: float
    criterion: str = "I"
    time_s: float = 0.0
    design: MachineDesign = PROTOTYPE
    steps: list[Step] = field(default_factory=list)
    conditions: Conditions | None = None

    def __post_init__(self) -> None:
        self.table = slot_table(self.design)
        if self.criterion not in CRITERIA:
            raise ValueError(f"unknown criterion '{self.criterion}'; choose from {CRITERIA}")
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise ValueError(f"sigma must be a positive number, got {self.sigma}")
        self.slots = [int(s) for s in self.slots]
        self.engaged = [bool(e) and s >= 0 for s, e in zip(self.slots, self.engaged,
                                                           strict=True)]
        n = N_MACHINE + N_STAND * len(self.slots)
        self.world = world_terms(self.conditions, self.design, self.table, len(self.slots), n)
        n += self.world.count if self.world is not None else 0
        self.covariance = np.eye(n)
        self.mean: np.ndarray | None = None  # set by observe()
        # The posture, and its index in the table: a plan starts at Zero, and moves only
        # to candidate postures.
        self.rho, self.here = np.zeros(3), self.table.zero
        self.rows = np.zeros((len(self.slots), len(self.table.postures), n))
        # An upper bound of each stand's spread at every posture (see _reach).
        self.spread_bound = np.zeros((len(self.slots), len(self.table.postures)))
        # Each stand's columns of the unknowns its rows touch and its rows over them,
        # padded to N_MACHINE + N_STAND (the most a mounting touches) with zero rows at
        # column 0.
        self.touched: list[tuple[np.ndarray, np.ndarray]] = [
            (np.arange(0), np.zeros((0, 0)))] * len(self.slots)
        for k in range(len(self.slots)):
            self._set_rows(k)
        # Where an engaged gauge was seen not to read (its tip beyond the travel): it will
        # not read there again until its stand moves.
        self.silent = np.zeros((len(self.slots), len(self.table.postures)), dtype=bool)

    @property
    def weight(self) -> np.ndarray:
        return rigid_weight(self.design)

    # -- the model of a reading -----------------------------------------------------------
    def _columns(self, stand: int) -> np.ndarray:
        start = N_MACHINE + N_STAND * stand
        return np.concatenate((np.arange(N_MACHINE), np.arange(start, start + N_STAND)))

    def rows_of(self, stand: int) -> np.ndarray:
        """Rows (P, n) in mm per unit scale of a reading of ``stand`` at every posture."""
        out = np.zeros((len(self.table.postures), len(self.covariance)))
        if self.slots[stand] >= 0:
            out[:, self._columns(stand)[:-1]] = self.table.change[self.slots[stand]]
            out[:, self._columns(stand)[-1]] = ZERO_SCALE
        return out

    def _set_rows(self, stand: int) -> None:
        """Make ``stand``'s rows those of its present mounting (:meth:`rows_of`), also
        over the unknowns they touch (``touched``: columns, rows); its spread bound is the
        prior spread (its unknowns are as wide as a priori, the machine's at most)."""
        self.rows[stand] = self.rows_of(stand)
        self.spread_bound[stand] = self.table.prior_spread[max(self.slots[stand], 0)]
        used = np.flatnonzero(np.any(self.rows[stand] != 0.0, axis=0))
        cols = np.zeros(N_MACHINE + N_STAND, dtype=int)
        rows = np.zeros((len(self.table.postures), len(cols)))
        cols[:len(used)], rows[:, :len(used)] = used, self.rows[stand][:, used]
        self.touched[stand] = (cols, rows)

    def predicted_tips(self, postures: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Predicted tip distance of every stand's gauge at ``postures`` (K, P'), mm:
        nominal for a plan, from the mean once readings were observed.  (An empty stand
        gets slot 0's: it is masked later.)"""
        slots = np.maximum(np.array(self.slots), 0)
        tip = self.table.tip[slots][:, postures]
        if self.mean is None:
            return tip
        for k, slot in enumerate(slots):
            change = self.table.change[slot][postures] @ self.mean[self._columns(k)[:-1]]
            tip[k] += self.table.sign[slot] * change
        return tip

    def _spread(self, stand: int, postures: np.ndarray) -> np.ndarray:
        """Standard deviation (L,) of ``stand``'s predicted tip at ``postures`` (L,), mm,
        from the covariance.  A posture's value is the same to the bit whichever others
        are computed with it: the rows go to BLAS in an even count (its kernels take a
        lone last row their own way, a few ulps off)."""
        cols = self._columns(stand)[:-1]
        even = np.append(postures, postures[-1]) if len(postures) % 2 else postures
        change = self.table.change[self.slots[stand], even]
        product = change @ self.covariance[cols[:, None], cols]
        return np.sqrt(np.clip(np.sum(product * change, axis=-1), 0.0, None))[:len(postures)]

    def _reach(self, postures: np.ndarray | slice = slice(None)
               ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`reach` of every stand at ``postures`` (nothing for an empty stand, no
        contact where it was seen not to read).

        Once readings were observed, a spread is computed only where the answer depends
        on it.  Not where the tip misses its bar or a bar presses the gauge, nor where
        the tip is less than :data:`END_GAP` off the end, and not where the stand's
        spread bound (``spread_bound``) already leaves the tip safe and touching
        (contact exactly 1): the spread, at most the bound, would leave it so too.  The
        bound is the prior spread at a mounting, then each spread as last computed,
        plus :data:`SPREAD_SLACK`: readings only shrink the covariance, so a spread
        never grows until its stand is re-mounted."""
        slots = np.array(self.slots)
        mounted = (slots >= 0)[:, None]
        if self.mean is None:
            safe, contact = (a[np.maximum(slots, 0)][:, postures]
                             for a in self.table.prior_reach)
        else:
            tip = self.predicted_tips(postures)
            spread = self.spread_bound[:, postures] + SPREAD_SLACK
            safe, contact = reach(self.table, np.maximum(slots, 0), tip, spread, postures)
            index = np.arange(len(self.table.postures))[postures]
            with np.errstate(invalid="ignore"):
                open_ = ((tip >= END_GAP) & (contact < 1.0)
                         & ~self.table.pressed[np.maximum(slots, 0)][:, postures] & mounted)
            stands = np.flatnonzero(open_.any(axis=1))
            for k in stands:
                at = np.flatnonzero(open_[k])
                spread[k, at] = self.spread_bound[k, index[at]] = self._spread(k, index[at])
            if stands.size:
                safe, contact = reach(self.table, np.maximum(slots, 0), tip, spread, postures)
        return safe & mounted, np.where(self.silent[:, postures], 0.0, contact) * mounted

    # -- pricing --------------------------------------------------------------------------
    def options(self) -> Options:
        """Every candidate move priced: its gain, its seconds, the plungers down after it
        and how likely each reads."""
        seconds, after, reads = self._moves()
        gain = np.zeros(len(seconds))
        live = np.flatnonzero(reads.any(axis=0))
        gain[live] = self._price(reads, seconds, live)
        return Options(gain, seconds, after, reads)

    def _price(self, reads: np.ndarray, seconds: np.ndarray, postures: np.ndarray
               ) -> np.ndarray:
        """Gain (L,) of the moves to ``postures`` (L,) (``reads`` as in :meth:`_rows`,
        ``seconds`` of every move): the geometry's alone, or with the world's terms their
        rows too, at the time and from the direction each move arrives, and for I the
        considered terms' bias (:meth:`~calibrators.planning.world_terms.WorldTerms.gains`)."""
        rows = self._rows(reads, postures)
        if self.world is None:
            return self._gains(rows)
        weight = np.sqrt(reads.T[postures])[:, :, None] / self.sigma
        fitted, considered = self.world.rows(
            np.array(self.slots), postures, self.time_s + seconds[postures],
            directions(self.rho, self.table.postures[postures], self.world.approach))
        rows[..., self.world.start:] += np.swapaxes(fitted, 0, 1) * weight
        if self.criterion == "D":
            return self._gains(rows)
        return self.world.gains(rows, np.swapaxes(considered, 0, 1) * weight,
                                self.covariance, rigid_factor(self.design))

    def _moves(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seconds (P,) of every candidate move, the plungers down after it (K, P) and
        how likely each reads there (K, P).  A plunger is let down only where it is safe
        both here and there (let down here, it reads there), and lifted where it is not
        safe there."""
        safe, contact = self._reach()
        here = safe[:, self.here]
        engaged = np.array(self.engaged, dtype=bool)
        after = safe & (engaged | here)[:, None]
        reads = np.where(after, contact, 0.0)
        flicks = np.sum(after != engaged[:, None], axis=0)
        seconds = TIME.move(self.rho[None], self.table.postures) + TIME.lift_s * flicks
        return seconds, after, reads

    def _rows(self, reads: np.ndarray, postures: np.ndarray) -> np.ndarray:
        """Whitened rows (L, K, n) of the readings at ``postures`` (L,), each stand's
        weighted by its probability of reading (``reads``, K by every posture).

        Only postures where some stand reads need pricing: elsewhere every row is zero,
        the update nil and the gain exactly 0 (``_gains`` would give ``trace(solve(I,
        0))`` or ``slogdet(I)``, zeros that differ at most in their sign).  A posture's
        gain is computed alone (stacked products and solves work item by item), so it is
        the same to the bit whichever others are priced with it."""
        return (np.swapaxes(self.rows[:, postures], 0, 1)
                * np.sqrt(reads.T[postures])[:, :, None] / self.sigma)

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
        c, cols = self.covariance, np.array([cols for cols, _ in self.touched])  # (K, T)
        part = np.stack([rows[postures] for _, rows in self.touched])  # (K, L, T)
        if self.criterion == "D":
            left, right = part @ c[cols[:, :, None], cols[:, None, :]], part
        else:
            left = right = part @ (c[:, :N_MACHINE] @ rigid_factor(self.design))[cols]
        return np.sum(reads[:, postures] * np.sum(left * right, axis=-1), axis=0) / self.sigma**2

    def predicted_rigid_mm(self) -> float:
        """Predicted TCP error RMS after the best-fit rigid motion (mm), the considered
        world terms' bias included."""
        n = N_MACHINE
        square = np.trace(self.weight @ self.covariance[:n, :n])
        if self.world is not None:
            square += self.world.bias(self.weight)
        return float(np.sqrt(max(square, 0.0)))

    # -- taking operations ----------------------------------------------------------------
    def _add(self, rows: np.ndarray, innovations: np.ndarray | None = None,
             considered: np.ndarray | None = None) -> None:
        """Bayesian update with whitened ``rows`` (R, n) (and, when filtering, their
        whitened innovations; with world terms, their whitened rows over the considered
        ones)."""
        if len(rows) == 0:
            return
        b = self.covariance @ rows.T
        m = np.eye(len(rows)) + rows @ b
        gain = np.linalg.solve(m, b.T).T  # (n, R)
        if self.world is not None:
            self.world.update(gain, rows, considered)
        if self.mean is not None and innovations is not None:
            self.mean = self.mean + gain @ innovations
        self.covariance = self.covariance - gain @ b.T
        self.covariance = (self.covariance + self.covariance.T) / 2

    def expect_readings(self, stands: np.ndarray | None = None,
                        weights: np.ndarray | None = None) -> None:
        """Count readings of ``stands`` here, each with its probability (a plan's; default:
        :meth:`reading_here`)."""
        if stands is None:
            stands, weights = self.reading_here()
        rows, considered = self._rows_here(stands)
        weight = np.sqrt(weights)[:, None]
        self._add(rows * weight / self.sigma, considered=considered * weight / self.sigma)

    def _rows_here(self, stands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows (R, n) of readings of ``stands`` here and now, mm per unit, and (with
        world terms) their rows over the considered terms (R, m)."""
        rows = self.rows[stands, self.here]
        if self.world is None:
            return rows, np.zeros((len(stands), 0))
        fitted, considered = self.world.rows(
            np.array(self.slots), np.array([self.here]), np.array([self.time_s]),
            self.world.approach[None], stands)
        rows = rows.copy()
        rows[:, self.world.start:] += fitted[:, 0]
        return rows, considered[:, 0]

    def observe(self, stands: list[int], values: list[float]) -> None:
        """Readings (mm) of ``stands`` taken here (every other engaged stand read nothing):
        update the mean and the covariance."""
        if self.mean is None:
            self.mean = np.zeros(len(self.covariance))
        quiet = [k for k, down in enumerate(self.engaged) if down and k not in stands]
        self.silent[quiet, self.here] = True
        stands_ = np.asarray(stands, dtype=int)
        if not stands_.size:
            return
        rows, considered = self._rows_here(stands_)
        nominal = self.table.reading[[self.slots[k] for k in stands_], self.here]
        predicted = nominal + rows @ self.mean
        self._add(rows / self.sigma, (np.asarray(values, dtype=float) - predicted) / self.sigma,
                  considered / self.sigma)

    def retire(self, stand: int) -> None:
        """A stand that reads no more (pushed past its travel) until it is re-mounted."""
        self.slots[stand] = -1
        self.engaged[stand] = False
        self._set_rows(stand)

    def move(self, posture: int, options: Options) -> np.ndarray:
        """Take candidate move ``posture``: the steps, the clock; returns which stands are
        down there.  (The readings are added by the caller: expected or observed.)"""
        after = options.engaged[:, posture]
        clock = self.time_s
        for k, down in enumerate(after):
            if bool(down) != self.engaged[k]:
                self.steps.append(Step(Op.ENGAGE if down else Op.LIFT, stand=k, time_s=clock))
                clock += TIME.lift_s
        rho = self.table.postures[posture]
        self.steps.append(Step(Op.MOVE, tuple(float(v) for v in rho), time_s=clock))
        if self.world is not None:
            self.world.moved(self.rho, rho)
        self.engaged = [bool(v) for v in after]
        self.rho, self.here = rho.copy(), posture
        self.time_s += float(options.seconds[posture])
        return after

    def remount(self, stand: int, slot: int) -> None:
        """Move ``stand`` to ``slot`` (the machine drives to Zero first): a new mounting
        with fresh unknowns, its plunger down."""
        if slot in self.slots:
            raise ValueError(f"slot {slot} already holds a stand")
        self.steps.append(Step(Op.REMOUNT, stand=stand, slot=slot, time_s=self.time_s))
        self.time_s += float(TIME.move(self.rho, np.zeros(3))) + TIME.remount_s
        cols = self._columns(stand)[N_MACHINE:]
        if self.world is not None:
            self.world.moved(self.rho, np.zeros(3))
            cols = np.r_[cols, self.world.stand_columns(stand)]
            self.world.remounted(stand, cols, self.time_s)
        self.rho, self.here = np.zeros(3), self.table.zero
        self.covariance[cols, :] = 0.0
        self.covariance[:, cols] = 0.0
        self.covariance[cols, cols] = 1.0
        if self.mean is not None:
            self.mean[cols] = 0.0
        self.slots[stand] = slot
        self.engaged[stand] = True
        self._set_rows(stand)
        self.silent[stand] = False

    def reading_here(self) -> tuple[np.ndarray, np.ndarray]:
        """Stands down here and the probability that each reads."""
        _, contact = self._reach(np.array([self.here]))
        down = np.flatnonzero(self.engaged)
        return down, contact[down, 0]

    # -- choosing ---------------------------------------------------------------------------
    def fork(self) -> Planner:
        """A copy to try operations on (the table is shared, the state copied)."""
        trial = copy.copy(self)
        trial.slots, trial.engaged, trial.steps = list(self.slots), list(self.engaged), []
        trial.covariance, trial.rows = self.covariance.copy(), self.rows.copy()
        trial.touched = list(self.touched)
        trial.silent = self.silent.copy()
        trial.spread_bound = self.spread_bound.copy()
        trial.mean = None if self.mean is None else self.mean.copy()
        trial.world = None if self.world is None else self.world.copy()
        return trial

    def affordable_rates(self, options: Options) -> np.ndarray:
        """Gain per second of every move that fits in the budget (-inf otherwise)."""
        fits = self.time_s + options.seconds <= self.budget_s
        return np.where(fits, options.gain / options.seconds, -np.inf)

    def lookahead_rate(self, start: float | None = None, start_s: float | None = None
                       ) -> float:
        """Gain per second, since criterion value ``start`` at ``start_s`` (default now),
        of the next :data:`LOOKAHEAD_MOVES` greedy moves (readings expected), on a copy."""
        trial = self.fork()
        start = trial._criterion_value() if start is None else start
        start_s = trial.time_s if start_s is None else start_s
        for _ in range(LOOKAHEAD_MOVES):
            if not trial.greedy_move():
                break
        spent = trial.time_s - start_s
        return (start - trial._criterion_value()) / spent if spent > 0 else 0.0

    def _criterion_value(self) -> float:
        """What the plan drives down: the predicted mean-square TCP error (I), or the log
        det of the covariance (D)."""
        if self.criterion == "D":
            return float(np.linalg.slogdet(self.covariance)[1])
        return self.predicted_rigid_mm() ** 2

    def best_move(self) -> tuple[int, Options] | None:
        """The affordable move with the most gain per second (the first of equals), with
        every move's seconds, plungers and readings and the gains that were priced
        (:meth:`top_rates`), or None when no move gains anything within the budget: the
        same move as the highest of :meth:`affordable_rates` over :meth:`options`.

        With the world's terms the shortlist's best is taken unless it would end the plan
        (:meth:`~calibrators.planning.world_terms.WorldTerms.stops`, or no gain): then every
        move is priced, so a plan ends only when no move pays, not when the shortlist's
        do not (a fresh mounting's loose bounds may shortlist moves that add more to the
        indicators' bias than they take off the geometry)."""
        rate, options = self.top_rates(1)
        best = int(np.argmax(rate))
        if self.world is not None and self._ends(rate[best]):
            options = self.options()
            rate = self.affordable_rates(options)
            best = int(np.argmax(rate))
            if self._ends(rate[best]):
                return None
        return (best, options) if rate[best] > 0 else None

    def _ends(self, rate: float) -> bool:
        """Whether a best move of gain per second ``rate`` ends the plan."""
        return rate <= 0 or (self.criterion == "I" and self.world is not None
                             and self.world.stops(rate, self.budget_s - self.time_s,
                                                  self._criterion_value()))

    def top_rates(self, count: int) -> tuple[np.ndarray, Options]:
        """Gain per second (P,) of the affordable moves that may be among the ``count``
        best, exactly as :meth:`affordable_rates` over :meth:`options` has them, and -inf
        for the others, whose rates are below the ``count``-th best (NaN gains in the
        options: not priced).

        Each move's gain has an upper bound (:meth:`_gain_bounds`), widened by
        :data:`BOUND_SLACK` for the rounding of both.  The moves of the highest bounds
        per second are priced first; then every move whose bound per second reaches the
        ``count``-th best rate found, which can only rise as more are priced, so a move
        left out can neither beat nor tie it.  A move where no stand reads gains nothing
        (its rate 0) and is not priced either.

        With the world's terms only the :data:`WORLD_SHORTLIST` moves of the highest
        bounds per second and Zero are priced, with the world's terms
        (:meth:`_price`): their rates are returned, -inf for the others."""
        wanted = count if self.world is None else max(count, WORLD_SHORTLIST)
        seconds, after, reads = self._moves()
        fits = self.time_s + seconds <= self.budget_s
        live = np.flatnonzero(fits & reads.any(axis=0))
        gain = np.full(len(seconds), np.nan)
        rate = np.full(len(seconds), -np.inf)

        def price(moves: np.ndarray) -> None:
            postures = live[moves]
            gain[postures] = self._gains(self._rows(reads, postures))
            rate[postures] = gain[postures] / seconds[postures]

        if live.size:
            bound = self._gain_bounds(reads, live)
            bound = bound + BOUND_SLACK * (np.abs(bound) + np.max(np.abs(bound)))
            ceiling = bound / seconds[live]
            order = np.argsort(-ceiling, kind="stable")
            if self.world is not None:
                moves = np.union1d(live[order[:wanted]],
                                   np.intersect1d(live, [self.table.zero]))
                gain[moves] = self._price(reads, seconds, moves)
                rate[moves] = gain[moves] / seconds[moves]
                return rate, Options(gain, seconds, after, reads)
            first, rest = np.split(order, [max(FIRST_PRICED, wanted)])
            price(first)
            if rest.size:
                price(rest[ceiling[rest] >= np.sort(rate[live[first]])[-wanted]])
        return rate, Options(gain, seconds, after, reads)

    def greedy_move(self) -> bool:
        """Take :meth:`best_move`, its readings expected; False when there is none."""
        choice = self.best_move()
        if choice is None:
            return False
        self.move(*choice)
        self.expect_readings()
        return True

    def _remounted(self, stand: int, slot: int) -> Planner:
        trial = self.fork()
        trial.remount(stand, slot)
        trial.expect_readings()
        return trial

    def _screening_moves(self) -> tuple[np.ndarray, Options]:
        """The :data:`LOOKAHEAD_MOVES` affordable moves of the highest rates, the lowest
        first, as ``np.argsort`` of :meth:`affordable_rates` over :meth:`options` ranks
        them, and the options with their gains.  From :meth:`top_rates` when those rates
        are positive and distinct, and above every other (so the ranking is the only
        one); else from every move priced, whose ties ``np.argsort`` breaks its way."""
        rate, options = self.top_rates(LOOKAHEAD_MOVES)
        top = np.argsort(rate)[-LOOKAHEAD_MOVES:]
        kept = rate[top]
        if (kept[0] > 0 and np.unique(kept).size == LOOKAHEAD_MOVES
                and np.sum(rate >= kept[0]) == LOOKAHEAD_MOVES):
            return top, options
        options = self.options()
        return np.argsort(self.affordable_rates(options))[-LOOKAHEAD_MOVES:], options

    def best_remount(self, screened: int | None = SCREENED) -> tuple[int, int] | None:
        """The re-mount (stand, slot) whose next moves gain more per second, re-mount
        included, than the next moves of the present configuration, or None.  Every
        re-mount is screened by the best :data:`LOOKAHEAD_MOVES` moves it opens, each
        priced alone; the ``screened`` best (None: all) are then played out greedily."""
        start = self._criterion_value()
        candidates = []
        for stand in range(len(self.slots)):
            for slot in range(len(slot_catalogue(self.design))):
                if slot in self.slots:
                    continue
                trial = self._remounted(stand, slot)
                top, options = trial._screening_moves()
                gain = start - trial._criterion_value() + options.gain[top].sum()
                spent = trial.time_s - self.time_s + options.seconds[top].sum()
                candidates.append((gain / spent, stand, slot))
        best, best_rate = None, self.lookahead_rate()
        ranked = sorted(candidates)
        for _, stand, slot in ranked[-screened:] if screened else ranked:
            rate = self._remounted(stand, slot).lookahead_rate(start, self.time_s)
            if rate > best_rate:
                best, best_rate = (stand, slot), rate
        return best


def greedy_plan(planner: Planner, remounts: bool = True, screened: int | None = SCREENED
                ) -> list[Step]:
    """Spend the planner's budget greedily, the operation with the most gain per second
    first (re-mounts weighed every :data:`REMOUNT_CHECK_S`, the ``screened`` most
    promising played out: see :meth:`Planner.best_remount`), and end with a stop."""
    checked = -np.inf
    while True:
        if remounts and planner.time_s - checked >= REMOUNT_CHECK_S:
            checked = planner.time_s
            choice = planner.best_remount(screened)
            if choice is not None:
                planner.remount(*choice)
                planner.expect_readings()
                continue
        if not planner.greedy_move():
            break
    planner.steps.append(Step(Op.STOP, time_s=planner.time_s))
    return planner.steps
