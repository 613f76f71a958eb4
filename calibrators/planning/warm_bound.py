"""The bound with the timed terms unknown: the least TCP error after the best-fit rigid
motion that any plan can reach when, as the ``full`` fit does, it has to learn the drives'
warm-up and the stands' drift from the same readings.

:mod:`calibrators.planning.bound` takes every world term but the lead error as known, so
where the fit carries the timed terms as unknowns that bound is below what any plan's fit
can know.  Here they are unknowns of the bound's model too, with the priors of the
conditions table: the warm-up's 19 terms as ``full`` fits them
(:func:`~calibrators.estimators.consider.warmup_terms`: the amplitude's mean on every
axis, and per axis the time constant's and the amplitude's spread at three nodes), and
each stand's drift at the slots the lab mounts them at, as the planner carries it
(:func:`~calibrators.estimators.consider.drift_terms`: its creep at three time constants
and its arm's growth with the room).  They do not move the tool (the score is the
geometry's), but each reading sees them at the time it is taken, so a candidate is a pair
of a reading and a time: the budget is cut into :data:`TIME_BINS` equal bins, a reading
in bin ``k`` is read at the bin's middle, and the polytope is the bound's per bin
(:class:`~calibrators.planning.bound.Visits`), its visits at most the bin's seconds, and
all of them at most the budget less the set-ups (the set-ups fall in some bins, which the
bound leaves free).  ``f`` is convex over the pairs' counts, so its least value over that
polytope is again a convex problem, solved per bin by the multiplicative algorithm and
certified by the duality gap over the whole polytope (the linear oracle's bins filled best
rate first up to the budget, :func:`_fill`).

What it assumes, beyond the bound's relaxations:

* a reading's timed terms are those of its bin's middle (the warm-up's curves vary by
  their time constants, 20-40 minutes under ``lab``; the value's change with twice as
  many bins is measured in ``docs/instruments.md``);
* the warm-up moves a ballbar reading through the TCP it reads and through the pivot,
  centred where the warmed carriages put the TCP at the set-up's centre command, as the
  lead error does in the bound's rows (:func:`~calibrators.planning.instruments.
  bar_columns`), both at the reading's bin (the fit's pivot is warmed as at its set-up's
  end, earlier than the bins of a set-up's later readings: the bins' approximation);
* a stand's drift is counted from the lab's start and only at the slots it starts at; a
  stand re-mounted elsewhere, the backlash and the indicators' curves stay known: their
  unknowns would only raise it.

It is above the bound (the same polytope, cut by time, and more unknowns), and below
every plan's error on its own model (a plan's readings counted per candidate and bin,
:func:`plan_value`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from calibrators.estimators.consider import drift_terms, warmup_terms
from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import (
    BAR,
    GAP_EVERY,
    GAP_SHARE,
    MAX_ITERATIONS,
    POWER,
    Bound,
    BoundModel,
    Design,
    Visits,
    _atoms,
    _cap_laser,
    _design,
    _generate,
    _value,
    bar_bundle,
    best_rate,
    best_visits,
    dial_grid,
    lab_model,
    plan_hits,
    problems,
    start_slots,
)
from calibrators.planning.instruments import bar_columns, bar_layout, step_actions
from orthoglide_env.instruments import ballbar, interferometer
from orthoglide_env.lab.operations import PAPER_SLOTS
from orthoglide_env.lab.slot_table import slot_table
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.world.conditions import Conditions

#: The budget's bins of time.  Assumption: six, ten minutes at one hour and thirty at
#: three, below the warm-up's 20-40 minutes' time constant under ``lab``; the value's
#: change with twice as many is measured (``docs/instruments.md``).
TIME_BINS: int = 6
#: The timed families of the fit's unknowns the bound can carry.
TIMED_TERMS: tuple[str, ...] = ("warmup", "stands")


@dataclass(frozen=True)
class WarmModels:
    """The bound's model of a lab per bin of time: ``models`` (K) the bound's candidates
    with the warm-up's columns read at the middle of each bin of ``edges`` (K + 1, lab
    s)."""

    models: tuple[BoundModel, ...]
    edges: np.ndarray

    def value(self, counts: np.ndarray) -> float:
        """``f`` (mm^2) of ``counts`` (K, N) readings of each candidate in each bin."""
        information = sum(m.information(c) for m, c in zip(self.models, counts, strict=True))
        return _value(information, self.models[0].factor)[0]


def warm_rows(model: BoundModel, design: MachineDesign, conditions: Conditions,
              dial_sigma: float, t: float, start: tuple[int, ...] = (),
              terms: tuple[str, ...] = TIMED_TERMS) -> np.ndarray:
    """(N, W) each candidate of ``model``'s whitened row over the timed terms ``terms``
    read at lab time ``t`` (s).  ``warmup``: a carriage's warm-up moves a reading as its
    error does in the bound's rows (a dial's through its drive's encoder offset at the
    posture, the laser's along its drive, the bar's through the TCP and the pivot).  ``stands``: the
    drift of the stands mounted at the ``start`` slots at the lab's start, as the planner
    carries it (:func:`~calibrators.estimators.consider.drift_terms`, since time 0), on
    their dials' readings; other slots' mountings drift as known."""
    unknown = sorted(set(terms) - set(TIMED_TERMS))
    if unknown:
        raise ValueError(f"unknown timed terms {unknown}; known: {list(TIMED_TERMS)}")
    stroke = design.rho_max - design.rho_min

    def on(rho: np.ndarray) -> np.ndarray:
        x = (rho - design.rho_min) / stroke
        found = warmup_terms(x, np.full(len(rho), float(t)), conditions)
        return np.stack([p for _, p in found], axis=-1)  # (R, 3, W)

    dials = np.flatnonzero(model.laser == -1)
    slots, postures = model.label[dials, 0], model.label[dials, 1]
    parts = []
    if "warmup" in terms and "warmup" in conditions:
        out = np.zeros((model.rows.shape[0], 1 + 2 * 3 * 3))
        table = slot_table(design)
        drive = ((table.change[slots, postures, :3] + table.at_zero[slots, :3])
                 / default_scales(ParameterSpace())[:3])
        out[dials] = (np.einsum("ia,iaw->iw", drive, on(table.postures[postures]))
                      / dial_sigma)
        lasers = np.flatnonzero(model.laser >= 0)
        if lasers.size:
            axis = model.laser[lasers]
            rho = np.zeros((len(lasers), 3))
            rho[np.arange(len(lasers)), axis] = model.targets[model.label[lasers, 2]]
            out[lasers] = (on(rho)[np.arange(len(lasers)), axis]
                           / interferometer.sigma(conditions))
        bars = np.flatnonzero(model.laser == BAR)
        if bars.size:
            bundle = bar_bundle(design)
            out[bars] = (bar_columns(bundle, bar_layout(bundle, design, bundle.path), on)
                         / ballbar.sigma(conditions))
        parts.append(out)
    if "stands" in terms and "stands" in conditions and start:
        now = np.full(1, float(t))
        drift = np.array([p[0] for _, p in drift_terms(now, now, conditions)])
        out = np.zeros((model.rows.shape[0], len(start) * len(drift)))
        for j, slot in enumerate(start):
            mine = dials[slots == slot]
            out[mine, j * len(drift):(j + 1) * len(drift)] = drift / dial_sigma
        parts.append(out)
    return np.hstack(parts) if parts else np.zeros((model.rows.shape[0], 0))


def warm_models(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                budget_s: float, instruments: tuple[str, ...] = ("dial",),
                stands: int = len(PAPER_SLOTS), bins: int = TIME_BINS,
                terms: tuple[str, ...] = TIMED_TERMS, start: tuple[int, ...] | None = None
                ) -> WarmModels:
    """The bound's model of the lab (:func:`~calibrators.planning.bound.lab_model`) per
    bin of ``bins`` over ``budget_s``, the timed ``terms`` appended to its unknowns
    (:func:`warm_rows`), the stands' drift at the ``start`` slots (None: the lab's,
    :func:`~calibrators.planning.bound.start_slots`)."""
    if "warmup" not in conditions:
        raise ValueError(f"conditions {conditions.name!r} have no warm-up to bound")
    if not (isinstance(bins, int) and bins >= 1):
        raise ValueError(f"bins must be a positive integer, got {bins!r}")
    model = lab_model(design, conditions, dial_sigma, budget_s, instruments, stands)
    edges = np.linspace(0.0, budget_s, bins + 1)
    models = []
    for t in (edges[:-1] + edges[1:]) / 2:
        warm = warm_rows(model, design, conditions, dial_sigma, t,
                         start_slots(design, stands) if start is None else start, terms)
        models.append(replace(model, rows=np.hstack([model.rows, warm]), factor=np.vstack(
            [model.factor, np.zeros((warm.shape[1], model.factor.shape[1]))])))
    return WarmModels(tuple(models), edges)


def warm_design(design: MachineDesign, conditions: Conditions, dial_sigma: float,
                budget_s: float, instruments: tuple[str, ...] = ("dial",),
                stands: int = len(PAPER_SLOTS), bins: int = TIME_BINS,
                terms: tuple[str, ...] = TIMED_TERMS) -> tuple[Design, WarmModels]:
    """The bound with the timed terms unknown (see the module) of a lab as
    :func:`~calibrators.planning.bound.best_design`'s, with its best design (its counts
    (K, N) per bin) and its models."""
    warm = warm_models(design, conditions, dial_sigma, budget_s, instruments, stands, bins,
                       terms)
    first = warm.models[0]
    best: tuple[float, tuple[int, ...], bool, np.ndarray] | None = None
    lowest = np.inf
    for drives, pivot, visits in problems(design, budget_s, instruments, stands):
        lasers = np.flatnonzero(np.isin(first.laser, drives))
        bars = (np.flatnonzero(first.laser == BAR) if pivot else np.zeros(0, dtype=int))
        lower, value, counts = solve(warm, visits, lasers, bars)
        lowest = min(lowest, lower)
        if best is None or value < best[0]:
            best = (value, drives, pivot, counts)
    assert best is not None  # the dial-only problem always has a budget
    found = _design(first, lowest, *best[:3], best[3].sum(axis=0))
    return replace(found, counts=best[3]), warm


def warm_bound(design: MachineDesign, conditions: Conditions, dial_sigma: float,
               budget_s: float, instruments: tuple[str, ...] = ("dial",),
               stands: int = len(PAPER_SLOTS), bins: int = TIME_BINS,
               terms: tuple[str, ...] = TIMED_TERMS) -> Bound:
    """:func:`warm_design`'s :class:`~calibrators.planning.bound.Bound`."""
    return warm_design(design, conditions, dial_sigma, budget_s, instruments, stands,
                       bins, terms)[0].bound


def _fill(rates: np.ndarray, caps: np.ndarray, total_s: float) -> float:
    """The most ``rates`` (K,) per second gain with at most ``caps`` (K,) seconds in each
    bin and ``total_s`` in all: the best bins first."""
    out, left = 0.0, total_s
    for k in np.argsort(-rates, kind="stable"):
        take = min(caps[k], left)
        out += max(rates[k], 0.0) * take
        left -= take
    return out


def _blocks(widths: np.ndarray, total_s: float) -> np.ndarray:
    """Seconds of visits per bin of ``widths`` for a design: every bin's, but for the
    set-ups' (their sum less ``total_s``), taken from the first bins (a design's
    starting point only: the gap is taken over every split)."""
    cut = np.cumsum(widths) - (widths.sum() - total_s)
    return np.clip(np.minimum(widths, cut), 0.0, None)


def solve(warm: WarmModels, visits: Visits, lasers: np.ndarray, bars: np.ndarray
          ) -> tuple[float, float, np.ndarray]:
    """:func:`calibrators.planning.bound.solve` over bins of time: the least ``f`` of
    :class:`WarmModels` over the polytope of ``visits`` cut into bins (each bin's visits at
    most its seconds, all of them at most ``visits.seconds``), from a design whose bins
    are filled in order (:func:`_blocks`), each bin's shares moved by the multiplicative
    step within it; the duality gap is over the whole polytope.  Returns the certified
    value, the final design's value and its counts (K, N)."""
    models = warm.models
    factor = models[0].factor
    widths = np.diff(warm.edges)
    seconds = _blocks(widths, visits.seconds)
    grid = dial_grid(models[0])
    parts = []
    for model, budget in zip(models, seconds, strict=True):
        # A slot's re-mount share per reading is over the whole budget's visits: a slot
        # mounted once is read in every bin.
        block = replace(visits, seconds=max(budget, visits.settle_s),
                        remount_s=visits.remount_s * max(budget, visits.settle_s)
                        / visits.seconds)
        _, picked = best_visits(grid, model.fall(factor), block, block.settle_s)
        members = [p[p >= 0] for p in picked] + [np.array([b]) for b in bars]
        place = np.concatenate([np.arange(len(picked)), len(picked) + np.arange(len(bars))])
        touched = np.array([len(m) > 0 for m in members])
        members, place = [m for m, t in zip(members, touched, strict=True) if t], place[touched]
        price = np.concatenate([block.prices(members, grid),
                                np.full(len(lasers), block.dwell_s)])
        parts.append([block, budget, _atoms(members, model.rows.shape[0]), place,
                      np.full(len(price), 1.0 / len(price)), price])
    lower = -np.inf
    for iteration in range(MAX_ITERATIONS + 1):
        counts = np.zeros((len(models), models[0].rows.shape[0]))
        for k, (_, budget, atoms, _, share, price) in enumerate(parts):
            taken = share * budget / price
            counts[k] = atoms.T @ taken[:atoms.shape[0]]
            counts[k, lasers] += taken[atoms.shape[0]:]
        value, x = _value(sum(m.information(c) for m, c in zip(models, counts, strict=True)),
                          factor)
        falls = [m.fall(x) for m in models]
        gains = [np.concatenate([p[2] @ fall, fall[lasers]]) for p, fall in zip(parts, falls,
                                                                                strict=True)]
        if iteration % GAP_EVERY == 0 or iteration == MAX_ITERATIONS:
            rates = np.array([best_rate(p[0], grid, lasers, bars, fall)
                              for p, fall in zip(parts, falls, strict=True)])
            held = sum(float(f @ c) for f, c in zip(falls, counts, strict=True))
            lower = max(lower, value - (_fill(rates, widths, visits.seconds) - held))
            if value - lower <= GAP_SHARE * value or iteration == MAX_ITERATIONS:
                break
            for k, part in enumerate(parts):
                block, budget, atoms, place, share, price = part
                atoms, place, share, gains[k], price = _generate(
                    atoms, place, share, gains[k], price, grid, falls[k], block)
                parts[k] = [block, budget, atoms, place, share, price]
        for k, part in enumerate(parts):
            block, budget, atoms, place, share, price = part
            per_second = gains[k] / price
            share = share * (per_second / float(share @ per_second)) ** POWER
            share /= share.sum()
            part[4] = _cap_laser(share, price, atoms.shape[0], block.dwell_s)
    return lower, value, counts


def plan_value(warm: WarmModels, hits: np.ndarray, times: np.ndarray) -> float:
    """A plan's error on the bound's model with the timed terms unknown (mm^2): its readings
    ``hits`` (R, 2: action, candidate; :func:`~calibrators.planning.bound.plan_hits`)
    counted in the bin of their action's lab time ``times`` (per action, s)."""
    n = warm.models[0].rows.shape[0]
    when = np.clip(np.searchsorted(warm.edges, times[hits[:, 0]], side="right") - 1, 0,
                   len(warm.models) - 1)
    counts = np.zeros((len(warm.models), n))
    np.add.at(counts, (when, hits[:, 1]), 1.0)
    return warm.value(counts)


def steps_value(warm: WarmModels, design: MachineDesign, slots: tuple[int, ...],
                engaged: tuple[bool, ...], steps: tuple[PlannedOperation, ...]) -> float:
    """:func:`plan_value` (mm^2) of a planner's ``steps`` from stands at ``slots`` with
    plungers ``engaged``, each reading at its step's planned time."""
    hits = plan_hits(warm.models[0], design, slots, engaged, step_actions(steps))
    return plan_value(warm, hits, np.array([s.time_s for s in steps]))
