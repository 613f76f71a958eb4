"""The bound: the least TCP error after the best-fit rigid motion that any plan of a
budget can reach with a lab's instruments, on the planner's linearised model.

Every plan is a multiset of readings: a dial at a slot of the catalogue at a candidate
posture of the slot table (:mod:`orthoglide_env.lab.slot_table`), in a lab with the
interferometer, the laser along one drive with its carriage at a target, and in a lab
with the ballbar, the 50 mm bar about ISO 230-4's centre at a point of its circle in a
coordinate plane (every :data:`BAR_STEP_DEG`; the ``ballbar`` agent's and the planner's
points are among them).  On the linearised
model at the nominal machine with the estimators' priors, a reading adds the rank-one
information ``a a^T`` (its whitened row), so a plan that takes ``n_i`` readings of candidate
``i`` leaves the covariance ``M(n)^-1``, ``M(n) = I + sum_i n_i a_i a_i^T``, and the
predicted mean-square TCP error after rigid motion ``f(n) = trace(W M(n)^-1)`` (the
criterion ``I`` that ``optimal`` and ``active`` price, :mod:`calibrators.planning.belief`,
with the drives' lead error in it).  ``f`` is convex in ``n``; letting ``n`` be real
(time shares) makes the least ``f`` over a budget a convex problem, the continuous
optimal design, whose optimum no discrete plan can beat.  The same model linearised at a
machine's truth (:func:`machine_bound_model`) gives that machine's own bound: a
yardstick for a comparison, never a planner's input.

The unknowns: the machine's 27 errors (the realistic preset's sigmas), the lead error's
terms as the ``full`` estimator fits them (the pitch table's coefficients, whitened, and
the screw's periodic error: :func:`~calibrators.estimators.consider.lead_terms`), a
zero per dial slot and per drive's interferometer set-up (diffuse, :data:`~orthoglide_env.
lab.design_belief.ZERO_SCALE`), the installation of a stand at each slot (its
:data:`N_INSTALL` errors at the realistic preset's tolerances, unknowns of the fit and of
the planner), and the ballbar set-up's pivot centre (the fit's prior,
:func:`~calibrators.estimators.consider.pivot_sigmas` without the drives, whose lead terms
move the pivot in the bar's rows as in the fit's) and zero (the fit's rows:
:func:`~calibrators.planning.instruments.reading_rows`).  ``W`` is the TCP error's weight
over the first two groups (:func:`~orthoglide_env.scoring.predicted.rigid_weight_with_drives`).

What is relaxed, each a superset of what a plan can do, so the bound stays below every
plan (a Gaussian posterior only narrows when more is known or read):

* every world term but the lead error is known (drift, backlash, warm-up, the room, the
  indicators' curves, the interferometer's scale error): their unknowns only widen a
  plan's error;
* a slot's readings share one zero and one installation, however often a plan mounts a
  stand there, and so do a drive's set-ups and the ballbar's (a shared zero is separate
  zeros known to be equal; the installations and the pivots' centres likewise);
* a stand reads wherever the nominal machine's tip touches its bar (a priori contact
  above 0), and the stands may be at any slots on any visit, at a fraction of the
  re-mounts' price: a slot the stands do not start at (the paper's) is read only after a
  re-mount there, and on no more than ``T / settle`` visits, so each of its readings
  carries ``remount settle / T`` seconds (:attr:`Visits.moved_s`), and nothing else of
  mounting is priced; driving between postures, the levers and overtravels cost nothing;
* the laser's and the pivot's set-ups cost their time table's work and no more (their
  drive to Zero and back is free), and the visit a laser's set-up makes at Zero reads
  the laser without a dwell: each drive set up gives one dwell back.

What is priced as the lab prices it: the visit.  Every reading is taken on a visit, a
move that settles at one place and is read (:data:`~orthoglide_env.lab.operations.TIME`'s
settle and read); a visit to a candidate posture reads each slot that touches there at
most once (a slot holds one stand) and at most ``stands`` slots; a visit to a ballbar
point reads the bar and no dial candidate (no candidate posture is a point of the bar's
circles, and with the bar in a move must stay within its travel of them); with the
interferometer set up, a visit reads the laser at one target for its dwell more (a visit
of its own where nothing else is read).  A re-mount's or a set-up's reading at Zero is a
visit that costs more than one.  So with ``V`` visits and ``L`` laser readings a plan
needs ``settle V + dwell L <= T`` and ``L <= V``, and a posture's readings are a mix of
visits each reading a set of at most ``stands`` of its slots (the polytope of
:class:`Visits`).  Before, a dial reading was priced at a sixth of a visit wherever it
was, so one visit could read six slots at six postures, and the bar on top: a looser
bound (0.48 um against 0.87 um under ``lab``, one hour, the three instruments; 0.81 um
with the visits priced and mounting free).

Not relaxed: the set-ups.  The laser's set-up on a drive is a fixed cost paid once or not
at all (its soak before the first), and so is the ballbar's pivot: the bound is the least
over every set of drives set up, with or without the pivot, of the problem with ``T`` less
their set-ups, each solved alone (8 or 16 problems, each a group either paid or not, as in
optimal design with set-up costs).

Each problem is solved by the multiplicative algorithm over kinds of visit, generating
the kinds as it goes (:func:`solve`), and certified by its Frank-Wolfe duality gap
(:func:`gap`, whose linear oracle is each posture's ``stands`` best slots,
:func:`best_visits`): ``f(n) - gap`` is below the optimum for every feasible ``n``, so the
bound reported is the least certified value (a true lower bound however far the solver
got), and the gap says how tight it is.  The tracker and the step gauge are
not candidates here: a lab that owns them is bounded over its dials, interferometer and
ballbar only.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, replace
from functools import cached_property, lru_cache
from typing import TYPE_CHECKING

import numpy as np

from calibrators.estimators.consider import DEFAULT_NODE_SPACING, lead_terms
from calibrators.planning.instruments import Bundle, reading_rows
from orthoglide_env.instruments import interferometer
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.lab.design_belief import N_MACHINE, N_STAND, ZERO_SCALE
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, Op, slot_index
from orthoglide_env.lab.slot_table import changes_at, slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import inverse
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.scoring.predicted import rigid_weight_with_drives
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

#: The instruments whose readings are candidates of the bound.
BOUND_INSTRUMENTS: tuple[str, ...] = ("dial", "interferometer", "ballbar")
#: A stand's installation unknowns (a mounting's unknowns but its dial's zero).
N_INSTALL: int = N_STAND - 1
#: ``BoundModel.laser``'s mark of a ballbar candidate (a dial's is -1, a laser's its drive).
BAR: int = -2
#: The ballbar's candidate readings lie on the 50 mm bar's circles about ISO 230-4's centre
#: (:mod:`calibrators.agents.ballbar`) in the three coordinate planes, this far apart
#: (degrees): the circles' points and their overshoot starts, both ways, fall on them.
BAR_STEP_DEG: float = 7.5
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
#: A kind of visit whose share falls below this share of the largest is dropped.
VANISHED: float = 1e-12


@dataclass(frozen=True)
class BoundModel:
    """The candidate readings of a lab and the criterion over them.

    ``rows`` (N, n): each candidate's whitened row over the unknowns (machine, lead terms,
    zeros, the stands' installations per slot, and a ballbar set-up's pivot centre and
    zero); ``laser`` (N,): the drive a
    laser candidate reads (-1: a dial reading, :data:`BAR`: a ballbar reading);
    ``label`` (N, 3): a dial's (slot, posture, -1), a laser's (-1, axis, target index) or
    a ballbar's (:data:`BAR`, -1, point index);
    ``factor`` (n, r): ``F`` with ``F F^T`` the TCP error's weight padded with zeros
    (the zeros do not move the tool); ``local`` (N, k): the columns of each candidate's
    own unknowns (a dial's slot's zero and installation; -1: none), which no other
    slot's candidate reads (None: every column is shared), so that the information costs
    the shared columns' square and not all of them'."""

    rows: np.ndarray
    laser: np.ndarray
    label: np.ndarray
    factor: np.ndarray
    targets: np.ndarray  # (T,) the laser's targets along a drive, mm
    #: (B, 3) the ballbar's candidate points (commands, mm) and its set-up's pivot command
    #: and bar index (None: no ballbar).
    bar_points: np.ndarray | None = None
    pivot: tuple[tuple[float, float, float], int] | None = None
    local: np.ndarray | None = None

    def value(self, counts: np.ndarray) -> float:
        """``f(n)``: the predicted mean-square TCP error after rigid motion (mm^2) of
        ``counts`` (N,) readings of each candidate."""
        return _value(self.information(counts), self.factor)[0]

    @cached_property
    def _blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The shared columns and every candidate's values there (N, g), and the local
        candidates (sorted by slot) with their local values (M, k)."""
        assert self.local is not None
        owned = np.flatnonzero(self.local[:, 0] >= 0)
        if np.any(np.diff(self.local[owned, 0]) < 0):
            raise ValueError("a model's local candidates must come sorted by their columns")
        shared = np.setdiff1d(np.arange(self.rows.shape[1]), self.local[owned])
        return (shared, np.ascontiguousarray(self.rows[:, shared]), owned,
                np.take_along_axis(self.rows[owned], self.local[owned], axis=1))

    @cached_property
    def _groups(self) -> list[tuple[int, int, np.ndarray]]:
        """Each slot's local candidates, contiguous in :attr:`_blocks`' (M,): their
        start, end and local columns (every candidate of a slot has the slot's)."""
        columns = self.local[self._blocks[2]]
        starts = np.flatnonzero(np.r_[True, columns[1:, 0] != columns[:-1, 0]])
        ends = np.r_[starts[1:], len(columns)]
        return [(int(a), int(b), columns[a]) for a, b in zip(starts, ends, strict=True)]

    def information(self, counts: np.ndarray) -> np.ndarray:
        """``sum_i n_i a_i a_i^T`` (n, n) over the candidates read (``counts`` > 0)."""
        if self.local is None:
            return _information(self.rows, counts)
        shared, on_shared, owned, values = self._blocks
        used = np.flatnonzero(counts > 0)
        part = on_shared[used]
        out = np.zeros((self.rows.shape[1],) * 2)
        out[np.ix_(shared, shared)] = (part * counts[used, None]).T @ part
        mine = counts[owned] > 0
        rows, n, values = owned[mine], counts[owned][mine], values[mine]
        if not rows.size:
            return out
        columns = self.local[rows]
        # Each slot's candidates are contiguous: sum their outer products per slot.  The
        # products are laid out candidates last, so each slot's sum runs over contiguous
        # memory (the same sums, a third of the time of candidates first).
        starts = np.flatnonzero(np.r_[True, columns[1:, 0] != columns[:-1, 0]])
        weighted = np.ascontiguousarray((values * n[:, None]).T)[None]
        cross = np.add.reduceat(np.ascontiguousarray(on_shared[rows].T)[:, None] * weighted,
                                starts, axis=2)
        own = np.add.reduceat(np.ascontiguousarray(values.T)[:, None] * weighted, starts,
                              axis=2)
        # Every slot's blocks at once (no two slots share a column).
        blocks = columns[starts].T
        out[shared[:, None, None], blocks] = cross
        out[blocks, shared[:, None, None]] = cross
        out[blocks[:, None], blocks] = own
        return out

    def projected(self, x: np.ndarray) -> np.ndarray:
        """``rows @ x`` (N, r) for ``x`` (n, r)."""
        if self.local is None:
            return self.rows @ x
        shared, on_shared, owned, values = self._blocks
        out = on_shared @ x[shared]
        # Per slot, whose candidates share its columns: not each candidate's copy of them.
        local = out[owned]
        for start, end, columns in self._groups:
            local[start:end] += np.einsum("ik,kr->ir", values[start:end], x[columns])
        out[owned] = local
        return out

    def fall(self, x: np.ndarray) -> np.ndarray:
        """Each reading's fall of ``f`` (minus its gradient) where ``X = M^-1 F``."""
        return np.sum(self.projected(x) ** 2, axis=1)

    def value_and_fall(self, counts: np.ndarray) -> tuple[float, np.ndarray]:
        """``f(n)`` (mm^2) of ``counts`` (N,) readings and each candidate's fall of it
        there (N,): what a multiplicative design step weighs."""
        value, x = _value(self.information(counts), self.factor)
        return value, self.fall(x)

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

    def bar_index(self, rho: np.ndarray) -> int | None:
        """The ballbar candidate read at command ``rho`` (None: no candidate there)."""
        if self.bar_points is None:
            return None
        hit = np.flatnonzero(np.all(np.abs(self.bar_points - rho) < 1e-9, axis=-1))
        return int(np.flatnonzero(self.laser == BAR)[hit[0]]) if hit.size else None


def bar_bundle(design: MachineDesign) -> Bundle:
    """The ballbar's candidate readings as one bundle: the 50 mm bar at ISO 230-4's centre,
    read every :data:`BAR_STEP_DEG` round its circle in each coordinate plane."""
    from calibrators.agents import ballbar as circles  # (the agents import the planner)

    nominal = MachineParams(design=design)
    centre = inverse(nominal, np.full(3, circles.CENTRE_MM))
    angles = np.radians(np.arange(0.0, 360.0, BAR_STEP_DEG))
    points = []
    for plane in circles.PLANES:
        tcp = np.full((len(angles), 3), circles.CENTRE_MM)
        tcp[:, plane[0]] += circles.LENGTH_MM * np.cos(angles)
        tcp[:, plane[1]] += circles.LENGTH_MM * np.sin(angles)
        points.append(inverse(nominal, tcp))
    return Bundle("ballbar", "ballbar candidates", Op.PIVOT, np.concatenate(points),
                  centre=tuple(float(v) for v in centre),
                  bar=BALLBAR_LENGTHS_MM.index(circles.LENGTH_MM))


@lru_cache(maxsize=4)
def bound_model(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                interferometer_owned: bool, ballbar_owned: bool = False) -> BoundModel:
    """The candidates of a lab of ``design`` under ``conditions`` whose dials read with
    ``dial_sigma`` (mm, the weighting sigma), with or without the interferometer and the
    ballbar."""
    return _candidates(MachineParams(design=design), None, conditions, dial_sigma,
                       interferometer_owned, ballbar_owned)


def machine_bound_model(machine: MachineParams, conditions: Conditions, dial_sigma: float,
                        interferometer_owned: bool, installed: np.ndarray | None = None
                        ) -> BoundModel:
    """:func:`bound_model` linearised at ``machine`` (its 27 errors) with the stands at each
    slot installed with ``installed`` ((S, 4) parameters, None: as aimed) in place of the
    nominal machine's: the dials' rows and the TCP error's weight are the machine's.
    The candidates are the nominal model's (a dial where the nominal tip may touch: the
    machine's own contact could drop or add a few; with more candidates a bound is only
    lower), and so are the laser's rows (the carriage alone, no geometry).  The ballbar
    is no candidate here (its rows are the nominal machine's).

    What it is: the local, Cramer-Rao-type bound of that machine, where its fit
    linearises, so the mean over machines of each one's squared bound is a yardstick no
    plan, fixed or adaptive, beats on the linearised model.  What it is not: anything a
    plan can be designed on, since it reads the machine's truth: a yardstick for a
    comparison, never an agent's input (seconds per machine: its derivatives)."""
    return _candidates(machine, changes_at(machine, installed), conditions, dial_sigma,
                       interferometer_owned, False)


def _candidates(machine: MachineParams, change: tuple[np.ndarray, np.ndarray] | None,
                conditions: Conditions, dial_sigma: float, interferometer_owned: bool,
                ballbar_owned: bool) -> BoundModel:
    """:func:`bound_model` at ``machine`` whose dials' derivatives are ``change``
    (:attr:`~orthoglide_env.lab.slot_table.SlotTable.change` and ``at_zero``; None: the
    slot table's, the nominal machine's)."""
    if not (np.isfinite(dial_sigma) and dial_sigma > 0):
        raise ValueError(f"dial_sigma must be a positive number, got {dial_sigma}")
    design = machine.design
    table = slot_table(design)
    derivative, at_zero = (table.change, table.at_zero) if change is None else change
    scale = default_scales(ParameterSpace())
    slots, postures = np.nonzero(table.prior_reach[1] > 0)
    n_slots = len(table.tip)

    def lead(rho: np.ndarray) -> np.ndarray:
        terms = lead_terms(rho, design, conditions, DEFAULT_NODE_SPACING)
        return (np.stack([p for _, p in terms], axis=-1) if terms
                else np.zeros((*np.shape(rho), 0)))

    n_lead = lead(np.zeros((1, 3))).shape[-1]
    n = N_MACHINE + n_lead + n_slots + 3 + N_INSTALL * n_slots + (4 if ballbar_owned else 0)
    zero = N_MACHINE + n_lead  # the first zero's column
    installed = zero + n_slots + 3  # the first slot's installation's first column
    dial = np.zeros((len(slots), n))
    dial[:, :N_MACHINE] = derivative[slots, postures, :N_MACHINE]
    # The stand's installation, one per slot (the fit's and the planner's unknowns: a plan
    # that mounts a stand at a slot twice has two, which the bound knows to be equal).
    columns = installed + N_INSTALL * slots[:, None] + np.arange(N_INSTALL)
    dial[np.arange(len(slots))[:, None], columns] = derivative[slots, postures, N_MACHINE:]
    # A carriage's error moves a reading as its drive's encoder offset does, at the
    # posture (the zero takes the reading's value at Zero).
    drive = (derivative[slots, postures, :3] + at_zero[slots, :3]) / scale[:3]
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
    bar: Bundle | None = bar_bundle(design) if ballbar_owned else None
    if bar is not None:
        # The fit's rows of the bar's readings; its set-up's centre and zero are the last
        # four unknowns (one set-up: a plan's set-ups there share them, a relaxation).
        over, setup, _ = reading_rows(bar, design, conditions, bar.path)
        on_bar = np.zeros((len(bar.path), n))
        on_bar[:, :zero] = over
        on_bar[:, n - 4:] = setup
        rows.append(on_bar)
        laser.append(np.full(len(bar.path), BAR))
        label.append(np.stack([np.full(len(bar.path), BAR), np.full(len(bar.path), -1),
                               np.arange(len(bar.path))], axis=-1))
    weight = rigid_weight_with_drives(machine, lead)
    units = np.concatenate([scale, np.ones(n_lead)])
    weight = weight * np.outer(units, units)
    value, vector = np.linalg.eigh(weight)
    keep = value > 1e-12 * value[-1]
    factor = np.zeros((n, int(keep.sum())))
    factor[:zero] = vector[:, keep] * np.sqrt(value[keep])
    # A dial's own columns: its slot's zero and installation; no other candidate's.
    local = np.full((sum(len(r) for r in rows), 1 + N_INSTALL), -1)
    local[:len(slots), 0] = zero + slots
    local[:len(slots), 1:] = columns
    return BoundModel(np.vstack(rows), np.concatenate(laser), np.vstack(label), factor,
                      targets, None if bar is None else bar.path,
                      None if bar is None else (bar.centre, bar.bar), local)


def plan_counts(model: BoundModel, design: MachineDesign, slots: tuple[int, ...],
                engaged: tuple[bool, ...], actions: list[dict[str, object]]) -> np.ndarray:
    """The readings (N,) a discrete plan of lab ``actions`` (the lab env's, ``op``, ``rho``,
    ``stand``, ``slot``, ``axis``) takes, from stands at ``slots`` with plungers ``engaged``,
    counted per candidate of ``model``: every engaged stand at every posture it moves to or
    is re-mounted or set up at (where its nominal tip touches), and the laser, once set up
    on a drive, at each posture's target along it (its set-up reads at Zero; a target
    is taken at the nearest candidate; a move whose ``laser`` is 0, ``OrthoglideLab-v4``'s,
    leaves it unread), and the ballbar, once its pivot is set up at the
    model's, at every move until any other operation takes the bar off (a point off the
    candidates counts nothing).  ``f`` of these counts (:meth:`BoundModel.value`) is
    the plan's error on the bound's model, which the bound is below."""
    hits = plan_hits(model, design, slots, engaged, actions)
    return np.bincount(hits[:, 1], minlength=model.rows.shape[0]).astype(float)


def plan_hits(model: BoundModel, design: MachineDesign, slots: tuple[int, ...],
              engaged: tuple[bool, ...], actions: list[dict[str, object]]) -> np.ndarray:
    """(R, 2) each reading :func:`plan_counts` counts: the index of the action that took
    it and its candidate of ``model``."""
    table = slot_table(design)
    slots_, down = list(slots), list(engaged)
    hits: list[tuple[int, int]] = []
    axis = -1
    bar_in = False
    where = {tuple(p): k for k, p in enumerate(table.postures)}
    dial = {(int(a), int(b)): k for k, (a, b, _) in enumerate(model.label) if a >= 0}
    for i, step in enumerate(actions):
        op = Op(int(step["op"]))  # type: ignore[call-overload]
        if op == Op.PIVOT:
            bar_in = model.pivot is not None and np.allclose(
                step["rho"], model.pivot[0], rtol=0, atol=1e-9) and int(
                step["bar"]) == model.pivot[1]  # type: ignore[call-overload]
            continue
        if op != Op.MOVE:
            bar_in = False
        elif bar_in:
            k = model.bar_index(np.asarray(step["rho"], dtype=float))
            if k is not None:
                hits.append((i, k))
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
                hits.append((i, k))
        if axis >= 0 and (op != Op.MOVE or int(step.get("laser", 1))):  # type: ignore[call-overload]
            hits.append((i, model.laser_index(axis, float(rho[axis]))))
    return np.array(hits, dtype=int).reshape(-1, 2)


def _information(rows: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``sum_i n_i a_i a_i^T`` over the candidates read (``counts`` > 0)."""
    used = np.flatnonzero(counts > 0)
    part = rows[used]
    return (part * counts[used, None]).T @ part


def _value(information: np.ndarray, factor: np.ndarray) -> tuple[float, np.ndarray]:
    """``f`` at ``I + information`` and ``X = M^-1 F`` (n, r)."""
    # SciPy's linear algebra loads when a bound is solved: a planning agent's process that
    # is handed its plan (a sweep's workers) never solves one.
    from scipy.linalg import cho_factor, cho_solve

    m = np.eye(len(information)) + information
    x = cho_solve(cho_factor(m), factor)
    return float(np.sum(x * factor)), x


@dataclass(frozen=True)
class Visits:
    """The polytope of one problem: ``seconds`` of visits, each ``settle_s`` long and at one
    place (a candidate posture, or a ballbar point), reading there each dial slot whose
    candidate it is at most once and at most ``stands`` of them (or the bar's point), and
    the laser at one target for ``dwell_s`` more (a visit of its own where no dial or bar
    is read).  A slot the stands do not ``start`` at is read only after a re-mount there
    (``remount_s``), so each of its readings adds :attr:`moved_s` to its visit (an
    infinite ``remount_s``: the stands are held where they start, the polytope of the
    plans that never re-mount).  With ``phases`` (sets of slots) a visit reads the slots
    of one of them only: the stands stand at each set in turn, for as long as a design
    likes."""

    seconds: float
    settle_s: float
    dwell_s: float
    stands: int
    start: tuple[int, ...] = ()
    remount_s: float = 0.0
    phases: tuple[tuple[int, ...], ...] = ()

    @property
    def moved_s(self) -> float:
        """The seconds a reading of a slot the stands do not start at adds: a slot read at
        all took a re-mount, and no slot is read on more than ``seconds / settle_s``
        visits, so its readings ``n`` took at least ``n settle_s / seconds`` re-mounts."""
        return self.remount_s * self.settle_s / self.seconds

    def moved_seconds(self, count: np.ndarray) -> np.ndarray:
        """What ``count`` readings of slots the stands do not start at add to a visit
        (infinite where the stands are held and ``count`` is not 0)."""
        if np.isfinite(self.remount_s):
            return self.moved_s * np.asarray(count)
        return np.where(np.asarray(count) > 0, np.inf, 0.0)

    def prices(self, members: list[np.ndarray], grid: np.ndarray) -> np.ndarray:
        """The seconds of a visit that reads each of ``members`` (dial or bar candidates)."""
        lengths = [len(m) for m in members]
        flat = np.concatenate(members) if members else np.zeros(0, dtype=int)
        hit = np.isin(flat, _moved(grid, self.start))
        # One membership test over every visit's readings, counted per visit: a visit
        # per posture each generation made the test per visit the solver's largest cost.
        count = np.bincount(np.repeat(np.arange(len(members)), lengths), hit,
                            minlength=len(members)).astype(int)
        return self.settle_s + self.moved_seconds(count)


def _moved(grid: np.ndarray, start: tuple[int, ...]) -> np.ndarray:
    """The dial candidates (of ``grid``, see :func:`dial_grid`) of the slots not in
    ``start``."""
    columns = np.setdiff1d(np.arange(grid.shape[1]), start)
    cells = grid[:, columns]
    return cells[cells >= 0]


def dial_grid(model: BoundModel) -> np.ndarray:
    """(P, S) the dial candidate of each posture and slot of ``model`` (-1: none there)."""
    dials = np.flatnonzero(model.laser == -1)
    slot, posture = model.label[dials, 0], model.label[dials, 1]
    grid = np.full((int(posture.max()) + 1, int(slot.max()) + 1), -1)
    grid[posture, slot] = dials
    return grid


def best_visits(grid: np.ndarray, fall: np.ndarray, visits: Visits, base_s: float,
                base_gain: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Each posture's best visit per second against the readings' gains ``fall`` (N,,
    >= 0), a visit of ``base_s`` and ``base_gain`` (the laser's, when it reads) before its
    dials: its gain per second (P,), and the dial candidates it reads (P, m; -1: none).
    The best of each count of the starting slots' candidates and the others' is the top
    of each (the others' each cost :attr:`Visits.moved_s` alike), so the counts are
    enumerated; with :attr:`Visits.phases`, the best over the phases, each a grid of its
    own slots."""
    if visits.phases:
        alone = replace(visits, phases=())
        per = [best_visits(np.where(np.isin(np.arange(grid.shape[1]), phase), grid, -1),
                           fall, alone, base_s, base_gain) for phase in visits.phases]
        rates = np.stack([rate for rate, _ in per])
        best = np.argmax(rates, axis=0)
        width = max(picked.shape[1] for _, picked in per)
        picked = np.full((len(grid), width), -1)
        for j, (_, chosen) in enumerate(per):
            mine = best == j
            picked[mine, :chosen.shape[1]] = chosen[mine]
        return rates[best, np.arange(len(grid))], picked
    k = min(visits.stands, grid.shape[1])
    gains = np.where(grid >= 0, fall[grid], -np.inf)
    start = np.isin(np.arange(grid.shape[1]), visits.start)
    ranked, sums = [], []
    for columns in (np.flatnonzero(start), np.flatnonzero(~start)):
        order = np.argsort(-gains[:, columns], axis=1, kind="stable")[:, :k]
        ranked.append(np.take_along_axis(grid[:, columns], order, axis=1))
        top = np.take_along_axis(gains[:, columns], order, axis=1)
        sums.append(np.concatenate([np.zeros((len(grid), 1)), np.cumsum(top, axis=1)], axis=1))
    own, other = np.arange(sums[0].shape[1]), np.arange(sums[1].shape[1])
    moved = visits.moved_seconds(other)
    with np.errstate(invalid="ignore"):
        rate = ((base_gain + sums[0][:, :, None] + sums[1][:, None, :])
                / (base_s + moved[None, None, :]))
    rate[:, own[:, None] + other[None, :] > k] = -np.inf
    rate[:, :, ~np.isfinite(moved)] = -np.inf
    rate = np.nan_to_num(rate, nan=-np.inf).reshape(len(grid), -1)
    best = np.argmax(rate, axis=1)
    a, b = np.divmod(best, len(other))
    picked = np.concatenate([
        np.where(np.arange(ranked[0].shape[1]) < a[:, None], ranked[0], -1),
        np.where(np.arange(ranked[1].shape[1]) < b[:, None], ranked[1], -1)], axis=1)
    return rate[np.arange(len(grid)), best], picked


def gap(visits: Visits, grid: np.ndarray, lasers: np.ndarray, bars: np.ndarray,
        counts: np.ndarray, fall: np.ndarray) -> float:
    """The Frank-Wolfe duality gap at ``counts`` where the readings' gains (minus ``f``'s
    gradient) are ``fall``: ``max over the polytope of fall . s - fall . n``.  ``f`` is
    convex, so ``f(n) - gap`` is below its least value over the polytope.  The linear
    oracle: the polytope's vertices spend the budget on one kind of visit, so the most is
    the budget times the best gain per second of a visit (:func:`best_visits`, or a bar
    point of ``bars``), reading the laser's best candidate of ``lasers`` or not."""
    return visits.seconds * best_rate(visits, grid, lasers, bars, fall) - float(fall @ counts)


def best_rate(visits: Visits, grid: np.ndarray, lasers: np.ndarray, bars: np.ndarray,
              fall: np.ndarray) -> float:
    """The most any kind of visit of ``visits``'s polytope gains per second against the
    readings' gains ``fall``: :func:`gap`'s linear oracle per second of the budget."""
    settle, both = visits.settle_s, visits.settle_s + visits.dwell_s
    bar = float(fall[bars].max()) if bars.size else -np.inf
    rate = max(float(best_visits(grid, fall, visits, settle)[0].max()), bar / settle)
    if lasers.size:
        laser = float(fall[lasers].max())
        rate = max(rate, float(best_visits(grid, fall, visits, both, laser)[0].max()),
                   (bar + laser) / both)
    return rate


def _atoms(members: list[np.ndarray], n: int) -> csr_matrix:
    """(A, n) 0/1: the readings each visit in ``members`` (candidate indices) takes."""
    from scipy.sparse import csr_matrix  # as :func:`_value`'s linear algebra

    lengths = [len(m) for m in members]
    indptr = np.concatenate([[0], np.cumsum(lengths)])
    indices = np.concatenate(members) if members else np.zeros(0, dtype=int)
    return csr_matrix((np.ones(len(indices)), indices, indptr), shape=(len(members), n))


def solve(model: BoundModel, visits: Visits, lasers: np.ndarray,
          stop_above: float = np.inf, bars: np.ndarray | None = None,
          stop_below: float = 0.0) -> tuple[float, float, np.ndarray]:
    """The continuous design of least ``f`` over the polytope of ``visits`` with every dial
    candidate, the laser candidates ``lasers`` and the bar points ``bars`` (indices), by
    the multiplicative algorithm (Silvey, Titterington and Torsney 1978; Yu 2010 for
    A-optimality's monotone convergence) over visits, with their columns generated.

    A design is a share of the budget per kind of visit (a posture with a set of at most
    ``stands`` of its dial candidates, or a bar point), each at its price
    (:meth:`Visits.prices`), and per laser candidate, ``dwell_s`` each.  Each share is
    multiplied by its fall of ``f`` per second against the shares' mean: the fixed point
    is the optimum's condition, every kind used gains as much per second.  The laser's
    shares are capped so that it reads on at most every visit.  Every :data:`GAP_EVERY`
    steps the duality gap (:func:`gap`) is taken over the whole polytope (``f(n) - gap``
    is below the least ``f`` there for any ``n``), and each posture whose best visit
    (:func:`best_visits`) gains more per second than its kinds there is given that visit
    as a new kind, with half of the posture's share.  The best certified value is
    returned with the final design's value and counts.  Stops once the gap is
    :data:`GAP_SHARE` of the value, the certified value passes ``stop_above`` (a problem
    that cannot be the least), the design's value falls below ``stop_below`` (mm^2: the
    optimum is below it, all a search that compares with it asks), or after
    :data:`MAX_ITERATIONS`."""
    rows, factor = model.rows, model.factor
    grid = dial_grid(model)
    bars = np.zeros(0, dtype=int) if bars is None else bars
    _, picked = best_visits(grid, model.fall(factor), visits, visits.settle_s)
    members = [p[p >= 0] for p in picked] + [np.array([b]) for b in bars]
    place = np.concatenate([np.arange(len(picked)), len(picked) + np.arange(len(bars))])
    touched = np.array([len(m) > 0 for m in members])
    members, place = [m for m, t in zip(members, touched, strict=True) if t], place[touched]
    atoms = _atoms(members, rows.shape[0])
    price = np.concatenate([visits.prices(members, grid),
                            np.full(len(lasers), visits.dwell_s)])
    share = np.full(len(price), 1.0 / len(price))
    lower = -np.inf
    for iteration in range(MAX_ITERATIONS + 1):
        taken = share * visits.seconds / price
        n_atoms = atoms.shape[0]
        counts = atoms.T @ taken[:n_atoms]
        counts[lasers] += taken[n_atoms:]
        value, x = _value(model.information(counts), factor)
        fall = model.fall(x)
        gains = np.concatenate([atoms @ fall, fall[lasers]])
        if iteration % GAP_EVERY == 0 or iteration == MAX_ITERATIONS:
            lower = max(lower, value - gap(visits, grid, lasers, bars, counts, fall))
            if (value - lower <= GAP_SHARE * value or lower > stop_above
                    or value < stop_below or iteration == MAX_ITERATIONS):
                break
            atoms, place, share, gains, price = _generate(
                atoms, place, share, gains, price, grid, fall, visits)
        per_second = gains / price
        share = share * (per_second / float(share @ per_second)) ** POWER
        share /= share.sum()
        share = _cap_laser(share, price, atoms.shape[0], visits.dwell_s)
    return lower, value, counts


def _cap_laser(share: np.ndarray, price: np.ndarray, n_atoms: int, dwell_s: float
               ) -> np.ndarray:
    """``share`` with the laser's (after the ``n_atoms`` visits') scaled down, the visits'
    up, where it would read on more than every visit (``L <= V``)."""
    laser = share[n_atoms:].sum() / dwell_s
    visits = float(share[:n_atoms] @ (1.0 / price[:n_atoms]))
    if laser <= visits:
        return share
    # beta (visits' scale) and alpha (the laser's): alpha L = beta V, alpha sL + beta sV = 1.
    beta = 1.0 / (share[:n_atoms].sum() + dwell_s * visits)
    alpha = beta * visits / laser
    return np.concatenate([share[:n_atoms] * beta, share[n_atoms:] * alpha])


def _generate(atoms: csr_matrix, place: np.ndarray, share: np.ndarray, gains: np.ndarray,
              price: np.ndarray, grid: np.ndarray, fall: np.ndarray, visits: Visits
              ) -> tuple[csr_matrix, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`solve`'s column generation: the kinds of visit ``atoms`` at ``place`` with
    shares ``share``, gains ``gains`` and prices ``price`` (the laser's after them),
    without the kinds whose share has vanished (the multiplicative step never revives
    one), and with the best visit of each posture that gains more per second than every
    kind there, given half of the posture's share."""
    from scipy.sparse import vstack  # as :func:`_value`'s linear algebra

    n_atoms = atoms.shape[0]
    keep = np.concatenate([share[:n_atoms] > VANISHED * share.max(),
                           np.ones(len(share) - n_atoms, dtype=bool)])
    atoms, place = atoms[keep[:n_atoms]], place[keep[:n_atoms]]
    share, gains, price = share[keep], gains[keep], price[keep]
    n_atoms = atoms.shape[0]
    best, picked = best_visits(grid, fall, visits, visits.settle_s)
    held = np.zeros(len(best))
    dial = place < len(best)
    np.maximum.at(held, place[dial], (gains[:n_atoms] / price[:n_atoms])[dial])
    new = np.flatnonzero(best > held * (1 + 1e-9))
    if not new.size:
        return atoms, place, share, gains, price
    owned = np.bincount(place[dial], share[:n_atoms][dial], minlength=len(best))
    share = share.copy()
    share[:n_atoms][np.isin(place, new)] *= 0.5
    added = 0.5 * owned[new] + VANISHED * share.max()
    members = [picked[p][picked[p] >= 0] for p in new]
    cost = visits.prices(members, grid)
    atoms = vstack([atoms, _atoms(members, atoms.shape[1])], format="csr")
    share = np.concatenate([share[:n_atoms], added, share[n_atoms:]])
    share /= share.sum()
    gains = np.concatenate([gains[:n_atoms], best[new] * cost, gains[n_atoms:]])
    price = np.concatenate([price[:n_atoms], cost, price[n_atoms:]])
    return atoms, np.concatenate([place, new]), share, gains, price


@dataclass(frozen=True)
class Bound:
    """The bound of a lab and budget: ``bound_mm`` the certified least TCP error after
    rigid motion (mm), ``design_mm`` the error of the best continuous design found (at
    most :data:`GAP_SHARE` of the mean square above, unless the solver stopped early),
    ``gap_mm2`` their squares' difference, ``drives`` the drives the best design sets the
    laser up on and ``laser_readings`` how many laser readings it takes (real, a time
    share); ``ballbar_readings`` how many ballbar readings (0: no pivot set up; a bound
    without them writes no such key, as before the ballbar)."""

    bound_mm: float
    design_mm: float
    gap_mm2: float
    drives: tuple[int, ...]
    laser_readings: float
    ballbar_readings: float = 0.0

    def to_dict(self) -> dict[str, object]:
        out = {**asdict(self), "drives": list(self.drives)}
        if not self.ballbar_readings:
            del out["ballbar_readings"]
        return out

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> Bound:
        unknown = sorted(set(data) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"unknown bound key(s) {unknown}")
        return cls(float(data["bound_mm"]), float(data["design_mm"]),  # type: ignore[arg-type]
                   float(data["gap_mm2"]), tuple(int(d) for d in data["drives"]),  # type: ignore[attr-defined]
                   float(data["laser_readings"]),  # type: ignore[arg-type]
                   float(data.get("ballbar_readings", 0.0)))  # type: ignore[arg-type]


def setup_seconds(drives: tuple[int, ...]) -> float:
    """What setting the laser up on ``drives`` costs: a set-up each, the soak before the
    first."""
    if not drives:
        return 0.0
    return TIME.interferometer_soak_s + TIME.interferometer_setup_s * len(drives)


def lower_bound(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                budget_s: float, instruments: tuple[str, ...] = ("dial",),
                stands: int = len(PAPER_SLOTS), remounts: bool = True,
                machine: MachineParams | None = None,
                installed: np.ndarray | None = None) -> Bound:
    """The bound (see the module) of a lab of ``design`` under ``conditions`` with dials of
    weighting sigma ``dial_sigma`` (mm) on ``stands`` stands, owning ``instruments``, over
    a budget of ``budget_s`` seconds; without ``remounts``, the bound of the plans that
    never re-mount a stand (the stands held at the paper's slots: above the bound).  With
    ``machine`` (of ``design``), its bound linearised there, the stands' ``installed``
    parameters with it (:func:`machine_bound_model`: a yardstick that reads the truth)."""
    return best_design(design, conditions, dial_sigma, budget_s, instruments, stands,
                       remounts, machine, installed).bound


@dataclass(frozen=True)
class Design:
    """The bound's best continuous design: its :class:`Bound`, its set-ups (the laser's
    ``drives``, the ballbar's ``pivot`` or not) and its ``counts`` (N,) of the candidates
    of :func:`bound_model`'s model of the lab (real: time shares)."""

    bound: Bound
    drives: tuple[int, ...]
    pivot: bool
    counts: np.ndarray


def best_design(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                budget_s: float, instruments: tuple[str, ...] = ("dial",),
                stands: int = len(PAPER_SLOTS), remounts: bool = True,
                machine: MachineParams | None = None,
                installed: np.ndarray | None = None) -> Design:
    """:func:`lower_bound` with the design that reaches it (a plan rounds it:
    :mod:`calibrators.planning.rounding`)."""
    model = lab_model(design, conditions, dial_sigma, budget_s, instruments, stands,
                      machine, installed)
    return _least(model, problems(design, budget_s, instruments, stands, remounts))


def held_design(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                budget_s: float, instruments: tuple[str, ...] = ("dial",),
                slots: tuple[int, ...] = (), remounts: int | None = None,
                stands: int = len(PAPER_SLOTS),
                setups: tuple[tuple[tuple[int, ...], bool], ...] | None = None,
                stop_above: float = np.inf,
                phases: tuple[tuple[int, ...], ...] = (), at_contact: bool = False,
                machine: MachineParams | None = None,
                installed: np.ndarray | None = None,
                given: np.ndarray | None = None) -> Design:
    """The bound of the plans that re-mount ``remounts`` times (None: once per slot of
    ``slots`` beyond the paper's) and mount stands only at the paper's slots and
    ``slots``: :func:`best_design`'s problems with the stands held at all of those slots
    (each readable on any visit, at most ``stands`` a visit; :class:`Visits` with an
    infinite ``remount_s``) and the budget less ``remounts`` whole re-mounts
    (``TIME.remount_s`` each), over every choice of set-ups, or over ``setups`` alone
    (pairs of the laser's drives and the pivot: then a bound of the plans with those
    set-ups only).  A problem whose certified value passes ``stop_above`` (mm^2: a search's
    best so far) is left unsolved: its design is then no optimum, its bound still below it.

    Why it is a bound of those plans: a plan that re-mounts ``r`` times pays ``r`` times
    ``remount_s`` on top of the visit each re-mount's reading at Zero is (the lab's clock
    charges a re-mount its drive, settle and work), so its visits fit in the budget less
    ``r`` re-mounts; at every moment its stands stand at ``stands`` of the slots, so every
    visit reads at most ``stands`` of them, each once; it is a point of this problem.  So
    the least of this over the sets of at most ``r`` slots beyond the paper's is a bound of
    every plan that re-mounts at most ``r`` times (a plan re-mounting ``k <= r`` times is a
    point of its own ``k``'s problem).

    Why it is above :func:`lower_bound` (re-mounts priced per reading): every kind of visit
    here is one there, and with ``S`` a problem's seconds there, a slot beyond the paper's
    is read here on at most ``(S - r remount_s) / settle`` visits, so its readings' shares
    of a re-mount (:attr:`Visits.moved_s`, ``remount_s settle / S`` each) add at most one
    ``remount_s``, and the ``r`` slots at most the ``r`` re-mounts taken off: each point
    here is a point there, at the same ``f``.  With no slot and no re-mount it is
    :func:`lower_bound` without ``remounts``: the same problems.

    With ``phases`` (sets of at most ``stands`` of those slots), the bound of the plans
    whose stands stand at each set in turn: a visit reads the slots of one set only
    (:attr:`Visits.phases`), each set for as long as the design likes, so such a plan is
    a point of it, and it is above the bound without them (fewer kinds of visit).  With
    ``at_contact``, the same problem on :func:`at_contact_model`: the design a plan can
    expect to read, no bound.  With ``given`` (N,), readings of the model's candidates
    taken whatever the design (a plan's laser or bar runs, :func:`given_model`; their time is
    not in ``budget_s``): the least of the other readings beside them, a design to round,
    no bound.  ``machine`` and ``installed``: as :func:`lower_bound`'s."""
    start = start_slots(design, stands)
    added = tuple(s for s in sorted(set(slots)) if s not in start)
    if stray := sorted({s for phase in phases for s in phase} - set(start) - set(added)):
        raise ValueError(f"phases name slots {stray} neither the paper's nor of {slots}")
    count = len(added) if remounts is None else remounts
    if count < len(added):
        raise ValueError(f"{len(added)} slots beyond the paper's need as many re-mounts, "
                         f"got {count}")
    left = budget_s - count * TIME.remount_s
    if not left > 0:
        raise ValueError(f"{count} re-mounts leave no time of {budget_s} s")
    model = lab_model(design, conditions, dial_sigma, budget_s, instruments, stands,
                      machine, installed)
    if at_contact:
        model = at_contact_model(model, design)
    if given is not None:
        model = given_model(model, given)
    held = [(drives, pivot, replace(visits, start=start + added,
                                    phases=tuple(tuple(phase) for phase in phases)))
            for drives, pivot, visits in problems(design, left, instruments, stands, False)
            if setups is None or (drives, pivot) in setups]
    if not held:
        raise ValueError(f"no set-up of {setups} fits in {left} s")
    return _least(model, held, stop_above)


def at_contact_model(model: BoundModel, design: MachineDesign) -> BoundModel:
    """``model`` with each dial reading counted at its a-priori contact probability (its
    row times the root of it), as a plan expects it (:meth:`~calibrators.planning.belief.
    Belief.expect_readings`): a reading that misses reads nothing, so its value is above
    the bound's, which counts every candidate whole; a design to round, no bound."""
    contact = slot_table(design).prior_reach[1]
    dial = model.laser == -1
    weight = np.ones(len(model.laser))
    weight[dial] = np.sqrt(contact[model.label[dial, 0], model.label[dial, 1]])
    return replace(model, rows=model.rows * weight[:, None])


def given_model(model: BoundModel, counts: np.ndarray) -> BoundModel:
    """``model`` with ``counts`` (N,) readings taken before any design, none of a dial's
    own columns (:attr:`BoundModel.local`): ``f`` of a design's counts ``n`` on it is ``f``
    of ``counts + n`` on ``model``.  With ``I + G = L L^T`` the prior and the given
    readings' information on the columns they touch (the identity elsewhere), ``M = L (I +
    sum n_i b_i b_i^T) L^T`` with ``b_i = L^-1 a_i``, so the rows become ``b_i`` and the
    factor ``L^-1 F``: the same rows' structure, a dial's own columns untouched."""
    from scipy.linalg import cholesky, solve_triangular  # as :func:`_value`'s

    information = model.information(np.asarray(counts, dtype=float))
    columns = np.flatnonzero(np.any(information != 0, axis=0))
    if not columns.size:
        return model
    if model.local is not None and np.isin(columns, model.local[model.local >= 0]).any():
        raise ValueError("given readings must not read a dial's own columns")
    lower = cholesky(np.eye(len(columns)) + information[np.ix_(columns, columns)], lower=True)
    rows, factor = model.rows.copy(), model.factor.copy()
    rows[:, columns] = solve_triangular(lower, model.rows[:, columns].T, lower=True).T
    factor[columns] = solve_triangular(lower, model.factor[columns], lower=True)
    return replace(model, rows=rows, factor=factor)


def _least(model: BoundModel, choices: list[tuple[tuple[int, ...], bool, Visits]],
           stop_above: float = np.inf) -> Design:
    """The :class:`Design` of the least of ``model``'s problems ``choices`` (the laser's
    drives, the pivot or not, and the visits' polytope, as :func:`problems` gives them),
    each stopped once it cannot be the least (nor below ``stop_above``, mm^2)."""
    best: tuple[float, tuple[int, ...], bool, np.ndarray] | None = None
    lowest = np.inf
    for drives, pivot, visits in choices:
        lasers = np.flatnonzero(np.isin(model.laser, drives))
        bars = np.flatnonzero(model.laser == BAR) if pivot else None
        lower, value, counts = solve(model, visits, lasers,
                                     min(best[0], stop_above) if best else stop_above, bars)
        lowest = min(lowest, lower)
        if best is None or value < best[0]:
            best = (value, drives, pivot, counts)
    assert best is not None  # the dial-only problem always has a budget
    return _design(model, lowest, *best)


def _design(model: BoundModel, lowest: float, value: float, drives: tuple[int, ...],
            pivot: bool, counts: np.ndarray) -> Design:
    """The :class:`Design` of ``model``'s least certified value ``lowest`` and its best
    design's ``value`` (mm^2) with its set-ups and ``counts``."""
    lowest = max(lowest, 0.0)
    found = Bound(float(np.sqrt(lowest)), float(np.sqrt(value)), float(value - lowest),
                  tuple(drives), float(counts[model.laser >= 0].sum()),
                  float(counts[model.laser == BAR].sum()))
    return Design(found, tuple(drives), pivot, counts)


def lab_model(design: MachineDesign, conditions: Conditions, dial_sigma: float,
              budget_s: float, instruments: tuple[str, ...], stands: int,
              machine: MachineParams | None = None, installed: np.ndarray | None = None
              ) -> BoundModel:
    """:func:`bound_model` of a lab owning ``instruments``, its arguments checked; with
    ``machine``, :func:`machine_bound_model` at it and its stands' ``installed``."""
    if not (np.isfinite(budget_s) and budget_s > 0):
        raise ValueError(f"budget_s must be a positive number of seconds, got {budget_s}")
    if not (isinstance(stands, int) and stands >= 1):
        raise ValueError(f"stands must be a positive integer, got {stands!r}")
    if "dial" not in instruments:
        raise ValueError(f"instruments must include 'dial', got {list(instruments)}")
    owned = "interferometer" in instruments
    if machine is not None:
        if machine.design != design:
            raise ValueError("the machine must be of the lab's design")
        if "ballbar" in instruments:
            raise ValueError("a bound at a machine has no ballbar candidates")
        return machine_bound_model(machine, conditions, float(dial_sigma), owned, installed)
    return (bound_model(design, conditions, float(dial_sigma), owned, True)
            if "ballbar" in instruments
            else bound_model(design, conditions, float(dial_sigma), owned))


def start_slots(design: MachineDesign, stands: int) -> tuple[int, ...]:
    """The slots the lab's ``stands`` stands are mounted at on every reset: the paper's."""
    return tuple(slot_index(spec, design=design) for spec in PAPER_LAYOUT[:stands])


def problems(design: MachineDesign, budget_s: float, instruments: tuple[str, ...],
             stands: int, remounts: bool = True
             ) -> list[tuple[tuple[int, ...], bool, Visits]]:
    """The bound's problems, one per choice of set-ups: the drives the laser is set up on,
    the pivot set up or not, and the polytope of the visits the budget leaves them."""
    start = start_slots(design, stands)
    choices = [()] + ([c for k in (1, 2, 3) for c in itertools.combinations(range(3), k)]
                      if "interferometer" in instruments else [])
    # The pivot's set-up is paid once or not at all, as the laser's are.
    pivots = [False, True] if "ballbar" in instruments else [False]
    out = []
    for pivot in pivots:
        for drives in choices:
            # A set-up's own visit (at Zero, its settle on the clock) reads the laser
            # without a dwell: each is given one.
            seconds = (budget_s - setup_seconds(drives) - (TIME.ballbar_setup_s if pivot else 0)
                       + TIME.interferometer_target_s * len(drives))
            if seconds > 0:
                out.append((drives, pivot, Visits(
                    seconds, TIME.settle_and_read_s, TIME.interferometer_target_s, stands,
                    start, TIME.remount_s if remounts else np.inf)))
    return out
