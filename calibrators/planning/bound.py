"""The bound: the least TCP error after the best-fit rigid motion that any plan of a
budget can reach with a lab's instruments, on the planner's linearised model.

Every plan is a multiset of readings: a dial at a slot of the catalogue at a candidate
posture of the slot table (:mod:`orthoglide_env.lab.slot_table`), and, in a lab with the
interferometer, the laser along one drive with its carriage at a target.  On the linearised
model at the nominal machine with the estimators' priors, a reading adds the rank-one
information ``a a^T`` (its whitened row), so a plan that takes ``n_i`` readings of candidate
``i`` leaves the covariance ``M(n)^-1``, ``M(n) = I + sum_i n_i a_i a_i^T``, and the
predicted mean-square TCP error after rigid motion ``f(n) = trace(W M(n)^-1)`` (the
criterion ``I`` that ``optimal`` and ``active`` price, :mod:`calibrators.planning.belief`,
with the drives' lead error in it).  ``f`` is convex in ``n``; letting ``n`` be real
(time shares) makes the least ``f`` over a budget a convex problem, the continuous
optimal design, whose optimum no discrete plan can beat.

The unknowns: the machine's 27 errors (the realistic preset's sigmas), the lead error's
terms as the ``full`` estimator fits them (the pitch table's coefficients, whitened, and
the screw's periodic error: :func:`~calibrators.estimators.consider.lead_terms`), and a
zero per dial slot and per drive's interferometer set-up (diffuse, :data:`~orthoglide_env.
lab.design_belief.ZERO_SCALE`).  ``W`` is the TCP error's weight over the first two
groups (:func:`~orthoglide_env.scoring.predicted.rigid_weight_with_drives`).

What is relaxed, each a superset of what a plan can do, so the bound stays below every
plan (a Gaussian posterior only narrows when more is known or read):

* every world term but the lead error is known (drift, backlash, warm-up, the room, the
  indicators' curves, the interferometer's scale error), and so is every stand's
  installation: their unknowns only widen a plan's error;
* a slot's readings share one zero, however often a plan mounts a stand there, and so
  do a drive's set-ups (a shared zero is separate zeros known to be equal);
* a stand reads wherever the nominal machine's tip touches its bar (a priori contact
  above 0), mounting costs nothing, and a visit to a posture reads up to ``stands`` dial
  slots, any of them, at one settle and read each (:data:`~orthoglide_env.lab.
  operations.TIME`); driving between postures and the levers cost nothing;
* with the interferometer set up, a reading costs its dwell on top of the visit and the
  visit reads the dials too: readings of counts ``n_d`` (dials) and ``n_l`` (laser) then
  need ``settle n_d / stands + dwell n_l <= T`` and ``(settle + dwell) n_l <= T``, two
  linear budgets (each visit reads at most one laser target and ``stands`` dials).

Not relaxed: the set-ups.  The laser's set-up on a drive is a fixed cost paid once or not
at all (its soak before the first): the bound is the least over every set of drives set
up of the problem with ``T`` less their set-ups, each solved alone (8 problems, each a
group either paid or not, as in optimal design with set-up costs).

Each problem is solved by the multiplicative algorithm (:func:`solve`), and certified by
its Frank-Wolfe duality gap (:func:`gap`): ``f(n) - gap`` is below the optimum for every
``n``, so the bound reported is the least certified value (a true lower bound however far
the solver got), and the gap says how tight it is.  The tracker, step gauge and ballbar
are not candidates here: a lab that owns them is bounded over its dials and
interferometer only.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from calibrators.estimators.consider import DEFAULT_NODE_SPACING, lead_terms
from orthoglide_env.instruments import interferometer
from orthoglide_env.lab.design_belief import N_MACHINE, ZERO_SCALE
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, Op
from orthoglide_env.lab.slot_table import slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring.predicted import rigid_weight_with_drives
from orthoglide_env.world.conditions import Conditions

#: The instruments whose readings are candidates of the bound.
BOUND_INSTRUMENTS: tuple[str, ...] = ("dial", "interferometer")
#: The laser's candidate targets along each drive are this far apart (mm): ten per period
#: of the screw's periodic error (its lead, 5 mm on the prototype), and a twentieth of the
#: pitch table's node spacing.
LASER_STEP_MM: float = 0.5
#: :func:`solve` stops when its duality gap is this share of the value (0.5 % of the mean
#: square, 0.25 % of the RMS: below what 50 machines' medians resolve), or after
#: :data:`MAX_ITERATIONS` (about a minute under load; its gap is reported, its bound
#: certified either way).
GAP_SHARE: float = 5e-3
MAX_ITERATIONS: int = 400
#: The duality gap is computed every this many steps.
GAP_EVERY: int = 10
#: The multiplicative step's power: 1 converged as far in 200 steps on the prototype's
#: one-hour problems as 1/2 in 400 (certified 4.953 and 4.273 um against the designs'
#: 4.955 and 4.283).
POWER: float = 1.0


@dataclass(frozen=True)
class BoundModel:
    """The candidate readings of a lab and the criterion over them.

    ``rows`` (N, n): each candidate's whitened row over the unknowns (machine, lead terms,
    zeros); ``laser`` (N,): the drive a laser candidate reads (-1: a dial reading);
    ``label`` (N, 3): a dial's (slot, posture, -1) or a laser's (-1, axis, target index);
    ``factor`` (n, r): ``F`` with ``F F^T`` the TCP error's weight padded with zeros
    (the zeros do not move the tool)."""

    rows: np.ndarray
    laser: np.ndarray
    label: np.ndarray
    factor: np.ndarray
    targets: np.ndarray  # (T,) the laser's targets along a drive, mm

    def value(self, counts: np.ndarray) -> float:
        """``f(n)``: the predicted mean-square TCP error after rigid motion (mm^2) of
        ``counts`` (N,) readings of each candidate."""
        return _value(_information(self.rows, counts), self.factor)[0]

    def index(self, slot: int, posture: int) -> int:
        """The candidate of a dial at ``slot`` read at ``posture`` (``ValueError`` where the
        nominal tip does not touch: no candidate)."""
        hit = np.flatnonzero((self.label[:, 0] == slot) & (self.label[:, 1] == posture))
        if not hit.size:
            raise ValueError(f"a dial at slot {slot} does not read at posture {posture}")
        return int(hit[0])

    def laser_index(self, axis: int, target_mm: float) -> int:
        """The laser candidate along drive ``axis`` nearest ``target_mm``."""
        k = int(np.argmin(np.abs(self.targets - target_mm)))
        return int(np.flatnonzero((self.laser == axis) & (self.label[:, 2] == k))[0])


@lru_cache(maxsize=4)
def bound_model(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                interferometer_owned: bool) -> BoundModel:
    """The candidates of a lab of ``design`` under ``conditions`` whose dials read with
    ``dial_sigma`` (mm, the weighting sigma), with or without the interferometer."""
    if not (np.isfinite(dial_sigma) and dial_sigma > 0):
        raise ValueError(f"dial_sigma must be a positive number, got {dial_sigma}")
    table = slot_table(design)
    scale = default_scales(ParameterSpace())
    slots, postures = np.nonzero(table.prior_reach[1] > 0)
    n_slots = len(table.tip)

    def lead(rho: np.ndarray) -> np.ndarray:
        terms = lead_terms(rho, design, conditions, DEFAULT_NODE_SPACING)
        return (np.stack([p for _, p in terms], axis=-1) if terms
                else np.zeros((*np.shape(rho), 0)))

    n_lead = lead(np.zeros((1, 3))).shape[-1]
    n = N_MACHINE + n_lead + n_slots + 3
    zero = N_MACHINE + n_lead  # the first zero's column
    dial = np.zeros((len(slots), n))
    dial[:, :N_MACHINE] = table.change[slots, postures, :N_MACHINE]
    # A carriage's error moves a reading as its drive's encoder offset does, at the
    # posture (the zero takes the reading's value at Zero).
    drive = (table.change[slots, postures, :3] + table.at_zero[slots, :3]) / scale[:3]
    dial[:, N_MACHINE:zero] = np.einsum("ia,iak->ik", drive, lead(table.postures[postures]))
    dial[np.arange(len(slots)), zero + slots] = ZERO_SCALE
    rows, laser = [dial / dial_sigma], [np.full(len(slots), -1)]
    label = [np.stack([slots, postures, np.full(len(slots), -1)], axis=-1)]
    targets = np.arange(design.rho_min, design.rho_max + 1e-9, LASER_STEP_MM)
    if interferometer_owned:
        for axis in range(3):
            rho = np.zeros((len(targets), 3))
            rho[:, axis] = targets
            # The laser reads the carriage's own error, no kinematics between: only its
            # drive's terms move it.
            part = lead(rho)[:, axis]
            on_axis = np.zeros((len(targets), n))
            on_axis[:, N_MACHINE:zero] = part
            on_axis[:, zero + n_slots + axis] = ZERO_SCALE
            rows.append(on_axis / interferometer.sigma(conditions))
            laser.append(np.full(len(targets), axis))
            label.append(np.stack([np.full(len(targets), -1), np.full(len(targets), axis),
                                   np.arange(len(targets))], axis=-1))
    nominal = MachineParams(design=design)
    weight = rigid_weight_with_drives(nominal, lead)
    units = np.concatenate([scale, np.ones(n_lead)])
    weight = weight * np.outer(units, units)
    value, vector = np.linalg.eigh(weight)
    keep = value > 1e-12 * value[-1]
    factor = np.zeros((n, int(keep.sum())))
    factor[:zero] = vector[:, keep] * np.sqrt(value[keep])
    return BoundModel(np.vstack(rows), np.concatenate(laser), np.vstack(label), factor,
                      targets)


def plan_counts(model: BoundModel, design: MachineDesign, slots: tuple[int, ...],
                engaged: tuple[bool, ...], actions: list[dict[str, object]]) -> np.ndarray:
    """The readings (N,) a discrete plan of lab ``actions`` (the lab env's, ``op``, ``rho``,
    ``stand``, ``slot``, ``axis``) takes, from stands at ``slots`` with plungers ``engaged``,
    counted per candidate of ``model``: every engaged stand at every posture it moves to or
    is re-mounted or set up at (where its nominal tip touches), and the laser, once set up
    on a drive, at each posture's target along it (its set-up reads at Zero; a target
    is taken at the nearest candidate).  ``f`` of these counts (:meth:`BoundModel.value`) is
    the plan's error on the bound's model, which the bound is below."""
    table = slot_table(design)
    slots_, down = list(slots), list(engaged)
    counts = np.zeros(len(model.rows))
    axis = -1
    where = {tuple(p): k for k, p in enumerate(table.postures)}
    dial = {(int(a), int(b)): k for k, (a, b, _) in enumerate(model.label) if a >= 0}
    for step in actions:
        op = Op(int(step["op"]))  # type: ignore[call-overload]
        if op in (Op.LIFT, Op.ENGAGE):
            down[int(step["stand"])] = op == Op.ENGAGE  # type: ignore[call-overload]
            continue
        if op == Op.STOP:
            break
        rho = np.zeros(3) if op != Op.MOVE else np.asarray(step["rho"], dtype=float)
        if op == Op.REMOUNT:
            stand = int(step["stand"])  # type: ignore[call-overload]
            slots_[stand], down[stand] = int(step["slot"]), True  # type: ignore[call-overload]
        if op == Op.ALIGN:
            axis = int(step["axis"])  # type: ignore[call-overload]
        posture = where.get(tuple(rho))
        for slot, on in zip(slots_, down, strict=True):
            k = dial.get((slot, posture)) if posture is not None and on else None
            if k is not None:
                counts[k] += 1
        if axis >= 0:
            counts[model.laser_index(axis, float(rho[axis]))] += 1
    return counts


def _information(rows: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``sum_i n_i a_i a_i^T`` over the candidates read (``counts`` > 0)."""
    used = np.flatnonzero(counts > 0)
    part = rows[used]
    return (part * counts[used, None]).T @ part


def _value(information: np.ndarray, factor: np.ndarray) -> tuple[float, np.ndarray]:
    """``f`` at ``I + information`` and ``X = M^-1 F`` (n, r)."""
    m = np.eye(len(information)) + information
    x = cho_solve(cho_factor(m), factor)
    return float(np.sum(x * factor)), x


@dataclass(frozen=True)
class Budgets:
    """The two linear budgets of a problem: ``dial_s`` per dial reading and ``laser_s``
    per laser reading against the first, ``visit_s`` per laser reading against the second
    (both of ``seconds``)."""

    seconds: float
    dial_s: float
    laser_s: float
    visit_s: float

    def atom(self, dial: int | None, laser: int | None) -> tuple[tuple[int, float], ...]:
        """A vertex of the polytope: the readings of one dial candidate, one laser
        candidate, or both together, each budget spent."""
        if laser is None:
            return ((dial, self.seconds / self.dial_s),)  # type: ignore[return-value]
        visits = self.seconds / self.visit_s
        if dial is None:
            return ((laser, visits),)
        return ((dial, (self.seconds - self.laser_s * visits) / self.dial_s), (laser, visits))


def gap(model: BoundModel, budgets: Budgets, lasers: np.ndarray, counts: np.ndarray,
        gradient: np.ndarray) -> float:
    """The Frank-Wolfe duality gap at ``counts`` with the ``gradient`` of ``f`` there:
    ``g . n - min over the polytope of g . s``.  ``f`` is convex, so ``f(n) - gap`` is
    below its least value over the polytope.  The least of a linear function over it is
    at a vertex: one dial candidate's readings, one laser candidate's, or both read on
    every visit (:meth:`Budgets.atom`), each at its least gradient."""
    dials = np.flatnonzero(model.laser < 0)
    i = int(dials[np.argmin(gradient[dials])])
    options = [budgets.atom(i, None)]
    if lasers.size:
        j = int(lasers[np.argmin(gradient[lasers])])
        options += [budgets.atom(None, j), budgets.atom(i, j)]
    least = min(sum(gradient[k] * c for k, c in atom) for atom in options)
    return float(gradient @ counts - least)


def solve(model: BoundModel, budgets: Budgets, lasers: np.ndarray,
          stop_above: float = np.inf) -> tuple[float, float, np.ndarray]:
    """The continuous design of least ``f`` over ``budgets`` with every dial candidate and
    the laser candidates ``lasers`` (indices), by the multiplicative algorithm (Silvey,
    Titterington and Torsney 1978; Yu 2010 for A-optimality's monotone convergence).

    The design is a share ``w_i`` of the first budget per candidate (summing to 1), ``n_i
    = w_i T / c_i`` with ``c_i`` its price there (``dial_s`` or ``laser_s``).  Each share
    is multiplied by the square root of its reading's fall of ``f`` per second against
    the shares' mean: the fixed point is the optimum's condition, every reading used
    gains as much per second.  The second budget (the laser's visits) caps the laser's
    shares after each step.  The duality gap (:func:`gap`, every :data:`GAP_EVERY`
    steps) is over the whole polytope, and ``f(n) - gap`` bounds the least ``f`` there
    from below for any ``n``.  The best certified value is returned with the final
    design's value and counts.  Stops once the gap is :data:`GAP_SHARE` of the value,
    the certified value passes ``stop_above`` (a problem that cannot be the least), or
    after :data:`MAX_ITERATIONS`."""
    rows, factor = model.rows, model.factor
    used = np.concatenate([np.flatnonzero(model.laser < 0), lasers])
    price = np.where(model.laser[used] < 0, budgets.dial_s, budgets.laser_s)
    w = np.full(len(used), 1.0 / len(used))
    lower = -np.inf
    for iteration in range(MAX_ITERATIONS + 1):
        counts = np.zeros(len(rows))
        counts[used] = w * budgets.seconds / price
        value, x = _value(_information(rows, counts), factor)
        fall = np.sum((rows @ x) ** 2, axis=1)  # -gradient
        if iteration % GAP_EVERY == 0 or iteration == MAX_ITERATIONS:
            lower = max(lower, value - gap(model, budgets, lasers, counts, -fall))
            if (value - lower <= GAP_SHARE * value or lower > stop_above
                    or iteration == MAX_ITERATIONS):
                break
        per_second = fall[used] / price
        w = w * (per_second / float(w @ per_second)) ** POWER
        w /= w.sum()
        # The laser's visits within the second budget: its shares of the first at most
        # dwell / (settle + dwell), the dials' the rest.
        laser, cap = model.laser[used] >= 0, budgets.laser_s / budgets.visit_s
        if w[laser].sum() > cap:
            w[laser] *= cap / w[laser].sum()
            w[~laser] *= (1 - cap) / w[~laser].sum()
    return lower, value, counts


@dataclass(frozen=True)
class Bound:
    """The bound of a lab and budget: ``bound_mm`` the certified least TCP error after
    rigid motion (mm), ``design_mm`` the error of the best continuous design found (at
    most :data:`GAP_SHARE` of the mean square above, unless the solver stopped early),
    ``gap_mm2`` their squares' difference, ``drives`` the drives the best design sets the
    laser up on and ``laser_readings`` how many laser readings it takes (real, a time
    share)."""

    bound_mm: float
    design_mm: float
    gap_mm2: float
    drives: tuple[int, ...]
    laser_readings: float

    def to_dict(self) -> dict[str, object]:
        return {**asdict(self), "drives": list(self.drives)}

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> Bound:
        unknown = sorted(set(data) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"unknown bound key(s) {unknown}")
        return cls(float(data["bound_mm"]), float(data["design_mm"]),  # type: ignore[arg-type]
                   float(data["gap_mm2"]), tuple(int(d) for d in data["drives"]),  # type: ignore[attr-defined]
                   float(data["laser_readings"]))  # type: ignore[arg-type]


def setup_seconds(drives: tuple[int, ...]) -> float:
    """What setting the laser up on ``drives`` costs: a set-up each, the soak before the
    first."""
    if not drives:
        return 0.0
    return TIME.interferometer_soak_s + TIME.interferometer_setup_s * len(drives)


def lower_bound(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                budget_s: float, instruments: tuple[str, ...] = ("dial",),
                stands: int = len(PAPER_SLOTS)) -> Bound:
    """The bound (see the module) of a lab of ``design`` under ``conditions`` with dials of
    weighting sigma ``dial_sigma`` (mm) on ``stands`` stands, owning ``instruments``, over
    a budget of ``budget_s`` seconds."""
    if not (np.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f"budget_s must be a positive number of seconds, got {budget_s}")
    if not (isinstance(stands, int) and stands >= 1):
        raise ValueError(f"stands must be a positive integer, got {stands!r}")
    if "dial" not in instruments:
        raise ValueError(f"instruments must include 'dial', got {list(instruments)}")
    owned = "interferometer" in instruments
    model = bound_model(design, conditions, float(dial_sigma), owned)
    dial_s = TIME.settle_and_read_s / stands
    laser_s = TIME.interferometer_target_s
    choices = [()] + ([c for k in (1, 2, 3) for c in itertools.combinations(range(3), k)]
                      if owned else [])
    best: tuple[float, tuple[int, ...], np.ndarray] | None = None
    lowest = np.inf
    for drives in choices:
        seconds = budget_s - setup_seconds(drives)
        if seconds <= 0:
            continue
        budgets = Budgets(seconds, dial_s, laser_s, TIME.settle_and_read_s + laser_s)
        lasers = np.flatnonzero(np.isin(model.laser, drives))
        lower, value, counts = solve(model, budgets, lasers, best[0] if best else np.inf)
        lowest = min(lowest, lower)
        if best is None or value < best[0]:
            best = (value, drives, counts)
    assert best is not None  # the dial-only problem always has a budget
    value, drives, counts = best
    lowest = max(lowest, 0.0)
    return Bound(float(np.sqrt(lowest)), float(np.sqrt(value)), float(value - lowest),
                 tuple(drives), float(counts[model.laser >= 0].sum()))
