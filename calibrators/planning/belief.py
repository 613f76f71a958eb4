"""What an experiment being designed knows: where its stands are, whose plunger is down, its
posture, clock and operations so far, and its Gaussian belief about the unknowns.

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

A reading counts with the probability that the tip touches (it may leave the bar's reach
at the far end of the travel); a plunger goes down only where the tip stays
:data:`~orthoglide_env.lab.slot_table.SAFETY_SIGMAS` of its predicted spread plus
:data:`~orthoglide_env.lab.slot_table.END_GAP` off the pushed-in end (the candidates and
what a gauge does there: :mod:`orthoglide_env.lab.slot_table`).
A fixed plan knows each reading only a priori, so its margins are wide (up to ~3 mm);
a belief that has seen readings (:meth:`Belief.observe`) predicts them to microns and
may use the whole travel: that is what the ``active`` agent buys with its feedback.

Under ``lab`` or ``workshop`` conditions the state also holds the world's unknowns, and
the indicators' curves bias the estimate (:mod:`calibrators.planning.world_terms`).

The prices of moves: :mod:`calibrators.planning.pricing`; the choice among them:
:mod:`calibrators.planning.search`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from itertools import groupby
from operator import itemgetter
from typing import NamedTuple

import numpy as np

from calibrators.planning.instruments import instrument_kit
from calibrators.planning.world_terms import rows_many, world_terms
from orthoglide_env.lab.design_belief import (
    N_MACHINE,
    N_STAND,
    ZERO_SCALE,
    rigid_factor,  # noqa: F401  (the planner's modules import it from here)
    rigid_weight,
    shrunk,
    woodbury_gain,
)
from orthoglide_env.lab.operations import TIME, Op
from orthoglide_env.lab.slot_table import END_GAP, at_entries, reach_at, slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.world.conditions import Conditions

CRITERIA: tuple[str, ...] = ("I", "D")
#: Widening (mm) of a remembered spread before it is taken for an upper bound of the
#: present one (:meth:`Belief._reach`): far above the rounding of a spread (under 1e-6
#: mm even where it is nearly zero) and far below the microns that decide a margin.
SPREAD_SLACK: float = 1e-5


class PlannedOperation(NamedTuple):
    """One lab operation of a plan (the fields of the lab env's action) and the lab time
    at which the plan starts it; ``laser``: whether a move reads the interferometer where
    one is set up and waits its dwell (``OrthoglideLab-v4``'s key; 0 only in a plan for a
    lab that asks, :attr:`Belief.laser_asked`)."""

    op: Op
    rho: tuple[float, float, float] = (0.0, 0.0, 0.0)
    stand: int = 0
    slot: int = 0
    time_s: float = 0.0
    laser: int = 1


@lru_cache(maxsize=64)
def _stand_columns(stand: int) -> np.ndarray:
    """:meth:`Belief._columns` of ``stand``, made once."""
    start = N_MACHINE + N_STAND * stand
    out = np.concatenate((np.arange(N_MACHINE), np.arange(start, start + N_STAND)))
    out.setflags(write=False)
    return out


@lru_cache(maxsize=256)
def _block_index(stands: tuple[int, ...], size: int) -> np.ndarray:
    """The flat index (G, C, C) into a ``size`` by ``size`` covariance of the blocks of
    ``stands`` (G) over the unknowns their tips move with (:meth:`Belief._columns` but the
    zero), made once: one ``take`` gathers them, at a quarter of the price of indexing
    with the rows and columns."""
    columns = np.stack([_stand_columns(k)[:-1] for k in stands])
    out = columns[:, :, None] * size + columns[:, None, :]
    out.setflags(write=False)
    return out


@lru_cache(maxsize=512)
def _touched_block(design: MachineDesign, slot: int) -> tuple[np.ndarray, np.ndarray]:
    """Which of a stand's columns (:meth:`Belief._columns`) its rows at ``slot`` (-1:
    none) touch, and those rows (P, N_MACHINE + N_STAND), padded with zero columns
    (read-only): what :meth:`Belief.rows_of` puts in them, made once per slot, not at
    each re-mount a search tries."""
    table = slot_table(design)
    touched = np.zeros((len(table.postures), N_MACHINE + N_STAND))
    if slot < 0:
        picked = np.zeros(N_MACHINE + N_STAND, dtype=bool)
    else:
        values = np.concatenate((table.change[slot], np.full((len(touched), 1), ZERO_SCALE)),
                                axis=1)
        picked = np.any(values != 0.0, axis=0)
        touched[:, :np.count_nonzero(picked)] = values[:, picked]
    picked.setflags(write=False)
    touched.setflags(write=False)
    return picked, touched


@dataclass
class Belief:
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
    None or ``ideal``: the geometry alone.  ``dwell_s``: the seconds every move of the
    dials takes on top of its drive and settle while an instrument stays set up (the lab's
    :func:`~orthoglide_env.lab.clock.move_dwell_seconds`): 0 from a lab with nothing set
    up, the laser's dwell from one whose interferometer a reference procedure left set
    up (:func:`~calibrators.agents.optimal.move_dwell_s`), and the laser's once a plan
    sets it up (:func:`~calibrators.planning.search.take`), unless ``laser_asked``: the
    lab's moves read the laser, and wait its dwell, only where they ask
    (``OrthoglideLab-v4``'s action key ``laser``), so the plan's dial moves leave it unread
    (``laser`` 0) and pay no dwell, and only its laser bundles' moves read it."""

    slots: list[int]
    engaged: list[bool]
    sigma: float
    budget_s: float
    criterion: str = "I"
    time_s: float = 0.0
    design: MachineDesign = field(kw_only=True)
    steps: list[PlannedOperation] = field(default_factory=list)
    conditions: Conditions | None = None
    instruments: tuple[str, ...] = ()
    dwell_s: float = 0.0
    laser_asked: bool = False

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
        self.kit = instrument_kit(tuple(self.instruments), self.design, self.conditions, n)
        if self.kit is not None:
            n += len(self.kit.lead)
            if self.world is not None:
                self.world.consider = np.vstack([self.world.consider, np.zeros(
                    (len(self.kit.lead), self.world.consider.shape[1]))])
        self.covariance = np.eye(n)
        self.mean: np.ndarray | None = None  # set by observe()
        # The posture, and its index in the table: a plan starts at Zero, and moves only
        # to candidate postures.
        self.rho, self.here = np.zeros(3), self.table.zero
        k, p = len(self.slots), len(self.table.postures)
        # An upper bound of each stand's spread at every posture (see _reach).
        self.spread_bound = np.zeros((k, p))
        # Each stand's columns of the unknowns its rows touch (K, T) and its rows over
        # them (P, T) each, padded to T = N_MACHINE + N_STAND (the most a mounting
        # touches) with zero rows at column 0; replaced at a re-mount, as its rows are.
        # Its rows over every unknown (:meth:`rows_of`) are made only at the postures
        # asked for (:meth:`rows_at`): held for every posture, they were a megabyte per
        # stand, made at each re-mount a search tries.
        self.touched_columns = np.zeros((k, N_MACHINE + N_STAND), dtype=int)
        self.touched_rows: list[np.ndarray] = [np.zeros((p, N_MACHINE + N_STAND))] * k
        # Their stack by posture (P, K, T), read-only and shared by forks, the stands
        # re-mounted since it was made, and how often their rows were put in place since
        # the last re-mount (:meth:`touched_at`).
        self._touched: np.ndarray | None = None
        self._stale: frozenset[int] = frozenset()
        self._patched = 0
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
        """The state's columns (read-only) of a reading of ``stand``: the machine's errors,
        then its mounting's stand unknowns and zero (asked for at every decision)."""
        return _stand_columns(stand)

    def rows_of(self, stand: int) -> np.ndarray:
        """Rows (P, n) in mm per unit scale of a reading of ``stand`` at every posture."""
        return self.rows_at(slice(None), [stand])[:, 0]

    def rows_at(self, postures: np.ndarray | slice, stands: list[int] | None = None,
                weight: np.ndarray | None = None) -> np.ndarray:
        """Rows (L, K', n) in mm per unit scale of a reading of each of ``stands`` (K';
        default: every stand) at ``postures`` (L): its slot's changes over the machine's
        errors and its mounting's, and its zero's scale (an empty stand's are zero).
        With ``weight`` (L, K'), each stand's row at a posture times its weight, over the
        gauge's sigma: the readings' whitened rows, each entry ``(row * weight) / sigma``
        as a product of the whole array would have it, but made only where a row has
        entries (a mounting's columns are the machine's, then its stand's, two runs)."""
        stands = np.arange(len(self.slots)) if stands is None else np.asarray(stands, dtype=int)
        index = np.arange(len(self.table.postures))[postures]
        return reading_rows_many([self], stands, index[None],
                                 None if weight is None else weight[None])[0]

    def _set_rows(self, stand: int) -> None:
        """Make ``stand``'s rows those of its present mounting (:meth:`rows_of`) over the
        unknowns they touch (``touched_columns``, ``touched_rows``); its spread bound is
        the prior spread (its unknowns are as wide as a priori, the machine's at most)."""
        self.spread_bound[stand] = self.table.prior_spread[max(self.slots[stand], 0)]
        picked, touched = _touched_block(self.design, self.slots[stand])
        used = self._columns(stand)[picked]
        columns = self.touched_columns.copy()
        columns[stand] = 0
        columns[stand, :len(used)] = used
        self.touched_columns, self.touched_rows[stand] = columns, touched
        self._stale, self._patched = self._stale | {stand}, 0

    def touched_at(self, postures: np.ndarray) -> np.ndarray:
        """:attr:`touched_rows` at ``postures`` (L,), stacked by stand (K, L, T), laid out
        as a posture-major stack's rows are (a view of (L, K, T)).  Gathered from the
        stack of every stand's rows, made once per mounting of the stands, with the rows
        of a stand re-mounted since (one, in each re-mount a search tries) put in place:
        where each tried re-mount copied the stack (a megabyte), and gathering stand by
        stand cost every decision.  A belief asked again after a re-mount (a plan's own, a
        filter's, a look-ahead's) stacks them anew instead."""
        if self._touched is None or (self._stale and self._patched):
            self._touched = np.stack(self.touched_rows, axis=1)
            self._touched.setflags(write=False)
            self._stale, self._patched = frozenset(), 0
        part = np.swapaxes(self._touched.take(postures, axis=0), 0, 1)
        for stand in self._stale:
            part[stand] = self.touched_rows[stand][postures]
        self._patched += bool(self._stale)
        return part

    @property
    def rows(self) -> np.ndarray:
        """Rows (K, P, n) of every stand at every posture (:meth:`rows_at`, made anew at
        each call)."""
        return np.swapaxes(self.rows_at(slice(None)), 0, 1)

    def predicted_tips(self, postures: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Predicted tip distance of every stand's gauge at ``postures`` (K, P'), mm:
        nominal for a plan, from the mean once readings were observed.  (An empty stand
        gets slot 0's: it is masked later.)"""
        if self.mean is None:
            return self.table.tip[np.maximum(np.array(self.slots), 0)][:, postures]
        return predicted_tips_many([self], postures)[0]

    def _reach(self, postures: np.ndarray | slice = slice(None)
               ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~orthoglide_env.lab.slot_table.reach` of every stand at ``postures``
        (nothing for an empty stand, no contact where it was seen not to read):
        :func:`reaches` of this belief alone once readings were observed, else the
        table's prior reach."""
        if self.mean is not None:
            return reaches([self], postures)[0]
        slots = np.array(self.slots)
        mounted, used = (slots >= 0)[:, None], np.maximum(slots, 0)
        # Only the postures asked are gathered (one, to read here), not every one first.
        at = (used, postures) if isinstance(postures, slice) else (used[:, None], postures)
        safe, contact = (a[at] for a in self.table.prior_reach)
        return safe & mounted, np.where(self.silent[:, postures], 0.0, contact) * mounted

    def predicted_rigid_mm(self) -> float:
        """Predicted TCP error RMS after the best-fit rigid motion (mm), the considered
        world terms' bias included."""
        n = N_MACHINE
        square = np.trace(self.weight @ self.covariance[:n, :n])
        if self.world is not None:
            square += self.world.bias(self.weight)
        if self.kit is not None:
            square += self.kit.share(self.covariance)
        return float(np.sqrt(max(square, 0.0)))

    def _criterion_value(self) -> float:
        """What the plan drives down: the predicted mean-square TCP error (I), or the log
        det of the covariance (D)."""
        if self.criterion == "D":
            return float(np.linalg.slogdet(self.covariance)[1])
        return self.predicted_rigid_mm() ** 2


    # -- taking readings and mountings ----------------------------------------------------
    def _add(self, rows: np.ndarray, innovations: np.ndarray | None = None,
             considered: np.ndarray | None = None) -> None:
        """Bayesian update with whitened ``rows`` (R, n) (and, when filtering, their
        whitened innovations; with world terms, their whitened rows over the considered
        ones)."""
        if len(rows) == 0:
            return
        gain, b = woodbury_gain(self.covariance, rows)  # (n, R)
        if self.world is not None:
            self.world.update(gain, rows, considered)
        if self.mean is not None and innovations is not None:
            self.mean = self.mean + gain @ innovations
        self.covariance = shrunk(self.covariance, gain, b)

    def expect_readings(self, stands: np.ndarray | None = None,
                        weights: np.ndarray | None = None) -> None:
        """Count readings of ``stands`` here, each with its probability (a plan's; default:
        :meth:`reading_here`)."""
        if stands is None:
            stands, weights = self.reading_here()
        self._expected(weights, *rows_here_many([self], [stands])[0])

    def _expected(self, weights: np.ndarray, rows: np.ndarray, considered: np.ndarray
                  ) -> None:
        """:meth:`expect_readings` with ``weights`` of the readings of rows ``rows`` (R, n)
        and ``considered`` (R, m) here (:func:`rows_here_many`)."""
        weight = np.sqrt(weights)[:, None]
        self._add(rows * weight / self.sigma, considered=considered * weight / self.sigma)

    def observe(self, stands: list[int], values: list[float]) -> None:
        """Readings (mm) of ``stands`` taken here (every other engaged stand read nothing):
        update the mean and the covariance (:func:`observe_many` of this belief alone)."""
        observe_many([self], [stands], [values])

    def _observed(self, stands: np.ndarray, values: list[float], rows: np.ndarray,
                  considered: np.ndarray) -> None:
        """:meth:`observe`'s update by the readings of ``stands`` (some), of rows ``rows``
        (R, n) and ``considered`` (R, m) (:func:`rows_here_many`)."""
        nominal = self.table.reading[[self.slots[k] for k in stands], self.here]
        predicted = nominal + rows @ self.mean
        self._add(rows / self.sigma, (np.asarray(values, dtype=float) - predicted) / self.sigma,
                  considered / self.sigma)

    def retire(self, stand: int) -> None:
        """A stand that reads no more (pushed past its travel) until it is re-mounted."""
        self.slots[stand] = -1
        self.engaged[stand] = False
        self._set_rows(stand)

    def remount_seconds(self) -> float:
        """Seconds a re-mount takes from here, as the lab's clock charges it: the drive to
        Zero, then the stand's work."""
        return float(TIME.move(self.rho, np.zeros(3))) + TIME.remount_s

    def remount(self, stand: int, slot: int) -> None:
        """Move ``stand`` to ``slot`` (the machine drives to Zero first): a new mounting
        with fresh unknowns, its plunger down."""
        if slot in self.slots:
            raise ValueError(f"slot {slot} already holds a stand")
        self.steps.append(PlannedOperation(Op.REMOUNT, stand=stand, slot=slot, time_s=self.time_s))
        self.time_s += self.remount_seconds()
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


def reading_rows_many(beliefs: list[Belief], stands: np.ndarray, postures: np.ndarray,
                      weight: np.ndarray | None = None) -> np.ndarray:
    """:meth:`Belief.rows_at` of each of ``beliefs`` (one design, as many unknowns and
    stands each) at its ``postures`` (M, L) for ``stands`` (K'), with its ``weight`` (M,
    L, K') if any, stacked (M, L, K', n): each entry ``(row * weight) / sigma`` as each
    belief alone has it, made only where a row has entries."""
    first_belief = beliefs[0]
    table = first_belief.table
    slots = np.array([b.slots for b in beliefs])[:, stands]  # (M, K')
    out = np.zeros((*postures.shape, len(stands), len(first_belief.covariance)))
    mounted = slots >= 0
    if not mounted.any():
        return out
    # (M, L, K', C): each stand's changes at the postures.
    values = table.change[np.maximum(slots, 0)[:, None, :], postures[:, :, None]]
    zero: float | np.ndarray = ZERO_SCALE
    if weight is not None:
        sigma = np.array([b.sigma for b in beliefs])
        values = values * weight[..., None] / sigma[:, None, None, None]
        zero = ZERO_SCALE * weight / sigma[:, None, None]
    # A mounting's columns are the machine's, then its stand's (the zero's last).
    first = N_MACHINE + N_STAND * stands
    each = np.arange(len(stands))
    out[..., :N_MACHINE] = values[..., :N_MACHINE]
    out[..., each[:, None], first[:, None] + np.arange(N_STAND - 1)] = values[..., N_MACHINE:]
    out[..., each, first + N_STAND - 1] = zero
    out.transpose(0, 2, 1, 3)[~mounted] = 0.0  # an empty stand's rows are zero
    return out


def predicted_tips_many(beliefs: list[Belief], postures: np.ndarray | slice = slice(None)
                        ) -> np.ndarray:
    """:meth:`Belief.predicted_tips` of filters ``beliefs`` (readings observed, one design,
    as many stands each) stacked (M, K, P'), each to the bit as alone: the stands at one
    slot share its table of changes, their means' products with it in one stacked
    product (item by item, as one belief's)."""
    table = beliefs[0].table
    slots = np.maximum(np.array([b.slots for b in beliefs]), 0)  # (M, K)
    tip = table.tip[slots][..., postures]
    means = _tip_means(beliefs)
    for slot in np.unique(slots):
        at = slots == slot
        change = np.matmul(table.change[slot][postures], means[at][..., None])[..., 0]
        tip[at] += table.sign[slot] * change
    return tip


def tips_at(beliefs: list[Belief], asked: tuple[np.ndarray, np.ndarray, np.ndarray]
            ) -> np.ndarray:
    """:func:`predicted_tips_many` at every posture, at the entries ``asked`` alone
    (machine, stand and posture indices), each to the bit as it has it there.

    A slot's stands get their changes at the postures asked of any of them, not at all
    1,500: a few hundred where a stand may go down.  BLAS's matrix-vector kernel takes
    the rows of a stand's product four at a time and any rows left over its own way (a
    few ulps off), and a slot table holds a multiple of four postures: so the postures
    asked are padded to a multiple of four by repeating the last, and each row's value
    is the full product's, whichever others are computed with it."""
    table = beliefs[0].table
    slots = np.maximum(np.array([b.slots for b in beliefs]), 0)  # (M, K)
    m, k, j = asked
    pair = m * slots.shape[1] + k
    slot = slots.ravel()[pair]
    tips = at_entries(table.tip, slot, j)
    means = _tip_means(beliefs)
    # Each (machine, stand)'s row in its slot's product, each posture's column in it.
    row_of = np.zeros(slots.size, dtype=int)
    column_of = np.zeros(len(table.postures), dtype=int)
    # The slots of the (machine, stand) pairs, not of the entries: as many, far fewer.
    for value in np.unique(slots):
        mine = np.flatnonzero(slot == value)
        if not mine.size:
            continue
        at = slots == value
        row_of[np.flatnonzero(at)] = np.arange(np.count_nonzero(at))
        needed = np.zeros(len(table.postures), dtype=bool)
        needed[j[mine]] = True
        postures = np.flatnonzero(needed)
        column_of[postures] = np.arange(len(postures))
        rows = np.concatenate((postures, np.full(-len(postures) % 4, postures[-1])))
        change = np.matmul(table.change[value][rows], means[at][..., None])[..., 0]
        tips[mine] += table.sign[value] * change.take(row_of[pair[mine]] * change.shape[1]
                                                      + column_of[j[mine]])
    return tips


def _tip_means(beliefs: list[Belief]) -> np.ndarray:
    """The means (M, K, C) of the unknowns each stand's tip moves with (:meth:`Belief.
    _columns` but the zero) of filters ``beliefs``."""
    columns = np.stack([_stand_columns(k)[:-1] for k in range(len(beliefs[0].slots))])
    return np.stack([b.mean for b in beliefs])[:, columns]


@lru_cache(maxsize=8)
def _change_bound(design: MachineDesign) -> float:
    """The largest sum of absolute changes (mm per unit) over a row of the design's slot
    table: a tip's change from means of at most ``x`` in size is at most this times
    ``x``."""
    return float(np.max(np.sum(np.abs(slot_table(design).change), axis=-1)))


def _missed(beliefs: list[Belief], used: np.ndarray) -> np.ndarray:
    """Where each stand's predicted tip (:func:`predicted_tips_many`, M, K, P) misses its
    bar (NaN): the table's nominal misses where :func:`_misses_nominal`, else read off
    the tips themselves."""
    if _misses_nominal(beliefs):
        return _nominal_misses(beliefs[0].design)[used]
    return np.isnan(predicted_tips_many(beliefs))


def _misses_nominal(beliefs: list[Belief]) -> bool:
    """Whether the predicted tips of filters ``beliefs`` miss their bars where the nominal
    ones do: a predicted tip is the nominal one plus a product of finite changes with the
    means, finite (no NaN, no overflow) when the means are finite and below ``1e300`` over
    :func:`_change_bound`."""
    size = np.max(np.abs(_tip_means(beliefs)))
    return bool(np.isfinite(size) and size * _change_bound(beliefs[0].design) < 1e300)


@lru_cache(maxsize=8)
def _nominal_misses(design: MachineDesign) -> np.ndarray:
    """Where the nominal tip of each slot misses its bar at each posture (S, P), read-only:
    made once, where each decision gathered every stand's tips to test them."""
    out = np.isnan(slot_table(design).tip)
    out.setflags(write=False)
    return out


def _asked_and_spared(beliefs: list[Belief], used: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Where each stand at slot ``used`` (M, K) of filters ``beliefs`` is to have its reach
    worked out if its plunger may be down (its tip meets its bar and no bar presses it),
    and where it is safe without (its tip misses its bar and no bar comes near), (M, K,
    P) each.  Where :func:`_misses_nominal`, one gather each of both masks of every slot
    (:func:`_nominal_masks`), where the misses, the presses and the near bars were
    gathered and combined at every decision; else from the predicted tips' misses."""
    if _misses_nominal(beliefs):
        asked, spared = _nominal_masks(beliefs[0].design)
        return asked[used], spared[used]
    table, missed = beliefs[0].table, _missed(beliefs, used)
    return ~missed & ~table.pressed[used], missed & ~table.near[used]


@lru_cache(maxsize=8)
def _nominal_masks(design: MachineDesign) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_asked_and_spared`'s masks of every slot at every posture (S, P) for the
    nominal misses, read-only, made once."""
    table, missed = slot_table(design), _nominal_misses(design)
    out = ~missed & ~table.pressed, missed & ~table.near
    for mask in out:
        mask.setflags(write=False)
    return out


def entries(mask: np.ndarray) -> tuple[np.ndarray, ...]:
    """``np.nonzero(mask)``: the same index arrays, in the same order, worked out from
    the flat index of the entries set (a third of the price on the moves' arrays of every
    machine, stand and posture, where a few percent are set)."""
    flat = np.flatnonzero(mask)
    out = []
    for size in reversed(mask.shape[1:]):
        flat, index = np.divmod(flat, size)
        out.append(index)
    return (flat, *reversed(out))


def reaches(beliefs: list[Belief], postures: np.ndarray | slice = slice(None)
            ) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`~orthoglide_env.lab.slot_table.reach` of every stand at ``postures``
    (nothing for an empty stand, no contact where it was seen not to read) of each of
    filters ``beliefs`` (readings observed, one design, as many stands each), stacked over
    them: each to the bit as alone.

    A spread is computed only where the answer depends on it.  Not where the tip misses
    its bar or a bar presses the gauge, nor where the tip is less than :data:`END_GAP` off
    the end, and not where the stand's spread bound (``spread_bound``) already leaves the
    tip safe and touching (contact exactly 1): the spread, at most the bound, would leave
    it so too.  The bound is the prior spread at a mounting, then each spread as last
    computed, plus :data:`SPREAD_SLACK`: readings only shrink the covariance, so a spread
    never grows until its stand is re-mounted."""
    tip, spread, index = _tips_and_bounds(beliefs, postures)
    safe, contact = np.zeros(tip.shape, dtype=bool), np.zeros(tip.shape)
    _reach_where(beliefs, tip.ravel(), spread.ravel(), index,
                 np.nonzero(np.ones(tip.shape, dtype=bool)), safe, contact)
    return list(zip(*_unread(beliefs, safe, contact, postures), strict=True))


def move_reaches(beliefs: list[Belief]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reaches` at every posture of filters ``beliefs``, as far as the moves from
    where each stands depend on it (:func:`~calibrators.planning.pricing.moves_many`: the
    plungers down after a move and how likely each reads), each to the bit as
    :func:`reaches` has it there, stacked (M, K, P).

    A plunger is down after a move only if it is down now or safe here, so every stand's
    reach is worked out here first; then a stand that may be down is predicted only where
    its tip meets its bar and no bar presses it, a few hundred of the 1,500 postures (a
    missed bar's safety is the table's, a pressed gauge is never safe, and neither
    reads).  A stand that stays up is left out everywhere else: its ``safe`` there is
    False, whatever its reach."""
    table = beliefs[0].table
    slots = np.array([b.slots for b in beliefs])  # (M, K)
    used, mounted = np.maximum(slots, 0), slots >= 0
    index = np.arange(len(table.postures))
    machines, here = np.arange(len(beliefs)), np.array([b.here for b in beliefs])
    count = slots.shape[1]
    # Both passes fill one pair of arrays: their entries are apart (here, then elsewhere),
    # the first's taken in the order a mask's would be (machine, stand).  The second
    # reads no spread bound the first lowered, and each reads the bounds at its own
    # entries alone (:func:`_bounds_at`).
    safe, contact = np.zeros((*slots.shape, len(index)), dtype=bool), np.zeros(
        (*slots.shape, len(index)))
    first = (np.repeat(machines, count), np.tile(np.arange(count), len(beliefs)),
             np.repeat(here, count))
    _reach_where(beliefs, tips_at(beliefs, first), _bounds_at(beliefs, first), index, first,
                 safe, contact)
    may = (np.array([b.engaged for b in beliefs]) | safe[machines, :, here]) & mounted
    asked, spared = _asked_and_spared(beliefs, used)
    asked = may[..., None] & asked
    asked[machines, :, here] = False
    second = entries(asked)
    _reach_where(beliefs, tips_at(beliefs, second), _bounds_at(beliefs, second), index,
                 second, safe, contact)
    safe |= may[..., None] & spared
    return _unread(beliefs, safe, contact, slice(None))


def _tips_and_bounds(beliefs: list[Belief], postures: np.ndarray | slice
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every stand's predicted tip (M, K, P') at ``postures`` of each of ``beliefs``, the
    upper bound of its spread there (:func:`_spread_bounds`) and the postures' indices
    (P')."""
    return (predicted_tips_many(beliefs, postures), _spread_bounds(beliefs, postures),
            np.arange(len(beliefs[0].table.postures))[postures])


def _spread_bounds(beliefs: list[Belief], postures: np.ndarray | slice) -> np.ndarray:
    """The upper bound (M, K, P') of every stand's spread at ``postures`` of each of
    ``beliefs``, :data:`SPREAD_SLACK` added."""
    return np.stack([b.spread_bound[:, postures] for b in beliefs]) + SPREAD_SLACK


def _bounds_at(beliefs: list[Belief], asked: tuple[np.ndarray, np.ndarray, np.ndarray]
               ) -> np.ndarray:
    """:func:`_spread_bounds` at every posture, at the entries ``asked`` alone (machine,
    stand and posture indices, in C order): gathered from each belief's bounds, not from
    a stack of every belief's at every posture (megabytes, for a few hundred entries a
    stand)."""
    m, k, j = asked
    out = np.empty(len(m))
    for first, last in _runs(m):
        out[first:last] = at_entries(beliefs[m[first]].spread_bound, k[first:last],
                                     j[first:last])
    out += SPREAD_SLACK
    return out


def _runs(machines: np.ndarray) -> list[tuple[int, int]]:
    """The bounds (first, past the last) of each run of one value in ``machines``: the
    entries of each belief, which come belief by belief."""
    if not len(machines):
        return []
    firsts = np.flatnonzero(np.r_[True, machines[1:] != machines[:-1]]).tolist()
    return list(zip(firsts, [*firsts[1:], len(machines)], strict=True))


def _reach_where(beliefs: list[Belief], tips: np.ndarray, spreads: np.ndarray,
                 index: np.ndarray, asked: tuple[np.ndarray, np.ndarray, np.ndarray],
                 safe: np.ndarray, contact: np.ndarray) -> None:
    """:func:`reaches`' ``safe`` and ``contact`` (M, K, P') from the predicted tips and the
    spread bounds (:func:`_spread_bounds`) at the entries ``asked`` (machine, stand and
    posture indices, in C order), entered at those entries, each entry's answer its own:
    a spread computed where the bound leaves it open (each stand's together, in the order
    of its postures), its bound lowered to it (in ``spreads`` too)."""
    table = beliefs[0].table
    slots = np.array([b.slots for b in beliefs])
    m, k, j = asked
    # The entries' places in the (M, K) and (M, K, P') arrays, flat: one ``take`` or
    # ``put`` each instead of indexing with two or three arrays.
    pair = m * slots.shape[1] + k
    flat = pair * safe.shape[2] + j
    slot, posture = slots.take(pair), index[j]
    mounted = slot >= 0
    slot = np.maximum(slot, 0)
    safe_at, contact_at = reach_at(table, slot, posture, tips, spreads)
    with np.errstate(invalid="ignore"):
        open_ = np.flatnonzero((tips >= END_GAP) & (contact_at < 1.0)
                               & ~at_entries(table.pressed, slot, posture) & mounted)
    if open_.size:
        mine, own, at = m[open_], k[open_], posture[open_]
        spreads[open_] = value = spreads_many(beliefs, mine, own, at)
        # Each belief's bounds lowered at once (its entries are consecutive).
        for first, last in _runs(mine):
            bound = beliefs[mine[first]].spread_bound
            np.put(bound, own[first:last] * bound.shape[1] + at[first:last],
                   value[first:last])
        safe_at[open_], contact_at[open_] = reach_at(table, slot[open_], at, tips[open_],
                                                     spreads[open_])
    np.put(safe, flat, safe_at)
    np.put(contact, flat, contact_at)


def spreads_many(beliefs: list[Belief], machines: np.ndarray, stands: np.ndarray,
                 postures: np.ndarray) -> np.ndarray:
    """Standard deviation (N,) of the predicted tip of each entry's stand of ``stands``
    (N,) of its belief of ``machines`` (N,, indices in ``beliefs``, one design) at its
    posture of ``postures`` (N,), mm, from the covariances, in a few stacked products: the
    entries of one (belief, stand) are consecutive, the beliefs in order.  The stands go
    to :data:`SPREAD_BUCKETS` products by the count of their entries, each stand's rows
    padded to its product's even count by repeating its last posture, so each item goes
    to BLAS as an even count of rows, the value of a posture the same to the bit
    whichever others are computed with it (BLAS's kernels take a lone last row their own
    way, a few ulps off), and a stand of few entries is not padded to the longest."""
    table = beliefs[0].table
    pair = machines * len(beliefs[0].slots) + stands
    starts = np.flatnonzero(np.r_[True, pair[1:] != pair[:-1]])  # each (belief, stand)'s
    lengths = np.diff(np.r_[starts, len(pair)])
    first_machine, first_stand = machines[starts], stands[starts]
    slots = np.array([b.slots for b in beliefs])[first_machine, first_stand]
    # Each belief's stands' blocks of its covariance gathered at once (the pairs come
    # belief by belief).
    covariance = np.concatenate([
        beliefs[i].covariance.take(_block_index(tuple(int(s) for _, s in pairs),
                                                len(beliefs[i].covariance)))
        for i, pairs in groupby(zip(first_machine, first_stand, strict=True),
                                key=itemgetter(0))])
    postures_count, columns = table.change.shape[1:]
    out = np.empty(len(pair))
    for groups in _by_length(lengths):
        length = lengths[groups]
        longest = int(length[-1])
        longest += longest % 2
        # Each group's postures, its last repeated up to the even count (G, L).
        places = starts[groups, None] + np.minimum(np.arange(longest), length[:, None] - 1)
        # (G, L, C): each posture's row of its slot's changes, taken from the rows of every
        # slot's (as one ``take``: a third of the price of indexing with slots and
        # postures).
        change = np.take(table.change.reshape(-1, columns),
                         slots[groups, None] * postures_count + postures[places], axis=0)
        product = change @ covariance[groups]
        values = np.sqrt(np.clip(np.sum(product * change, axis=-1), 0.0, None))
        real = np.arange(longest) < length[:, None]
        out[places[real]] = values[real]
    return out


#: The products :func:`spreads_many` splits its stands over, by their counts of entries
#: (a stand's entries are the postures where its spread is open: a few to a few hundred).
SPREAD_BUCKETS: int = 6


def _by_length(lengths: np.ndarray) -> list[np.ndarray]:
    """The indices of ``lengths`` in up to :data:`SPREAD_BUCKETS` runs of as many of them,
    from the shortest up, each run in increasing length (its last the longest)."""
    order = np.argsort(lengths, kind="stable")
    return [part for part in np.array_split(order, min(SPREAD_BUCKETS, len(order)))
            if part.size]


def _unread(beliefs: list[Belief], safe: np.ndarray, contact: np.ndarray,
            postures: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray]:
    """The beliefs' ``safe`` and ``contact`` (M, K, P') at ``postures``, nothing for an
    empty stand and no contact where it was seen not to read: both arrays changed in
    place (megabytes each, made for this)."""
    np.copyto(contact, 0.0, where=np.stack([b.silent[:, postures] for b in beliefs]))
    # An empty stand's rows zeroed at once: the same as a product with 0 or 1 for the
    # probabilities (finite, non-negative) and a logical and for the plungers.
    empty = np.array([b.slots for b in beliefs]) < 0
    contact[empty] = 0.0
    safe[empty] = False
    return safe, contact


def world_rows_here(beliefs: list[Belief], stands: list[np.ndarray]
                    ) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """What the world adds to readings of each belief's ``stands`` (R,) here and now: the
    fitted unknowns' rows (R, count) and the considered ones' (R, m), None without world
    terms.  Beliefs of one design, conditions and stand count reading as many stands,
    with as many considered terms, in one stacked pass
    (:func:`~calibrators.planning.world_terms.rows_many`): each its own alone."""
    out: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(beliefs)
    groups: dict[tuple, list[int]] = {}
    for i, (belief, read) in enumerate(zip(beliefs, stands, strict=True)):
        if belief.world is not None:
            key = (len(read), len(belief.slots), belief.world.consider.shape, belief.design,
                   belief.conditions)
            groups.setdefault(key, []).append(i)
    for members in groups.values():
        group = [beliefs[i] for i in members]
        fitted, considered = rows_many(
            [b.world for b in group], np.array([b.slots for b in group]),
            np.array([[b.here] for b in group]), np.array([[b.time_s] for b in group]),
            np.stack([b.world.approach for b in group])[:, None],
            np.array([np.asarray(stands[i], dtype=int) for i in members]).reshape(
                len(members), -1))
        for i, f, c in zip(members, fitted, considered, strict=True):
            out[i] = f[:, 0], c[:, 0]
    return out


def rows_here_many(beliefs: list[Belief], stands: list[np.ndarray]
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The rows (R, n) of readings of each belief's ``stands`` (R,) here and now, mm per
    unit, and (with world terms) their rows over the considered terms (R, m; else R by
    0).  Beliefs of one slot table, stand count and unknowns get every stand's rows here
    in one stacked pass (:func:`reading_rows_many`, element by element), each reading
    its own stands off them, and the world's rows are stacked too
    (:func:`world_rows_here`): each its own alone, where each belief made its rows
    alone."""
    index = [np.asarray(read, dtype=int) for read in stands]
    out: list[tuple[np.ndarray, np.ndarray]] = []
    every: dict[int, np.ndarray] = {}
    groups: dict[tuple, list[int]] = {}
    for i, belief in enumerate(beliefs):
        groups.setdefault((id(belief.table), len(belief.slots), len(belief.covariance)),
                          []).append(i)
    for members in groups.values():
        group = [beliefs[i] for i in members]
        rows = reading_rows_many(group, np.arange(len(group[0].slots)),
                                 np.array([[b.here] for b in group]))
        every.update((i, rows[j, 0]) for j, i in enumerate(members))
    for i, (belief, world) in enumerate(zip(beliefs, world_rows_here(beliefs, index),
                                            strict=True)):
        rows = every[i][index[i]]  # a copy: its own to change
        if world is None:
            out.append((rows, np.zeros((len(index[i]), 0))))
            continue
        fitted, considered = world
        rows[:, belief.world.start:belief.world.start + belief.world.count] += fitted
        out.append((rows, considered))
    return out


def expect_many(beliefs: list[Belief]) -> None:
    """:meth:`Belief.expect_readings` of each of ``beliefs`` (every stand down here, each
    with its probability of reading), the rows of their readings stacked
    (:func:`rows_here_many`): each belief's update its own alone, to the bit."""
    here = [belief.reading_here() for belief in beliefs]
    rows = rows_here_many(beliefs, [stands for stands, _ in here])
    for belief, (_, weights), (row, considered) in zip(beliefs, here, rows, strict=True):
        belief._expected(weights, row, considered)


def observe_many(beliefs: list[Belief], stands: list[list[int]], values: list[list[float]]
                 ) -> None:
    """:meth:`Belief.observe` of each of ``beliefs`` (one per machine of a chunk) with its
    ``stands`` and ``values``, the rows of their readings stacked
    (:func:`rows_here_many`): each belief's update its own alone, to the bit."""
    reading = []
    for belief, read in zip(beliefs, stands, strict=True):
        if belief.mean is None:
            belief.mean = np.zeros(len(belief.covariance))
        quiet = [k for k, down in enumerate(belief.engaged) if down and k not in read]
        belief.silent[quiet, belief.here] = True
        reading.append(np.asarray(read, dtype=int))
    live = [i for i, read in enumerate(reading) if read.size]
    rows = rows_here_many([beliefs[i] for i in live], [reading[i] for i in live])
    for i, (row, considered) in zip(live, rows, strict=True):
        beliefs[i]._observed(reading[i], values[i], row, considered)
