"""The lab's instruments beyond the dial gauges in an experiment's design: the
interferometer along a drive and the ballbar about a pivot, priced as the dials' moves are.

A set-up reads nothing by itself, so the planner prices a **bundle**: a set-up and the
readings it opens, and the lifts, drives and engages around them (:class:`Bundle`).  Every
:data:`~calibrators.planning.search.REMOUNT_CHECK_S` of a plan each bundle that fits in the
budget is priced by the fall of the predicted TCP error it buys per second of lab time,
set-up included, and taken when that beats the dials' greedy continuation (their next
:data:`~calibrators.planning.search.LOOKAHEAD_MOVES` moves per second): the greedy choice
of :func:`~calibrators.planning.search.greedy_plan`, with bundles among its options.

The bundles (:func:`bundles`):

* ``ballbar``: the pivot at ISO 230-4's centre with the 50 mm bar
  (:mod:`calibrators.agents.ballbar`), then both runs of one coordinate plane's circle, or
  of all three;
* ``interferometer``: the laser set up along one drive (its material sensor's soak before
  the lab's first set-up), then one bidirectional run over ISO 230-2's targets
  (:mod:`calibrators.agents.iso230`).

Their readings' rows are the fit's (:mod:`orthoglide_env.reading_model`): a ballbar's over
the 27 machine errors, the drives' lead error through the TCP and through the pivot
(centred where the carriages put the TCP at the set-up's centre command,
:func:`bar_columns`), and its set-up's pivot centre (its prior without the drives', as
the fit's) and zero; a laser's over its drive's lead error and its set-up's zero.  The lead
error's terms are those ``full`` fits (the pitch table's whitened coefficients and the
screw's periodic error, :func:`~calibrators.estimators.consider.lead_terms`): a lab that
owns such an instrument can see them, so its planner carries them as unknowns
(:class:`InstrumentKit`) and its criterion counts their share of the TCP error
(:func:`~orthoglide_env.scoring.predicted.rigid_weight_with_drives`, the bound's weight).
A set-up's own unknowns (centre, zero) are read by its bundle only, so they are
marginalised within it (:func:`marginal`): its readings enter the belief as equivalent rows
over the machine's errors and the lead terms.

What is left out, each a simplification of the price, not of the lab: the dials' rows do
not carry the lead terms (base-fixed gauges see next to none of them: ``benchmarks/
terms.py`` gives 0.00-0.01 of their variance), and a dial move's gain counts the machine's
errors only, as without instruments; the world's drift, backlash and warm-up do not act
on an instrument's rows, nor its scale error; a laser left set up reads at every later
move of a lab whose moves do not ask (``OrthoglideLab-v1`` to ``-v3``), which a plan
counts in time (its dwell) but not in information (in ``OrthoglideLab-v4`` the plan's other
moves leave it unread: :attr:`~calibrators.planning.belief.Belief.laser_asked`); the 100
and 150 mm bars' arcs are not candidates.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from calibrators.estimators.consider import (
    DEFAULT_NODE_SPACING,
    Consider,
    lead_terms,
    pivot_sigmas,
)
from calibrators.estimators.exact_fit import world_columns
from orthoglide_env.instruments import ballbar, interferometer
from orthoglide_env.instruments.ballbar import BallbarSpec
from orthoglide_env.lab.design_belief import N_MACHINE, ZERO_SCALE
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import inverse
from orthoglide_env.reading_model import (
    BALLBAR_CENTRE_SCALE,
    ParameterSpace,
    ReadingLayout,
    default_scales,
    jacobian,
)
from orthoglide_env.scoring.predicted import rigid_weight_with_drives
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM

#: The instruments a planner prices besides the dial gauges.
PLANNED_INSTRUMENTS: tuple[str, ...] = ("interferometer", "ballbar")
#: Eigenvalues of a bundle's information below this share of its largest are the rounding
#: of zeros (the information has the rank of what the readings see, at most its columns).
RANK_SHARE: float = 1e-12


class InstrumentOperation(NamedTuple):
    """A planned lab operation with the keys of a later env version's action: ``axis`` (an
    ``align``'s drive) and ``bar`` (a ``pivot``'s bar index); the other fields as
    :class:`~calibrators.planning.belief.PlannedOperation`'s."""

    op: Op
    rho: tuple[float, float, float] = (0.0, 0.0, 0.0)
    stand: int = 0
    slot: int = 0
    time_s: float = 0.0
    axis: int = 0
    bar: int = 0
    laser: int = 1


def operation_keys(step: NamedTuple) -> dict[str, int]:
    """The later version's keys an operation's action needs: an align's ``axis``, a pivot's
    ``bar``, and ``laser`` 0 on a move that leaves the interferometer unread (only a plan
    for ``OrthoglideLab-v4`` has one: a move that reads it needs no key there, as in
    v1-v3, so a plan that reads it at every move plays in every version)."""
    if isinstance(step, InstrumentOperation) and step.op == Op.ALIGN:
        return {"axis": step.axis}
    if isinstance(step, InstrumentOperation) and step.op == Op.PIVOT:
        return {"bar": step.bar}
    if step.op == Op.MOVE and not step.laser:  # type: ignore[attr-defined]
        return {"laser": 0}
    return {}


def step_actions(steps: Iterable[NamedTuple]) -> list[dict[str, object]]:
    """The lab env's actions of a planner's ``steps``, as the bound's counters read them
    (:func:`~calibrators.planning.bound.plan_counts`)."""
    return [{"op": s.op, "rho": s.rho, "stand": s.stand, "slot": s.slot,  # type: ignore[attr-defined]
             **operation_keys(s)} for s in steps]


def conditions_or_default(conditions: Conditions | None) -> Conditions:
    return conditions if conditions is not None else Conditions("ideal")


def lead_patterns(design: MachineDesign, conditions: Conditions | None, rho: np.ndarray
                  ) -> np.ndarray:
    """The lead error's terms at carriage positions ``rho`` (..., 3): (..., 3, L), mm per
    unit coefficient (L = 0 where the world has no lead error)."""
    rho = np.asarray(rho, dtype=float)
    terms = (lead_terms(rho, design, conditions, DEFAULT_NODE_SPACING)
             if conditions is not None else [])
    return (np.stack([p for _, p in terms], axis=-1) if terms
            else np.zeros((*rho.shape, 0)))


@lru_cache(maxsize=4)
def lead_weight(design: MachineDesign, conditions: Conditions | None
                ) -> tuple[np.ndarray, np.ndarray]:
    """The blocks of the TCP error's weight over the machine's errors (in units of their
    scale) and the lead terms: machine-lead (27, L) and lead-lead (L, L)."""
    count = lead_patterns(design, conditions, np.zeros(3)).shape[-1]
    if not count:
        return np.zeros((N_MACHINE, 0)), np.zeros((0, 0))
    weight = rigid_weight_with_drives(MachineParams(design=design),
                                      lambda rho: lead_patterns(design, conditions, rho))
    units = np.concatenate([default_scales(ParameterSpace()), np.ones(count)])
    weight = weight * np.outer(units, units)
    return weight[:N_MACHINE, N_MACHINE:], weight[N_MACHINE:, N_MACHINE:]


@dataclass
class InstrumentKit:
    """What a belief holds for the instruments its lab owns: which (``owned``), the state's
    columns of the lead terms (``lead``), the TCP error's weight over them, and whether
    the laser's material sensor has soaked (the dwell every move costs while the laser
    stays set up is the belief's, :attr:`~calibrators.planning.belief.Belief.dwell_s`)."""

    owned: tuple[str, ...]
    design: MachineDesign
    conditions: Conditions | None
    lead: np.ndarray
    soaked: bool = False

    def __post_init__(self) -> None:
        self.machine_lead, self.lead_lead = lead_weight(self.design, self.conditions)

    @property
    def columns(self) -> np.ndarray:
        """The state's columns an instrument's rows touch: the machine's, then the lead's."""
        return np.concatenate([np.arange(N_MACHINE), self.lead])

    def share(self, covariance: np.ndarray) -> float:
        """The lead terms' share of the predicted mean-square TCP error (mm^2), their
        correlation with the machine's errors included."""
        if not len(self.lead):
            return 0.0
        cross = covariance[:N_MACHINE][:, self.lead]
        return float(2 * np.sum(self.machine_lead * cross)
                     + np.sum(self.lead_lead * covariance[self.lead][:, self.lead]))

    def copy(self) -> InstrumentKit:
        return copy.copy(self)


def instrument_kit(instruments: tuple[str, ...], design: MachineDesign,
                   conditions: Conditions | None, start: int) -> InstrumentKit | None:
    """The kit of a lab owning ``instruments`` whose belief has ``start`` columns before the
    lead terms, or None when it owns none the planner prices (its plans are today's)."""
    owned = tuple(n for n in PLANNED_INSTRUMENTS if n in instruments)
    if not owned:
        return None
    count = lead_patterns(design, conditions, np.zeros(3)).shape[-1]
    return InstrumentKit(owned, design, conditions, start + np.arange(count))


# -- the bundles ------------------------------------------------------------------------
@dataclass(frozen=True)
class Bundle:
    """A set-up and the readings it opens: ``instrument``, a ``label`` for people, the
    set-up's operation (``ALIGN`` along ``axis``, or ``PIVOT`` at command ``centre`` with bar
    index ``bar``) and the commands ``path`` (R, 3) driven to while it reads."""

    instrument: str
    label: str
    setup: Op
    path: np.ndarray
    axis: int = 0
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bar: int = 0

    @property
    def spec(self) -> BallbarSpec:
        return BallbarSpec(self.centre, BALLBAR_LENGTHS_MM[self.bar])


@lru_cache(maxsize=4)
def bundles(design: MachineDesign, instruments: tuple[str, ...]) -> tuple[Bundle, ...]:
    """The candidate bundles of a lab owning ``instruments`` (see the module)."""
    # Imported here: the agents package imports the planner.
    from calibrators.agents import ballbar as circles
    from calibrators.agents import iso230

    out: list[Bundle] = []
    if "ballbar" in instruments:
        centre = inverse(MachineParams(design=design), np.full(3, circles.CENTRE_MM))
        bar = BALLBAR_LENGTHS_MM.index(circles.LENGTH_MM)
        names = {(0, 1): "XY", (1, 2): "YZ", (2, 0): "ZX"}
        for planes in [(p,) for p in circles.PLANES] + [circles.PLANES]:
            path = np.concatenate([circles.circle_postures(design, plane, clockwise)
                                   for plane in planes for clockwise in (False, True)])
            label = f"ballbar {circles.LENGTH_MM:g} mm {'+'.join(names[p] for p in planes)}"
            out.append(Bundle("ballbar", label, Op.PIVOT, path,
                              centre=tuple(float(v) for v in centre), bar=bar))
    if "interferometer" in instruments:
        run = iso230.run_postures(iso230.targets_of(design))
        for axis in range(3):
            path = np.zeros((len(run) + 1, 3))
            path[:-1, axis] = run  # then back to Zero, read too
            out.append(Bundle("interferometer", f"interferometer {'xyz'[axis]}", Op.ALIGN,
                              path, axis=axis))
    return tuple(out)


def reading_rows(bundle: Bundle, design: MachineDesign, conditions: Conditions | None,
                 path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The readings of ``bundle`` at commands ``path`` (R, 3): their rows (R, 27 + L) over
    the machine's errors (per unit scale) and the lead terms, their rows (R, U) over the
    set-up's own unknowns (per unit prior), both whitened, and their nominal values (mm)."""
    world = conditions_or_default(conditions)
    lead = lead_patterns(design, conditions, path)  # (R, 3, L)
    rows = np.zeros((len(path), N_MACHINE + lead.shape[-1]))
    if bundle.instrument == "interferometer":
        # The laser reads its carriage's own error; the set-up's zero takes the rest.
        rows[:, N_MACHINE:] = lead[:, bundle.axis]
        setup = np.full((len(path), 1), ZERO_SCALE)
        return rows / interferometer.sigma(world), setup / interferometer.sigma(world), \
            np.zeros(len(path))
    layout = bar_layout(bundle, design, path)
    space = layout.space
    derivative = jacobian(np.zeros(len(space)), layout, np.ones(len(space), dtype=bool),
                          default_scales(space))
    rows[:, :N_MACHINE] = derivative[:, :N_MACHINE]
    rows[:, N_MACHINE:] = bar_columns(
        bundle, layout, lambda rho: lead_patterns(design, conditions, rho))
    # The pivot's centre, in units of the fit's prior (the centring and the room's growth:
    # the drives' share is the lead columns' and, in the bound, a known term's), and the
    # bar's length.
    centre = (derivative[:, N_MACHINE:] * pivot_sigmas(layout, world, drives=False)
              / BALLBAR_CENTRE_SCALE)
    setup = np.column_stack([centre, np.full(len(path), ZERO_SCALE)])
    sigma = ballbar.sigma(world)
    return rows / sigma, setup / sigma, ballbar.nominal_readings(design, bundle.spec, path)


def bar_layout(bundle: Bundle, design: MachineDesign, path: np.ndarray) -> ReadingLayout:
    """The fit's layout of a ballbar ``bundle``'s readings at commands ``path`` (R, 3): one
    set-up."""
    return ReadingLayout.of(["ballbar#planned"] * len(path), [bundle.spec] * len(path),
                            path, design)


def bar_columns(bundle: Bundle, layout: ReadingLayout,
                patterns: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(R, K) the fit's columns (:func:`~calibrators.estimators.exact_fit.world_columns`,
    mm per unit coefficient) of K carriage terms over a ballbar ``bundle``'s readings
    (``layout``, :func:`bar_layout`), the terms' patterns at commands ``rho`` (P, 3) being
    ``patterns(rho)`` (P, 3, K): each term moves the TCP the bar reads and, through the
    pivot centred where the carriages put the TCP at the set-up's centre command, the bar's
    other end (:attr:`~calibrators.estimators.consider.Consider.pivot`)."""
    at = patterns(layout.rho)
    centre = np.broadcast_to(patterns(np.asarray(bundle.centre, dtype=float)[None]), at.shape)
    return world_columns(layout, Consider((), at[None], np.zeros((1, len(at), 0)),
                                          centre[None]))[0]


def marginal(rows: np.ndarray, setup: np.ndarray, residual: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """Equivalent rows (r, m) of whitened readings ``rows`` (R, m) whose set-up's unknowns,
    of unit prior and read by them only, enter through ``setup`` (R, U): their information
    ``A' (I + B B')^-1 A`` as ``E' E``; with whitened ``residual`` (R,) (reading less its
    prediction), the equivalent residual ``e`` (r,) with ``E' e`` the information vector, so
    a Bayesian update by ``E`` and ``e`` is the update by the readings, the set-up's unknowns
    integrated out."""
    inner = np.eye(setup.shape[1]) + setup.T @ setup
    cross = rows.T @ setup  # (m, U)
    information = rows.T @ rows - cross @ np.linalg.solve(inner, cross.T)
    value, vector = np.linalg.eigh((information + information.T) / 2)
    keep = value > RANK_SHARE * max(value[-1], 0.0)
    if not keep.any():
        return np.zeros((0, rows.shape[1])), None if residual is None else np.zeros(0)
    equivalent = (vector[:, keep] * np.sqrt(value[keep])).T
    if residual is None:
        return equivalent, None
    vector_b = rows.T @ residual - cross @ np.linalg.solve(inner, setup.T @ residual)
    return equivalent, (vector[:, keep].T @ vector_b) / np.sqrt(value[keep])


def planned_bundles(steps: tuple[NamedTuple, ...] | list[NamedTuple], design: MachineDesign,
                    owned: tuple[str, ...], extra: tuple[Bundle, ...] = ()
                    ) -> list[tuple[float, Bundle]]:
    """The bundles a plan's ``steps`` take (a lab owning ``owned``), each with the lab
    time of its set-up: the candidate (of :func:`bundles` and ``extra``) whose set-up it
    is and whose path the moves after it drive (the longest, where one path begins
    another)."""
    out: list[tuple[float, Bundle]] = []
    for i, step in enumerate(steps):
        if step.op not in (Op.ALIGN, Op.PIVOT):
            continue
        moves = []
        for later in steps[i + 1:]:
            if later.op != Op.MOVE:
                break
            moves.append(later.rho)
        driven = np.asarray(moves, dtype=float).reshape(-1, 3)
        matches = [b for b in (*bundles(design, owned), *extra)
                   if b.setup == step.op and operation_keys(step) == operation_keys(
                       InstrumentOperation(b.setup, axis=b.axis, bar=b.bar))
                   and len(b.path) <= len(driven)
                   and np.array_equal(driven[:len(b.path)], b.path)]
        if matches:
            out.append((step.time_s, max(matches, key=lambda b: len(b.path))))
    return out
