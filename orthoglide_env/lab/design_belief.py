"""What the readings so far determine, at the nominal machine: the Gaussian belief of an
experiment as it runs, updated in closed form, and the candidate operations open to it.

The unknowns are Gaussian, each in units of its a-priori size: the machine's 27 errors
(the realistic preset's sigmas, the estimators' priors), then :data:`N_STAND` per stand's
present mounting, its stand's four installation errors and its dial's zero
(:data:`ZERO_SCALE`, diffuse: the estimators eliminate it).  A reading is a row of
derivatives at the nominal machine divided by the gauge's sigma, so each reading updates
the covariance by a rank-one (Woodbury) step, and the predicted mean-square TCP error
after the best-fit rigid motion is ``trace(W C)`` (:func:`rigid_weight`): microseconds,
never a fit.  The readings' values do not enter: at the nominal machine the covariance
depends on where and by which mounting each reading was taken, not on what it read, so
two machines read at the same places have the same belief.

The experiment planner (``calibrators.planning.belief``) builds on the same rows and
update; :class:`DesignBelief` is the lean form the env's design wrappers
(:mod:`orthoglide_env.wrappers`) keep for a learner: geometry only (the ``lab`` world's
drift and indicator curves are not in it), the candidate operations of the slot table
(:mod:`orthoglide_env.lab.slot_table`) as actions, and a plunger let down only where the
a-priori spread of its reading keeps it safe, as a fixed plan does.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache, partial

import numpy as np

from orthoglide_env.lab.operations import TIME, Op
from orthoglide_env.lab.rewards import ACCURACY_UNIT_MM
from orthoglide_env.lab.slot_table import SlotTable, slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import ERROR_NAMES, MachineParams
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring import rigid_weights

N_MACHINE = len(ERROR_NAMES)
#: Unknowns of one mounting besides the machine's: four of its stand, then its zero.
N_STAND = 5
#: A dial's zero, a priori (mm): wide enough to be eliminated by the first reading, as the
#: estimators do exactly.
ZERO_SCALE: float = 10.0
#: Added to every mean square (in units of ``ACCURACY_UNIT_MM`` squared) before its log is
#: observed: (0.01 µm)^2, far below what any reading resolves, so the log stays finite
#: where an eigenvalue is a rounding of zero.
LOG_FLOOR: float = 1e-6
#: A move is a candidate when some stand reads there at least this likely, a priori: the
#: planner prices a move whose every reading is unlikely (down to 1e-144 at the far end
#: of a gauge's travel) at next to nothing, and a learner would only spend time there.
READ_PROBABILITY: float = 0.5
#: States (stands, plungers, posture) whose candidate moves a process keeps per design
#: (:func:`state_moves`, about 100 kB each with six stands): a policy that has learnt
#: its experiment passes the same states on every machine, and its decision then costs no
#: pass over the postures.
MOVES_KEPT: int = 256
#: Views of the design (:attr:`DesignBelief.version`): 0, the predicted error's spectrum,
#: the stands, the posture and the clock; 1 adds how the present posture has been read
#: (:meth:`DesignBelief.reading_history`); 2 replaces the spectrum by the readings taken at
#: every posture (:meth:`DesignBelief.posture_counts`), which determine it.
VIEW_VERSIONS: tuple[int, ...] = (0, 1, 2)
#: The views whose observation is a function of the covariance (its spectrum, a reading's
#: fall): a belief of another view observes without following it.
SPECTRUM_VIEWS: tuple[int, ...] = (0, 1)
#: Readings are counted in units of this many in view 1's observation: a scale of the
#: learner's input (an expert's stays are up to about 20 readings), no physical size.
COUNT_SCALE: float = 10.0
#: Added to a reading's relative fall of the predicted mean square before its log is
#: observed (view 1): a fall of a millionth is below what a learner needs to tell apart,
#: and a reading that adds nothing (no stand read) keeps a finite log.
FALL_FLOOR: float = 1e-6


@lru_cache(maxsize=2)
def rigid_weight(design: MachineDesign) -> np.ndarray:
    """``W`` (27, 27): ``trace(W C)`` is the predicted mean-square TCP error over the
    scoring grid after the best-fit rigid motion (mm^2) for machine errors off by
    ``N(0, C)`` in units of their scale (the quadratic form of
    :func:`orthoglide_env.scoring.predicted_frame_errors`)."""
    scale = default_scales(ParameterSpace())
    return rigid_weights([MachineParams(design=design)])[0] * np.outer(scale, scale)


@lru_cache(maxsize=2)
def rigid_factor(design: MachineDesign) -> np.ndarray:
    """``F`` (27, r) with ``F F' = W`` (:func:`rigid_weight`): ``W`` has rank ``r``, 12 on
    the prototype, as many errors only move the tool rigidly or as others do.  The
    eigenvalues below 1e-12 of the largest are the rounding of those zeros."""
    value, vector = np.linalg.eigh(rigid_weight(design))
    keep = value > 1e-12 * value[-1]
    return vector[:, keep] * np.sqrt(value[keep])


@lru_cache(maxsize=2)
def drive_seconds(design: MachineDesign) -> np.ndarray:
    """Seconds (P, P) to drive from each of the design's candidate postures to each and
    settle (:meth:`~orthoglide_env.lab.operations.TimeTable.move`), read-only: 18 MB on the
    prototype, computed once per process and design (a tenth of a second)."""
    postures = slot_table(design).postures
    seconds = TIME.move(postures[:, None], postures[None])
    seconds.flags.writeable = False
    return seconds


#: A state's candidate moves (:func:`candidate_moves`): their seconds (P,), the plungers
#: down after them and how likely each reads (K, P), which of them some stand reads at
#: least :data:`READ_PROBABILITY` likely (P,), and the longest of those in seconds.
Moves = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]


def candidate_moves(design: MachineDesign, slots: bytes, faulted: bytes, engaged: bytes,
                    here: int) -> Moves:
    """The candidate moves of a state (see :meth:`DesignBelief.moves`), from the bytes of
    its stands' slots (int64, -1: none), out-of-service and engaged flags (bool) and its
    posture's index (:data:`Moves`; the arrays read-only)."""
    table = slot_table(design)
    slot = np.frombuffer(slots, dtype=np.int64)
    down = np.frombuffer(engaged, dtype=bool)
    safe, contact = (a[np.maximum(slot, 0)] for a in table.prior_reach)
    safe = safe & ((slot >= 0) & ~np.frombuffer(faulted, dtype=bool))[:, None]
    after = safe & (down | safe[:, here])[:, None]
    reads = np.where(after, contact, 0.0)
    flicks = np.count_nonzero(after != down[:, None], axis=0)
    seconds = drive_seconds(design)[here] + TIME.lift_s * flicks
    readable = (reads >= READ_PROBABILITY).any(axis=0)
    for array in (seconds, after, reads, readable):
        array.flags.writeable = False
    return seconds, after, reads, readable, float(np.max(seconds, initial=-np.inf,
                                                         where=readable))


@lru_cache(maxsize=2)
def state_moves(design: MachineDesign) -> Callable[[bytes, bytes, bytes, int], Moves]:
    """:func:`candidate_moves` of ``design``'s states, the last :data:`MOVES_KEPT` of them
    kept: a belief holds this function, so that finding a state's moves hashes the state's
    bytes and not the design (a microsecond and a half a decision)."""
    return lru_cache(maxsize=MOVES_KEPT)(partial(candidate_moves, design))


@lru_cache(maxsize=2)
def posture_index(design: MachineDesign) -> dict[bytes, int]:
    """Each of the design's candidate postures' index in the slot table, by the bytes of
    its joint targets (float64): a move's posture found without a pass over them."""
    return {p.tobytes(): k for k, p in enumerate(slot_table(design).postures)}


def woodbury_gain(covariance: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The gain ``K`` (n, R) of whitened readings ``rows`` (R, n) on a belief of
    ``covariance`` (n, n), and ``B = C R'`` (n, R): the posterior is :func:`shrunk`."""
    b = covariance @ rows.T
    m = np.eye(len(rows)) + rows @ b
    return np.linalg.solve(m, b.T).T, b


def shrunk(covariance: np.ndarray, gain: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The covariance after the readings of gain ``gain`` and ``B`` (:func:`woodbury_gain`),
    kept symmetric."""
    covariance = covariance - gain @ b.T
    return (covariance + covariance.T) / 2


def _transposed(matrices: np.ndarray) -> np.ndarray:
    """Each matrix of a stack (..., a, b) transposed."""
    return np.swapaxes(matrices, -1, -2)


class DesignBelief:
    """A lab experiment's belief as it runs (see the module), and its candidate operations:
    a move to each of the slot table's ``P`` postures (with the lever flicks it needs),
    a re-mount of each of ``K`` stands at each of the ``S`` slots of the design's
    catalogue, and stop: ``P + K S + 1`` operations, in that order.

    ``sigma``: a reading's standard deviation (mm), ``budget_s``: the lab's time budget,
    ``version``: the view its :meth:`observation` is (:data:`VIEW_VERSIONS`),
    ``covariance``: whether it follows the covariance (the Woodbury steps; needed for the
    predicted error, the reward, and the observation of the :data:`SPECTRUM_VIEWS`).  A
    policy of view 2 decides from the readings' counts alone, so its agent's belief skips
    the covariance, the larger part of a decision's cost.  It follows the lab from its
    observations (:meth:`start`, :meth:`observe`), never from its truth."""

    def __init__(self, design: MachineDesign, stands: int, sigma: float, budget_s: float,
                 version: int = 0, covariance: bool = True) -> None:
        if not (np.isfinite(sigma) and sigma > 0):
            raise ValueError(f"sigma must be a positive number, got {sigma}")
        if version not in VIEW_VERSIONS:
            raise ValueError(f"version must be one of {VIEW_VERSIONS}, got {version!r}")
        if not covariance and version in SPECTRUM_VIEWS:
            raise ValueError(f"view {version} observes the covariance: a belief of it follows "
                             "the covariance")
        self.design, self.sigma, self.budget_s = design, float(sigma), float(budget_s)
        self.version, self.follows = version, bool(covariance)
        self.table: SlotTable = slot_table(design)
        self.n_postures, self.n_slots, self.n_stands = (
            len(self.table.postures), len(self.table.tip), int(stands))
        self.n_actions = self.n_postures + self.n_stands * self.n_slots + 1
        self.weight, self.factor = rigid_weight(design), rigid_factor(design)
        # Found once: their caches are keyed by the design, whose hash every step would pay.
        self.drive_s, self.index = drive_seconds(design), posture_index(design)
        self._moves_of = state_moves(design)
        #: Each stand's columns (K, 32): the machine's errors, then its mounting's.
        self.stand_columns = np.array([self._columns(k) for k in range(self.n_stands)])
        self.start({"slot": np.full(stands, self.n_slots), "engaged": np.zeros(stands),
                    "faulted": np.zeros(stands), "valid": np.zeros(stands),
                    "time": np.zeros(1)})

    # -- following the lab ------------------------------------------------------------------
    def start(self, observation: dict[str, np.ndarray]) -> None:
        """A fresh belief at Zero from the lab's first observation (its readings at Zero)."""
        self.covariance = np.eye(N_MACHINE + N_STAND * self.n_stands)
        self.here, self.rho = self.table.zero, np.zeros(3)
        #: Readings taken at each posture (a move's or a re-mount's, of any stand or none),
        #: in a row at the present one, and the relative fall of the predicted mean square
        #: by the last.
        self.readings_at = np.zeros(self.n_postures, dtype=np.int64)
        self.run, self.fall = 0, 0.0
        #: The array whose row ``_index`` (``_row``) the covariance is, when
        #: :func:`observe_many` keeps it so.
        self._stack: np.ndarray | None = None
        self._index, self._row = -1, self.covariance
        self._sync(observation)
        self._read(observation)

    def observe(self, operation: dict[str, object], observation: dict[str, np.ndarray],
                refused: bool) -> None:
        """Take in the lab's observation after ``operation`` (a lab action, as
        :meth:`operations` gives them): a move's readings, a re-mount's fresh unknowns and
        its readings at Zero.  A refused operation changes nothing but the clock."""
        reads = self._step(operation, refused)
        self._sync(observation)
        if reads:
            self._read(observation)

    def _step(self, operation: dict[str, object], refused: bool) -> bool:
        """:meth:`observe`'s bookkeeping of the operation itself (a re-mount's fresh
        unknowns, a move's posture): whether the observation after it holds readings."""
        if not refused and operation["op"] == Op.REMOUNT:
            # Another set of mountings reads at Zero from here on: a new stay.
            self.run = 0
            cols = self._columns(int(operation["stand"]))[N_MACHINE:]
            # A mounting left behind is marginalised out: nothing reads it again.
            self.covariance[cols, :] = 0.0
            self.covariance[:, cols] = 0.0
            self.covariance[cols, cols] = 1.0
            self.here, self.rho = self.table.zero, np.zeros(3)
        if not refused and operation["op"] == Op.MOVE:
            self.rho = np.asarray(operation["rho"], dtype=float)
            here = self.index[self.rho.tobytes()]
            if here != self.here:
                self.run = 0
            self.here = here
        return not refused and operation["op"] in (Op.MOVE, Op.REMOUNT)

    def _sync(self, observation: dict[str, np.ndarray]) -> None:
        _sync_many([self], [observation])

    def _columns(self, stand: int) -> np.ndarray:
        start = N_MACHINE + N_STAND * stand
        return np.concatenate((np.arange(N_MACHINE), np.arange(start, start + N_STAND)))

    def _read(self, observation: dict[str, np.ndarray]) -> None:
        """Add the valid readings of the observation, taken here, and count them."""
        self._tally()
        if not self.follows:
            return
        rows = readings_rows([self], np.asarray(observation["valid"], dtype=bool)[None])[0]
        if not rows.size:
            return
        before = self.predicted_mse()
        gain, b = woodbury_gain(self.covariance, rows)
        self.covariance = shrunk(self.covariance, gain, b)
        if before > 0:
            self.fall = max(1.0 - self.predicted_mse() / before, 0.0)

    def _tally(self) -> None:
        """Count a reading here (its fall is the update's to set)."""
        self.readings_at[self.here] += 1
        self.run += 1
        self.fall = 0.0

    # -- what it predicts -------------------------------------------------------------------
    def predicted_mse(self) -> float:
        """Predicted mean-square TCP error after the best-fit rigid motion (mm^2)."""
        self._following()
        n = N_MACHINE
        # trace(W C) of two symmetric matrices, without their product.
        return float(max(np.sum(self.weight * self.covariance[:n, :n]), 0.0))

    def error_spectrum(self) -> np.ndarray:
        """Eigenvalues (r,), largest first, of the predicted TCP error's covariance in the
        ``r`` directions the rigid-motion score sees (``F' C F``, mm^2): their sum is
        :meth:`predicted_mse`."""
        self._following()
        return _spectra(self.factor, self.covariance[:N_MACHINE, :N_MACHINE])

    def _following(self) -> None:
        """Refuse to predict from a covariance this belief does not follow."""
        if not self.follows:
            raise ValueError("this belief counts the readings without following the "
                             "covariance (covariance=False): it predicts no error")

    def log_mean_squares(self) -> np.ndarray:
        """``log10`` of :meth:`error_spectrum` and of its sum (:meth:`predicted_mse`, to
        rounding), each in units of ``ACCURACY_UNIT_MM`` squared plus :data:`LOG_FLOOR`
        (r + 1,)."""
        return _log_mean_squares(self.error_spectrum())

    # -- what a learner observes ------------------------------------------------------------
    def reading_history(self) -> np.ndarray:
        """How the present posture has been read (3,): the readings taken here in a row
        (since the last move elsewhere or re-mount) and in all, over :data:`COUNT_SCALE`,
        and ``log10`` of the last reading's relative fall of the predicted mean square
        plus :data:`FALL_FLOOR`.  View 1 observes them: between two re-readings of one
        posture the rest of the observation hardly moves, and a stay's length is what an
        expert's choice to stay or leave turns on."""
        return _history(np.array([self.run]), np.array([self.readings_at[self.here]]),
                        np.array([self.fall]))[0]

    def posture_counts(self) -> np.ndarray:
        """The readings taken at each candidate posture (P,), over :data:`COUNT_SCALE`
        (view 2).  At the nominal machine the covariance is a function of where and by
        which mountings the readings were taken, and those are the counts with the
        stands' states, so view 2 observes them in place of the spectrum: a decision then
        needs no Woodbury step and no eigen-solve."""
        return self.readings_at / COUNT_SCALE

    def observation(self) -> np.ndarray:
        """The observation of the design view (float32; its parts:
        :class:`~orthoglide_env.wrappers.DesignLab`): in views 0 and 1
        :meth:`log_mean_squares`, then each stand's slot one-hot (then "not mounted"),
        engaged and out of service, the posture scaled to [-1, 1] over the design's
        control limits, the time used over the budget; in view 1 :meth:`reading_history`;
        in view 2 its first two numbers (no fall) and :meth:`posture_counts`."""
        tail = observation_tails([self])[0]
        if self.version not in SPECTRUM_VIEWS:
            return tail.astype(np.float32)
        return np.concatenate((self.log_mean_squares(), tail)).astype(np.float32)

    def observation_bounds(self, longest_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (float32) of every :meth:`observation` of a lab whose longest step takes
        ``longest_s``: the logs lie between that of :data:`LOG_FLOOR` and a decade above the
        prior's mean square (readings only shrink the covariance), the clock stops within a
        step of the budget; in views 1 and 2 no more readings at a posture than the
        shortest re-reading fits into that time, and in view 1 a fall between nothing and
        all."""
        top = float(np.log10(np.trace(self.weight) / ACCURACY_UNIT_MM**2 + LOG_FLOOR)) + 1.0
        logs, stands = self.factor.shape[1] + 1, self.n_stands * (self.n_slots + 3)
        most = self.most_readings(longest_s) / COUNT_SCALE
        low = [np.zeros(stands), -np.ones(3), [0.0]]
        high = [np.ones(stands), np.ones(3), [(self.budget_s + longest_s) / self.budget_s]]
        if self.version in SPECTRUM_VIEWS:
            low.insert(0, np.full(logs, np.log10(LOG_FLOOR)))
            high.insert(0, np.full(logs, top))
        if self.version == 1:
            low.append([0.0, 0.0, np.log10(FALL_FLOOR)])
            high.append([most, most, np.log10(1 + FALL_FLOOR)])
        if self.version == 2:
            low.append(np.zeros(2 + self.n_postures))
            high.append(np.full(2 + self.n_postures, most))
        return (np.concatenate(low).astype(np.float32),
                np.concatenate(high).astype(np.float32))

    def most_readings(self, longest_s: float) -> float:
        """The most readings an episode can take at one posture, in a lab whose longest
        step takes ``longest_s``: the shortest re-reading fits no more often into the
        budget and a step past it."""
        # The first reading is at Zero at no cost; every later one takes a move.
        return float(1 + np.floor((self.budget_s + longest_s) / np.min(np.diag(self.drive_s))))

    # -- the candidate operations -----------------------------------------------------------
    def moves(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every candidate move's seconds (P,), the plungers down after it (K, P) and how
        likely each reads there (K, P), a priori: a plunger is let down only where it is
        safe both here and there (let down here, it reads there) and lifted where it is
        not safe there; a stand out of service stays up.  (Computed once per state.)"""
        return self._candidates()[:3]

    def _candidates(self) -> Moves:
        """:func:`candidate_moves` of the present state (found once per state)."""
        if self._moves is None:
            self._moves = self._moves_of(self.slots.tobytes(), self.faulted.tobytes(),
                                         self.engaged.tobytes(), self.here)
        return self._moves

    def action_mask(self) -> np.ndarray:
        """Which operations are candidates now (``n_actions``,): a move where some stand
        reads at least :data:`READ_PROBABILITY` likely and which ends within the budget; a
        re-mount at a slot no stand holds, ending within the budget (a re-mount onto a held
        slot is what the lab refuses; onto its own, a new installation where it stands,
        buys nothing a planner weighs); stop (:func:`action_masks` of this belief alone)."""
        return action_masks([self])[0]

    def operations(self, action: int) -> list[dict[str, object]]:
        """The lab actions that operation ``action`` is: a move's lever flicks (by stand)
        then the move, a re-mount, or stop."""
        if not 0 <= action < self.n_actions:
            raise ValueError(f"an operation is an integer in [0, {self.n_actions}), got {action}")
        after = self.moves()[1] if action < self.n_postures else None
        return operations_of(self.table, self.n_stands, self.n_slots, action, after,
                             self.engaged)


def operations_of(table: SlotTable, stands: int, slots: int, action: int,
                  after: np.ndarray | None, engaged: np.ndarray) -> list[dict[str, object]]:
    """:meth:`DesignBelief.operations` of ``action`` on a design's slot ``table`` with
    ``stands`` stands and ``slots`` slots, for a state whose plungers are down after each
    move as ``after`` (K, P) says (:meth:`DesignBelief.moves`; unread unless ``action`` is
    a move) and now as ``engaged`` (K,)."""
    postures = len(table.postures)
    idle = {"rho": np.zeros(3), "stand": 0, "slot": 0}
    if action == postures + stands * slots:
        return [{**idle, "op": Op.STOP}]
    if action >= postures:
        stand, slot = divmod(action - postures, slots)
        return [{**idle, "op": Op.REMOUNT, "stand": stand, "slot": slot}]
    flicks = [{**idle, "op": Op.ENGAGE if down else Op.LIFT, "stand": k}
              for k, (down, now) in enumerate(zip(after[:, action].tolist(),
                                                  engaged.tolist(), strict=True))
              if down != now]
    return [*flicks, {**idle, "op": Op.MOVE, "rho": table.postures[action].copy()}]


def _sync_many(beliefs: list[DesignBelief], seen: list[dict[str, np.ndarray]]) -> None:
    """Each belief's stands and clock from its lab's observation (beliefs of one design and
    stands): their arrays are rows of one array each."""
    slot = np.array([o["slot"] for o in seen], dtype=np.int64)
    # A stand at a slot beyond the design's catalogue (or none) has no rows here.
    slots = np.where(slot < beliefs[0].n_slots, slot, -1)
    engaged = np.array([o["engaged"] for o in seen], dtype=bool) & (slots >= 0)
    faulted = np.array([o["faulted"] for o in seen], dtype=bool)
    for k, (belief, observation) in enumerate(zip(beliefs, seen, strict=True)):
        belief._moves = None
        belief.slots, belief.engaged, belief.faulted = slots[k], engaged[k], faulted[k]
        belief.time_s = float(observation["time"][0])


def _stacked(beliefs: list[DesignBelief]) -> np.ndarray:
    """The covariances of ``beliefs`` as one array (N, n, n) whose rows the beliefs'
    covariances are: the array of the last call for these beliefs in this order, kept
    while none of them has replaced its covariance (:meth:`DesignBelief.start`, a lone
    :meth:`DesignBelief.observe`); else made anew, their covariances then its rows."""
    stack = beliefs[0]._stack
    if stack is None or len(stack) != len(beliefs) or not all(
            b._stack is stack and b._index == k and b.covariance is b._row
            for k, b in enumerate(beliefs)):
        stack = np.stack([b.covariance for b in beliefs])
        for k, belief in enumerate(beliefs):
            belief._stack, belief._index, belief._row = stack, k, stack[k]
            belief.covariance = belief._row
    return stack


def readings_rows(beliefs: list[DesignBelief], valid: np.ndarray) -> np.ndarray:
    """The whitened rows (N, R, n) of the readings of each of ``beliefs`` (of one design and
    stands) at its posture by its stands ``valid`` (N, K) and mounted, in the stands' order,
    padded with rows of zeros (R: the most readings of one; 0 when none read)."""
    first = beliefs[0]
    slots = np.array([b.slots for b in beliefs])
    reads = valid & (slots >= 0)
    which, stand = np.nonzero(reads)
    rank = np.cumsum(reads, axis=1)[which, stand] - 1
    rows = np.zeros((len(beliefs), int(rank.max(initial=-1)) + 1, len(first.covariance)))
    values = np.full((len(which), first.stand_columns.shape[1]), ZERO_SCALE)
    values[:, :-1] = first.table.change[slots[which, stand],
                                        np.array([b.here for b in beliefs])[which]]
    # Whitened before they are placed: the rows' zeros need no division.
    values /= np.array([b.sigma for b in beliefs])[which, None]
    rows[which[:, None], rank[:, None], first.stand_columns[stand]] = values
    return rows


def observe_many(beliefs: list[DesignBelief], operations: list[dict[str, object]],
                 seen: list[dict[str, np.ndarray]], refused: list[bool]) -> None:
    """:meth:`DesignBelief.observe` of each of ``beliefs`` (of one design and stands) after
    its operation: each its own bookkeeping, and the readings' Woodbury steps of all of
    them at once, on their covariances kept as one array (:func:`_stacked`; a belief that
    read less, or nothing, has rows of zeros, which change nothing), so that a chunk of
    machines pays about one machine's calls.  A covariance is its lone belief's to
    rounding (a stacked product may sum in another order), and symmetric to rounding: the
    spectra symmetrise the block they see."""
    if not beliefs:
        return
    steps = [belief._step(operation, no)
             for belief, operation, no in zip(beliefs, operations, refused, strict=True)]
    _sync_many(beliefs, seen)
    for belief, reads in zip(beliefs, steps, strict=True):
        if reads:
            belief._tally()
    if not beliefs[0].follows:
        return
    valid = np.array([o["valid"] for o in seen], dtype=bool) & np.array(steps)[:, None]
    rows = readings_rows(beliefs, valid)
    if not rows.shape[1]:
        return
    covariances = _stacked(beliefs)
    # predicted_mse of each, before and after: trace(W C) as one product of the stack.
    size = covariances.shape[-1]
    weight = np.zeros((size, size))
    weight[:N_MACHINE, :N_MACHINE] = beliefs[0].weight
    flat = covariances.reshape(len(beliefs), -1)
    before = flat @ weight.ravel()
    # woodbury_gain and shrunk, in the orders of operands a stack multiplies fastest in
    # (``R C`` is ``B'``: the covariances are symmetric).
    b_t = rows @ covariances
    m = b_t @ _transposed(rows)
    m += np.eye(rows.shape[1])
    # m's inverse times B', not a solve: NumPy's stacked solve of 57 right-hand sides costs
    # five times the stacked inverse of m (R x R, R at most the stands) and its product.
    covariances -= _transposed(np.linalg.inv(m) @ b_t) @ b_t
    after = np.maximum(flat @ weight.ravel(), 0.0)
    for k in np.flatnonzero(rows.any(axis=(1, 2))).tolist():
        if before[k] > 0:
            beliefs[k].fall = max(1.0 - float(after[k]) / float(before[k]), 0.0)


def observation_tails(beliefs: list[DesignBelief]) -> np.ndarray:
    """The observation after the spectrum's logs of each of ``beliefs`` (of one design,
    stands and view), stacked (N, m), float64: each stand's slot one-hot (then "not
    mounted"), engaged and out of service, the posture scaled to [-1, 1] over the design's
    control limits, the time used over the budget, in view 1 the reading history, in
    view 2 its counts and every posture's (:meth:`DesignBelief.posture_counts`)."""
    history = (np.array([b.run for b in beliefs]),
               np.array([b.readings_at[b.here] for b in beliefs]),
               np.array([b.fall for b in beliefs])) if beliefs[0].version >= 1 else None
    stands = stands_of(beliefs[0], np.array([b.slots for b in beliefs]),
                       np.array([b.engaged for b in beliefs]),
                       np.array([b.faulted for b in beliefs]))
    return tails_of(beliefs[0], stands, np.array([b.rho for b in beliefs]),
                    np.array([b.time_s / b.budget_s for b in beliefs]), history,
                    np.stack([b.readings_at for b in beliefs])
                    if beliefs[0].version == 2 else None)


def stands_of(first: DesignBelief, held: np.ndarray, engaged: np.ndarray,
              faulted: np.ndarray) -> np.ndarray:
    """The stands' part (N, K (S + 3)) of :func:`observation_tails` of N states of beliefs
    like ``first`` (its design and stands): each stand's slot one-hot (then "not mounted"),
    engaged and out of service, from the slots held (N, K; -1: none), plungers down and
    stands out of service (N, K)."""
    count, stands, slots = len(held), first.n_stands, first.n_slots
    tails = np.zeros((count, stands, slots + 3))
    tails[np.arange(count)[:, None], np.arange(stands), np.where(held >= 0, held, slots)] = 1
    tails[:, :, -2] = engaged
    tails[:, :, -1] = faulted
    return tails.reshape(count, -1)


def tails_of(first: DesignBelief, stands: np.ndarray, rho: np.ndarray, clock: np.ndarray,
             history: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
             counts: np.ndarray | None) -> np.ndarray:
    """:func:`observation_tails` (N, m) of N states of beliefs like ``first`` (its design,
    stands and view) from their arrays: the stands' part (:func:`stands_of`), postures
    (N, 3), the time used over the budget (N,), in views 1 and 2 the readings in a row
    here, in all here and the last one's fall (N, each), in view 2 the readings at every
    posture (N, P)."""
    low, high = first.design.rho_min, first.design.rho_max
    parts = [stands, (2 * rho - (high + low)) / (high - low), clock[:, None]]
    if first.version == 1:
        parts.append(_history(*history))
    if first.version == 2:
        # The fall is not view 2's (nor its log's cost).
        run, total, _ = history
        parts.extend((run[:, None] / COUNT_SCALE, total[:, None] / COUNT_SCALE,
                      counts / COUNT_SCALE))
    return np.concatenate(parts, axis=1)


def _history(run: np.ndarray, total: np.ndarray, fall: np.ndarray) -> np.ndarray:
    """:meth:`DesignBelief.reading_history` (N, 3) of readings in a row ``run``, in all
    ``total`` and the last one's relative fall ``fall`` (N,) each."""
    return np.stack((run / COUNT_SCALE, total / COUNT_SCALE, np.log10(fall + FALL_FLOOR)),
                    axis=-1)


def action_masks(beliefs: list[DesignBelief]) -> np.ndarray:
    """:meth:`DesignBelief.action_mask` of each of ``beliefs`` (of one design and stands),
    stacked (N, ``n_actions``): each state's candidate moves from the cache
    (:func:`candidate_moves`), the clock and the held slots of all of them at once."""
    return masks_of(beliefs[0], [b._candidates() for b in beliefs],
                    np.array([b.time_s for b in beliefs]),
                    np.array([b.budget_s for b in beliefs]), [b.here for b in beliefs],
                    np.array([b.slots for b in beliefs]))


def masks_of(first: DesignBelief, moves: list[Moves], clock: np.ndarray, budget: np.ndarray,
             here: list[int] | np.ndarray, held: np.ndarray) -> np.ndarray:
    """:func:`action_masks` (N, ``n_actions``) of N states of beliefs like ``first`` (its
    design and stands) from their candidate moves (:func:`candidate_moves`), clocks and
    budgets (N,), postures' indices (N,) and slots held (N, K; -1: none)."""
    return close_late(first, open_masks(first, moves, held), moves, clock, budget,
                      remount_seconds(first, here))


def open_masks(first: DesignBelief, moves: list[Moves], held: np.ndarray) -> np.ndarray:
    """:func:`masks_of` with all the budget left (N, ``n_actions``): the readable moves, a
    re-mount at each slot no stand holds, stop."""
    count, postures, slots = len(moves), first.n_postures, first.n_slots
    masks = np.empty((count, first.n_actions), dtype=bool)
    np.stack([m[3] for m in moves], out=masks[:, :postures])
    free = np.ones((count, slots), dtype=bool)
    rows, stands = np.nonzero(held >= 0)
    free[rows, held[rows, stands]] = False
    masks[:, postures:-1] = np.tile(free, first.n_stands)
    masks[:, -1] = True
    return masks


def remount_seconds(first: DesignBelief, here: list[int] | np.ndarray) -> np.ndarray:
    """A re-mount's seconds from postures ``here`` (N,): the drive to Zero, as the lab
    times it, from the table of every move, and the re-mount itself."""
    return first.drive_s[here, first.table.zero] + TIME.remount_s


def close_late(first: DesignBelief, masks: np.ndarray, moves: list[Moves], clock: np.ndarray,
               budget: np.ndarray, remount_s: np.ndarray) -> np.ndarray:
    """``masks`` (N, ``n_actions``; :func:`open_masks`) with the operations that would end
    past the budget closed, in place, of states of candidate moves ``moves``, clocks and
    budgets (N,) and re-mounts' seconds ``remount_s`` (N,)."""
    postures = first.n_postures
    # A state's readable moves all end within the budget while its longest one does: only
    # a row near the budget's end compares each move's end with it.
    late = clock + np.array([m[4] for m in moves]) > budget
    for k in np.flatnonzero(late).tolist():
        masks[k, :postures] &= clock[k] + moves[k][0] <= budget[k]
    masks[clock + remount_s > budget, postures:-1] = False
    return masks


def observations(beliefs: list[DesignBelief]) -> np.ndarray:
    """:meth:`DesignBelief.observation` of each of ``beliefs`` (of one design, stands and
    view), stacked (N, n), the same floats: the predicted error's spectra of all of them in
    one batched product and eigen-solve, whose call costs a chunk of machines about what
    one machine's costs (view 2 has none)."""
    tails = observation_tails(beliefs)
    if beliefs[0].version not in SPECTRUM_VIEWS:
        return tails.astype(np.float32)
    n = N_MACHINE
    logs = _log_mean_squares(_spectra(beliefs[0].factor, np.stack(
        [b.covariance[:n, :n] for b in beliefs])))
    return np.concatenate((logs, tails), axis=1).astype(np.float32)


def _spectra(factor: np.ndarray, covariances: np.ndarray) -> np.ndarray:
    """Eigenvalues (..., r), largest first, of ``F' C F`` for the machine block ``C``
    (..., n, n) of one covariance or a stack of them."""
    block = factor.T @ covariances @ factor
    # A covariance's eigenvalues are >= 0; the rounding of a resolved one may not be.
    symmetric = (block + np.swapaxes(block, -1, -2)) / 2
    return np.clip(np.linalg.eigvalsh(symmetric), 0.0, None)[..., ::-1]


def _log_mean_squares(spectra: np.ndarray) -> np.ndarray:
    """``log10`` of spectra (..., r) and of their sums, in units of ``ACCURACY_UNIT_MM``
    squared plus :data:`LOG_FLOOR` (..., r + 1)."""
    values = np.concatenate((spectra, np.sum(spectra, axis=-1, keepdims=True)), axis=-1)
    return np.log10(values / ACCURACY_UNIT_MM**2 + LOG_FLOOR)
