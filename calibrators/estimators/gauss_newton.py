"""``gauss-newton``: any experiment's readings, fitted with the exact model.

The paper linearises the gauge differences around the nominal machine and fits six
parameters.  This strategy fits the exact model (:mod:`orthoglide_env.reading_model`) with the
batched damped Gauss-Newton solver of :mod:`calibrators.estimators.exact_fit`, over any parameter
selection (``paper6``, ``extended`` with the gauge stands, groups, names), with priors or
base parameters, and reports what the data could and could not determine, a chi-square
test of the model, per-reading residuals with outliers flagged, and optional held-out
readings.  It reads any experiment's notebook or measurement file.
"""

from __future__ import annotations

import numbers
from collections import Counter
from collections.abc import Callable
from operator import attrgetter
from typing import Any, ClassVar, NamedTuple

import numpy as np

from calibrators.estimators.base import PARAM_NAMES, Estimate, Estimator, Measurements, register
from calibrators.estimators.consider import (
    DEFAULT_NODE_SPACING,
    FULL_TERMS,
    TERM_FAMILIES,
    WORLD_PREFIX,
    Consider,
    check_families,
    consider_terms,
    indicator_end,
    pivot_sigmas,
    term_family,
    thermometer_sigma,
)
from calibrators.estimators.consider import tracker_sigma as tracker_sigma_of
from calibrators.estimators.constraints import (
    BOOLEAN,
    NONE,
    Constraint,
    InstanceOf,
    Interval,
    Options,
    Satisfies,
)
from calibrators.estimators.differences import check_zeros
from calibrators.estimators.exact_fit import (
    CHI2_LEVEL,
    RETAIN,
    SOLVERS,
    BatchFit,
    directions,
    fit_batch,
    world_columns,
)
from calibrators.estimators.faults import (
    MAX_REPAIRS,
    PREFIX,
    Finding,
    drive_sensitivities,
    find_faults,
    slips_against_nominal,
)
from calibrators.estimators.holdout import held_out_residuals, holdout_mask, verification_rms
from calibrators.estimators.outliers import CAUSE_WORDS as CAUSE_WORDS
from calibrators.estimators.outliers import (
    LISTED_MISFITS,
    model_misfits,
    next_outlier,
    repetition_means,
)
from calibrators.estimators.outliers import MAX_OUTLIER_FRACTION as MAX_OUTLIER_FRACTION
from calibrators.estimators.outliers import OUTLIER_K as OUTLIER_K
from calibrators.estimators.parameters import (
    ParameterSpace,
    act_together,
    check_prior,
    describe,
    fixed_values,
    prior_sigmas,
    scales,
    select,
    sparse_basis,
)
from calibrators.estimators.solvers import StartModel
from calibrators.estimators.world_sizes import (
    blind_spot,
    family_index,
    judge,
    noiseless_readings,
    power_against,
    restricted_statistics,
    scaled,
    seen_families,
    told_scales,
    warning,
    widening,
)
from calibrators.measurements.record import instrument_of
from orthoglide_env.instruments.ballbar import BallbarSpec, centring_sigma
from orthoglide_env.instruments.ballbar import sigma as ballbar_sigma
from orthoglide_env.instruments.dial import DEFAULT_SIGMA, weighting_sigma
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.instruments.interferometer import sigma as interferometer_sigma
from orthoglide_env.instruments.step_gauge import sigma as step_gauge_sigma
from orthoglide_env.lab.operations import TRACKER_SIGMA
from orthoglide_env.model.compensation import node_count
from orthoglide_env.model.errors import (
    DEFAULT_PRESET,
    ERROR_NAMES,
    PRESETS,
    ErrorPreset,
    MachineFileError,
    MachineParams,
    check_validity,
    valid_vectors,
)
from orthoglide_env.model.kinematics import direct
from orthoglide_env.reading_model import (
    ReadingLayout,
    TrackerAxis,
    default_scales,
    preset_sigmas,
    station_of,
)
from orthoglide_env.scoring import best_rigid_motion
from orthoglide_env.world.conditions import (
    AUTO,
    CONDITION_NAMES,
    Conditions,
)

#: What to do about an estimate outside the validity range.
VALIDITY_HINT: str = ("free more parameters, e.g. --params extended, or take readings at "
                      "more postures")
def layout_and_values(data: Measurements, zeros: bool = True
                      ) -> tuple[ReadingLayout, np.ndarray]:
    """The reading layout and the readings of ``data``; tracker readings turned into the machine's
    frame (:func:`align_tracker`); a gauge mounting without a Zero reading is refused
    (:func:`~calibrators.estimators.differences.check_zeros`) unless ``zeros`` is False (a
    stand found moved, whose new mounting's zero the fit estimates)."""
    if not len(data):
        raise ValueError("no readings to fit")
    if zeros:
        check_zeros(data.items)
    design = ReadingLayout.of([m.mounting for m in data.items], [m.gauge for m in data.items],
                       np.array([m.rho for m in data.items], dtype=float), data.design)
    return design, align_tracker(design, np.array([m.reading for m in data.items], dtype=float))


def _tracker_rows(design: ReadingLayout, station: str) -> list[np.ndarray]:
    """The readings of ``station``'s x, y and z coordinates, each in reading order."""
    return [np.flatnonzero([station_of(design.mountings[m]) == station
                            and isinstance(design.specs[m], TrackerAxis)
                            and design.specs[m].component == c for m in design.mounting])
            for c in range(3)]


def tracker_reach(design: ReadingLayout, data: Measurements) -> float:
    """The farthest point of ``data`` from its tracker (mm; 0 without one): the norm of its
    three coordinates, which a tracker reads in its own frame."""
    raw = np.array([m.reading for m in data.items], dtype=float)
    reach = 0.0
    for station in design.space.stations:
        rows = _tracker_rows(design, station)
        if all(len(r) == len(rows[0]) for r in rows):
            reach = max(reach, float(np.sqrt(sum(raw[r] ** 2 for r in rows)).max(initial=0.0)))
    return reach


def align_tracker(design: ReadingLayout, values: np.ndarray) -> np.ndarray:
    """Tracker readings in the machine's frame, to within a small rotation: each station's
    points are fitted (best rigid motion) to where the nominal machine puts the TCP, and
    turned back by that fit.  What is left of the station's rotation is of the order of
    the machine's errors over its workspace, a few mrad, which its three ``rot``
    parameters then fit; its offset is the three coordinates' zeros."""
    out = values.copy()
    space = design.space
    for station in space.stations:
        rows = _tracker_rows(design, station)
        # Equal postures in equal order (array_equal also tells unequal counts).
        if any(not np.array_equal(design.rho[rows[0]], design.rho[r]) for r in rows[1:]):
            raise ValueError(f"tracker station '{station}': every point needs its x, y and z "
                             "readings, in the same order")
        measured = np.stack([values[rows[c]] for c in range(3)], axis=-1)
        nominal = direct(MachineParams(design=design.machine_design), design.rho[rows[0]])
        if np.linalg.matrix_rank(nominal - nominal.mean(axis=0), tol=1.0) < 2:
            raise ValueError(f"tracker station '{station}': its points must span a plane "
                             "(at least three postures off one line) to fix its frame")
        rotation, translation = best_rigid_motion(nominal[None], measured[None],
                                                  np.ones((1, len(nominal)), bool))
        aligned = measured @ rotation[0].T + translation[0]
        for c in range(3):
            out[rows[c]] = aligned[:, c]
    return out


def _every_reading(datas: list[Measurements], name: str) -> np.ndarray | None:
    """Field ``name`` of every reading of every experiment (M, N), or None when one
    reading lacks it."""
    rows = []
    field = attrgetter(name)
    for data in datas:
        rows.append(list(map(field, data.items)))
        if None in rows[-1]:  # e.g. no thermometer: known from the first experiment
            return None
    return np.array(rows, dtype=float)


def _check_fix(fix: Any) -> None:
    """``ValueError`` unless ``fix`` maps parameter names to finite numbers."""
    if not isinstance(fix, dict) or not all(
            isinstance(k, str) and isinstance(v, numbers.Real) and not isinstance(v, bool)
            and np.isfinite(v) for k, v in fix.items()):
        raise ValueError("")


def _check_terms(terms: Any) -> None:
    """``ValueError`` unless ``terms`` is a tuple of term families."""
    if not isinstance(terms, tuple):
        raise ValueError("")
    check_families(terms)


#: The world whose terms the readings' world is measured against
#: (:mod:`calibrators.estimators.world_sizes`): the table's worst, where every effect acts.
BASE_WORLD: str = "workshop"
#: The floor of a world the fit estimates, the table's best beyond the ideal: a family the
#: readings cannot see is carried at the lab's size, not at none.
FLOOR_WORLD: str = "lab"


def _check_conditions(conditions: Any) -> None:
    if not isinstance(conditions, Conditions) and conditions not in (*CONDITION_NAMES, AUTO):
        raise ValueError("")


@register
class GaussNewtonCalibrator(Estimator):
    """The exact model, any parameter set.

    Parameters: ``params``, the free parameters (a selection of
    :mod:`calibrators.estimators.parameters`; ``full``: every parameter (``extended``) and,
    unless ``fit_world`` says otherwise, the terms of
    :data:`~calibrators.estimators.consider.FULL_TERMS` (and, of readings that hold a laser
    interferometer's, the screw's periodic error) on a pitch-error table, whose
    ``node_spacing`` defaults to :data:`~calibrators.estimators.consider.DEFAULT_NODE_SPACING`);
    ``sigma``, a dial gauge's noise (mm); ``verify``, leave-one-repetition-out verification;
    ``prior``, the parameters' zero-mean normal prior; ``fix``, parameters held at known
    values; ``keep_outliers``, flag outliers but keep them in the fit; ``holdout``, the
    fraction of readings held out (drawn with ``seed``) and predicted; ``solver``, one of
    :data:`~calibrators.estimators.solvers.SOLVERS`; ``tracker_sigma``, a laser tracker
    coordinate's noise (mm); ``explain``: the words on which combinations the data
    determine and which not (``identifiable``, ``unidentifiable``; they cost more than the
    fit on large designs); ``conditions``, the lab's (a name or
    :class:`~orthoglide_env.world.conditions.Conditions`), whose effects the fit does not
    model but puts in its covariance (:mod:`calibrators.estimators.consider`); under
    conditions with the tracker's MPE, its readings' sigma comes from it
    (:func:`~calibrators.estimators.consider.tracker_sigma`) instead; ``left_out``: the
    error preset whose sizes the machine errors and stand errors the selection leaves out
    have a priori (their spread goes into the covariance; ``paper`` or ``nominal``: they do
    not exist, and only a misfit widens it); ``fit_world``: the conditions' terms of these
    families (:data:`~calibrators.estimators.consider.TERM_FAMILIES`; True: all) are fitted
    (each coefficient a parameter ``world.<term>`` with its second moment as a normal
    prior) instead of considered; ``node_spacing``: the lead error's curve as a
    controller's pitch-error table with nodes this far apart (mm), with the lead curve
    the lab draws as its prior (:func:`~calibrators.estimators.consider.table_prior`);
    ``conditions="auto"``: the fit estimates the world from the readings, each effect
    family's size between the ``lab``'s and twice the ``workshop``'s
    (:mod:`calibrators.estimators.world_sizes`);
    ``world_check``: a warning of kind ``world`` when the readings show a world worse than
    the named ``conditions``, with the effects that show it; ``curvature``: a fit of
    interferometer or ballbar readings puts the model's curvature into its covariance
    (:func:`~calibrators.estimators.exact_fit.fit_batch`); a caller that reads only the
    estimate, not its error bars, leaves it out (the same estimate, at about half a
    three-hour notebook's cost); ``fault_words``: every fault the readings show is named
    in the warnings (:func:`~calibrators.estimators.faults.find_faults`); a caller that
    reads only the estimate leaves them out: the faults are then looked for as far as a
    repair can change the estimate (the same estimate, without the drives' test where no
    stand steps).
    """

    name = "gauss-newton"
    title = "the exact-model fit"
    _parameter_constraints: ClassVar[dict[str, list[Constraint]]] = {
        "params": [InstanceOf(str, "a parameter selection (paper6, extended, full, or a "
                                   "comma list of groups and names)")],
        "sigma": [Interval(0, None)],
        "verify": [BOOLEAN],
        "prior": [Satisfies(check_prior, "a prior (none, auto, a preset and/or "
                                         "GROUP=SIGMA or NAME=SIGMA)")],
        "fix": [NONE, Satisfies(_check_fix, "a dict of parameter names to finite numbers")],
        "keep_outliers": [BOOLEAN],
        "holdout": [Interval(0, 1, "left")],  # 0: none held out
        "seed": [Interval(None, None, integer=True)],
        "solver": [Options(tuple(SOLVERS))],
        "tracker_sigma": [Interval(0, None, "neither")],
        "explain": [BOOLEAN],
        "conditions": [Satisfies(_check_conditions, f"one of {[*CONDITION_NAMES, AUTO]} or a "
                                                    "Conditions")],
        "world_check": [BOOLEAN],
        "left_out": [Options(tuple(sorted(PRESETS)))],
        "fit_world": [BOOLEAN, Satisfies(_check_terms, f"a tuple of term families "
                                                       f"{list(TERM_FAMILIES)}")],
        "node_spacing": [NONE, Interval(0, None, "neither")],
        "curvature": [BOOLEAN],
        "fault_words": [BOOLEAN],
    }

    def __init__(self, *, params: str = "paper6", sigma: float = DEFAULT_SIGMA,
                 verify: bool = True, prior: str = "auto", fix: dict[str, float] | None = None,
                 keep_outliers: bool = False, holdout: float = 0.0, seed: int = 0,
                 solver: str = "gauss-newton", tracker_sigma: float = TRACKER_SIGMA,
                 explain: bool = True, conditions: Conditions | str = "ideal",
                 left_out: str = DEFAULT_PRESET, fit_world: bool | tuple[str, ...] = False,
                 node_spacing: float | None = None, world_check: bool = False,
                 curvature: bool = True, fault_words: bool = True) -> None:
        self.params, self.sigma, self.verify, self.prior = params, sigma, verify, prior
        self.fix, self.keep_outliers, self.holdout, self.seed = fix, keep_outliers, holdout, seed
        self.solver, self.tracker_sigma, self.explain = solver, tracker_sigma, explain
        self.conditions, self.left_out, self.fit_world = conditions, left_out, fit_world
        self.node_spacing, self.world_check = node_spacing, world_check
        self.curvature, self.fault_words = curvature, fault_words
        self._validate_params()

    def fit(self, data: Measurements) -> Estimate:
        """The estimate of ``data`` (:meth:`fit_many` of one experiment)."""
        result = self.fit_many([data])[0]
        if isinstance(result, Exception):
            raise result
        return result

    def fit_many(self, datas: list[Measurements]) -> list[Estimate | Exception]:
        """:meth:`fit` of many experiments: those of one design (the same readings of the
        same mountings at the same postures, as a fixed agent takes them on every machine)
        are fitted together, in one batched solve.  A failure is returned in place of its
        estimate, not raised.  Each fit's faults are named in its warnings
        (:mod:`calibrators.estimators.faults`); a knocked stand or a skipped row is
        refitted with its readings repaired."""
        layouts: list[tuple[ReadingLayout, np.ndarray] | None] = []
        out = self._fit_all(datas, layouts=layouts)
        for k, est in enumerate(out):
            if isinstance(est, Estimate):
                out[k] = self._with_faults(est, layouts[k])
            elif isinstance(est, RuntimeError):
                out[k] = self._without_slips(datas[k], est)
        return out

    def _without_slips(self, data: Measurements, failure: RuntimeError
                       ) -> Estimate | Exception:
        """A fit of ``data`` that did not converge (``failure``) done again without the
        readings written with the wrong sign, or with rows written late put back, when the
        nominal machine shows them (:func:`slips_against_nominal`)."""
        try:
            design, values = layout_and_values(data)
        except ValueError:
            return failure
        found = slips_against_nominal(data, design, values)
        if not found:
            return failure
        est = self._fit_all([found[0].repaired])[0]  # type: ignore[list-item]
        if isinstance(est, Estimate):
            est.warnings = [f.text for f in found] + est.warnings
        return est

    def _with_faults(self, est: Estimate,
                     layout: tuple[ReadingLayout, np.ndarray] | None = None) -> Estimate:
        """``est`` with the faults its readings show named first in its warnings, refitted
        on the readings repaired when one is repairable (``layout``: the layout and values
        of ``est``'s readings, when the caller has them)."""
        texts: list[str] = []
        named: set[tuple[str, str]] = set()
        # Each pass repairs one fault and fits again; the next finds what is left.
        for _ in range(MAX_REPAIRS + 1):
            found = [f for f in self._faults(est, layout) if (f.kind, f.where) not in named]
            texts += [f.text for f in found]
            named |= {(f.kind, f.where) for f in found}
            repaired = next((f.repaired for f in found if f.repaired is not None), None)
            if repaired is None:
                break
            refit = self._fit_all([repaired], zeros=False)[0]
            if not isinstance(refit, Estimate):
                texts.append(f"{PREFIX}: the refit on the repaired readings failed ({refit}); "
                             "this estimate is of the readings as written")
                break
            est, layout = refit, None
        est.warnings = texts + est.warnings
        return est

    def _faults(self, est: Estimate, layout: tuple[ReadingLayout, np.ndarray] | None = None
                ) -> list[Finding]:
        """The faults ``est``'s readings show (:func:`find_faults`; ``layout``: see
        :meth:`_with_faults`)."""
        used = np.ones(len(est.residuals), dtype=bool)
        used[est.outliers] = False
        residuals = est.residuals.copy()
        residuals[est.outliers] = est.outlier_residuals
        # A model of the paper's six errors alone cannot fit a machine with more: its
        # residuals step and drift where nothing went wrong.
        structural = any(n in ERROR_NAMES and n not in PARAM_NAMES for n in est.names)

        def drives() -> np.ndarray:
            design, values = (layout_and_values(est.readings, zeros=False) if layout is None
                              else layout)
            return drive_sensitivities(design, values, est.theta, used)

        return find_faults(est.readings, residuals, used, est.outliers,
                           weighting_sigma(self.sigma), structural=structural,
                           drives=drives if structural else None, words=self.fault_words)

    def _fit_all(self, datas: list[Measurements], zeros: bool = True,
                 layouts: list[tuple[ReadingLayout, np.ndarray] | None] | None = None
                 ) -> list[Estimate | Exception]:
        """The fits of :meth:`fit_many`, before their faults are looked for (``zeros``:
        of :func:`layout_and_values`; ``layouts`` is filled with each one's layout and
        values, None where they were refused)."""
        out: list[Estimate | Exception] = [ValueError("not fitted")] * len(datas)
        auto = self.conditions == AUTO
        conditions = (Conditions(BASE_WORLD if auto else self.conditions)
                      if isinstance(self.conditions, str) else self.conditions)
        fit_world, node_spacing = self.fit_world, self.node_spacing
        full = self.params == "full" and fit_world is False
        if full:
            fit_world = FULL_TERMS
            node_spacing = DEFAULT_NODE_SPACING if node_spacing is None else node_spacing
        terms = check_families(TERM_FAMILIES if fit_world is True else fit_world or ())
        if node_spacing is not None:
            machine = (datas[0].design if datas else MachineParams().design)
            node_count(machine.rho_max - machine.rho_min, node_spacing)
        groups: dict[tuple, list[int]] = {}
        prepared = [] if layouts is None else layouts
        for k, data in enumerate(datas):
            try:
                design, values = layout_and_values(data, zeros)
            except ValueError as exc:
                out[k] = exc
                prepared.append(None)
                continue
            prepared.append((design, values))
            # Under the tracker's MPE its sigma depends on how far its points are.
            reach = tracker_reach(design, data) if "tracker" in conditions else 0.0
            key = (design.mountings, design.specs, design.rho.tobytes(),
                   design.mounting.tobytes(), reach)
            groups.setdefault(key, []).append(k)
        options = {"params": self.params, "prior": self.prior, "fix": self.fix or {},
                   "holdout": self.holdout, "seed": self.seed, "solver": self.solver,
                   "keep_outliers": self.keep_outliers, "sigma": self.sigma,
                   "tracker_sigma": self.tracker_sigma, "verify": self.verify,
                   "explain": self.explain, "conditions": conditions,
                   "left_out": PRESETS[self.left_out], "terms": terms,
                   "spacing": node_spacing, "auto": auto,
                   "world_check": self.world_check}
        for members in groups.values():
            design = prepared[members[0]][0]
            values = np.stack([prepared[k][1] for k in members])
            seen = dict(options)
            plain = []
            if full and any(isinstance(s, InterferometerAxis | BallbarSpec)
                            for s in design.specs):
                # An interferometer reads a carriage to 0.1 um, a ballbar the TCP to
                # 0.35 um: the screw's periodic error is plain in their readings, and
                # fitted, not considered.
                plain.append("periodic")
            if full and conditions.indicator == "digital":
                # A digital indicator reads to 2 um: its own error curve and retrace (up
                # to 3 and 2 um) and the screw's periodic error (up to 6 um) are plain in
                # its readings, and fitted (with their priors), not considered.
                plain += ["periodic", "dial"]
            if plain:
                seen["terms"] = check_families((*terms, *plain))
            try:
                results = self._fit_group(design, values, [datas[k] for k in members],
                                          **seen)
            except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
                results = [exc] * len(members)
            for k, result in zip(members, results, strict=True):
                out[k] = result
        return out

    def _fit_group(self, design: ReadingLayout, values: np.ndarray, datas: list[Measurements], *,
                   params: str, prior: str, fix: dict[str, float], holdout: float, seed: int,
                   solver: str, keep_outliers: bool, sigma: float, tracker_sigma: float,
                   verify: bool, explain: bool, conditions: Conditions,
                   left_out: ErrorPreset, terms: tuple[str, ...], spacing: float | None,
                   auto: bool, world_check: bool) -> list[Estimate | Exception]:
        """Fit the experiments ``values`` (M, N) of one ``design`` together."""
        space = design.space
        times, temperatures = (_every_reading(datas, name) for name in ("time_s",
                                                                        "temperature_c"))
        consider = consider_terms(design, values, times, conditions, spacing, temperatures)
        free = select(params, space)
        fixed = fixed_values(fix, space)
        for name in fix:
            free[space.names.index(name)] = False
        if not free.any():
            raise ValueError("every parameter of the selection is fixed: nothing to fit")
        unmodelled = ~free & ~np.isin(np.arange(len(space)),
                                      [space.names.index(n) for n in fix])
        priors = prior_sigmas(prior, space, free)
        if space.ballbars:
            # A pivot sits where the drives truly put the TCP: the drives' terms move it
            # (their patterns at its centre, when it was centred), and its default prior
            # (the centring's) widens by what no term holds, the room's growth.
            centres = np.array([g == "ballbar_centre" for g in space.groups])
            priors[centres] = np.where(priors[centres] == centring_sigma(),
                                       pivot_sigmas(design, conditions, drives=False),
                                       priors[centres])
        scale = scales(space, priors)
        needed = len(design.mountings) + int(np.sum(~np.isfinite(priors[free]))) + 1
        if values.shape[1] < needed:
            raise ValueError(f"{values.shape[1]} readings cannot determine "
                             f"{len(design.mountings)} gauge zeros and the parameters "
                             f"without a prior: at least {needed} are needed")
        spread = preset_sigmas(left_out, space)
        names = list(space.names)
        world = None
        tracked = np.array([isinstance(design.specs[m], TrackerAxis)
                            for m in design.mounting])
        if "tracker" in conditions and tracked.any():
            # One machine's (estimate_many groups machines by it).
            tracker_sigma = tracker_sigma_of(conditions, tracker_reach(design, datas[0]))
        if temperatures is not None:
            # The thermometer's rounding, through the stands' arms, is white on a reading.
            sigma = float(np.hypot(sigma, thermometer_sigma(conditions)))
        noise = np.where(tracked, tracker_sigma, sigma)
        lasers = np.array([isinstance(design.specs[m], InterferometerAxis)
                           for m in design.mounting])
        if lasers.any():
            noise = np.where(lasers, interferometer_sigma(conditions), noise)
        bars = np.array([isinstance(design.specs[m], BallbarSpec) for m in design.mounting])
        if bars.any():
            noise = np.where(bars, ballbar_sigma(conditions), noise)
        if design.probed.any():
            noise = np.where(design.probed, step_gauge_sigma(conditions), noise)
        held = holdout_mask(design, holdout, seed) if holdout else np.zeros(values.shape[1], bool)
        # A digital indicator's readings near its stroke's ends scatter beyond its sigma.
        ends = indicator_end(design, values, conditions)
        used = ~held & ~ends
        base_of = _world_terms(design, times, temperatures, conditions, spacing)
        told_terms = consider
        shown: list[dict[str, float]] = [{} for _ in values]
        if auto:
            sizes = _estimated_world(
                design, values, used, noise, free, fixed, priors,
                scale, unmodelled, spread, solver, base_of)
            consider = scaled(consider, sizes)
            present = {term_family(n) for n in consider.names}
            shown = [{f: float(v) for f, v in zip(TERM_FAMILIES, row, strict=True)
                      if f in present} for row in sizes]
        fitted, consider = consider.split(terms)
        if not fitted.empty:
            # The terms' coefficients, in units of their root second moment, join the
            # parameters with a unit normal prior.
            world = world_columns(design, fitted)
            names += [f"{WORLD_PREFIX}{n}" for n in fitted.names]
            k = world.shape[-1]
            free, fixed, priors, scale, unmodelled, spread = (
                np.concatenate([a, np.full(k, v, dtype=a.dtype)])
                for a, v in ((free, True), (fixed, 0.0), (priors, 1.0), (scale, 1.0),
                             (unmodelled, False), (spread, 0.0)))

        # An interferometer or a ballbar determines the best-seen combinations finely
        # enough that the model's curvature over what it does not see outgrows them.
        curved = self.curvature and any(isinstance(s, InterferometerAxis | BallbarSpec)
                                        for s in design.specs)

        # The fits below that start at the prior mean (the refits that leave one outlier
        # out after another) share its model and Jacobian.
        shared = StartModel()

        def fit(rows: np.ndarray, mask: np.ndarray, terms: Consider = consider,
                start: np.ndarray | None = None) -> BatchFit:
            return fit_batch(design, values[rows], mask[rows], noise, free, fixed, priors,
                             scale, unmodelled=unmodelled, solver=solver,
                             consider=terms.rows(rows), left_out=spread,
                             world=None if world is None else world[rows], start=start,
                             curvature=curved, shared=shared)

        m_count = len(values)
        mask = used
        results = fit(np.arange(m_count), mask).split()
        outliers: list[list[int]] = [[] for _ in range(m_count)]
        causes: list[list[str]] = [[] for _ in range(m_count)]
        group = design.distinct[1]  # each reading's mounting at its posture: repetitions
        pending = np.arange(m_count)
        while len(pending):
            pending = np.array([m for m in pending if results[m].converged[0] and len(
                outliers[m]) < MAX_OUTLIER_FRACTION * values.shape[1]], dtype=int)
            flagged, why = next_outlier(np.array([results[m].residuals[0] for m in pending]),
                                        group, noise)
            for m, k, cause in zip(pending, flagged, why, strict=True):
                if k >= 0:
                    outliers[m].append(int(k))
                    causes[m].append(cause)
                    mask[m, k] = False
            pending = pending[flagged >= 0]
            if len(pending):
                for m, result in zip(pending, fit(pending, mask).split(), strict=True):
                    results[m] = result
        if keep_outliers:
            flagged = np.array([m for m in range(m_count) if outliers[m]], dtype=int)
            for m in flagged:
                mask[m, outliers[m]] = True
            if len(flagged):
                for m, result in zip(flagged, fit(flagged, mask).split(), strict=True):
                    results[m] = result
        out: list[Estimate | Exception] = []
        whole = BatchFit.joined(results)
        # The information's eigenvalues, most first, of every machine in one call.
        eigenvalues = np.linalg.eigvalsh(whole.information)[:, ::-1]
        # Every machine's residuals, a left-out reading's with its mounting's zero from
        # the readings used, what the report compares with its repetitions, and the
        # readings the model does not fit, over the arrays of machines at once.
        residuals = whole.residuals
        every = residuals.copy()
        converged = whole.converged
        for m in np.flatnonzero(~mask.all(axis=1) & converged):
            every[m] = np.where(mask[m], residuals[m], held_out_residuals(
                design, values[m], results[m].theta[0], mask[m], ~mask[m],
                None if world is None else world[m]))
        repeated, _ = repetition_means(every, group)
        misfits = model_misfits(residuals, group, noise)
        # The readings the model does not fit are its own errors, not the world's sizes.
        fitting = mask.copy()
        for m, rows in enumerate(misfits):
            fitting[m, rows] = False
        thetas = whole.theta
        # Most estimates are inside the validity range: only the others are made into a
        # machine each, for their warning's words.
        valid = valid_vectors(thetas[:, :len(ERROR_NAMES)], design.machine_design)
        columns = _Columns.of(names, whole.free, whole.scale, consider.names, space.groups)
        reported = _Reported.of(whole, columns)
        judged = ([None] * m_count if auto or not world_check else _world_warnings(
            design, values, fitting, noise, thetas, free, scale, told_terms, base_of,
            conditions, reported.covariance,
            lambda terms: fit(np.arange(m_count), mask, terms, thetas).considered_gain))
        for m, result in enumerate(results):
            if not result.converged[0]:
                out.append(RuntimeError("the exact-model fit did not converge"))
            elif not (eigenvalues[m] >= RETAIN).any():
                out.append(ValueError(f"the readings identify no combination of the "
                                      f"parameters '{params}' (every one is below its "
                                      "a-priori scale)"))
            else:
                out.append(self._estimate(datas[m], params, prior, sigma, design, values[m],
                                          result, reported, m,
                                          eigenvalues[m], mask[m], held, outliers[m],
                                          causes[m], every[m], repeated[m], misfits[m],
                                          verify, explain, consider, columns,
                                          None if world is None else world[m],
                                          conditions, spacing, judged[m], shown[m],
                                          bool(valid[m]), int(ends[m].sum())))
        return out

    def _estimate(self, data: Measurements, params: str, prior: str, sigma: float,
                  design: ReadingLayout, values: np.ndarray, result: BatchFit,
                  reported: _Reported, m: int,
                  eigenvalues: np.ndarray, mask: np.ndarray, held: np.ndarray,
                  outliers: list[int], causes: list[str], every_residual: np.ndarray,
                  repeated: np.ndarray, misfits: np.ndarray, verify: bool, explain: bool,
                  considered: Consider, columns: _Columns, world: np.ndarray | None,
                  conditions: Conditions, spacing: float | None, judged: str | None,
                  world_scales: dict[str, float], valid: bool, ends: int) -> Estimate:
        """The estimate of machine ``data`` from its fit ``result``, row ``m`` of its
        group's ``reported`` figures (``columns``: the group's parameters); ``valid``:
        whether its machine is inside the validity range
        (:func:`~orthoglide_env.model.errors.valid_vectors`); ``ends``: how many of its
        readings a digital indicator took at its stroke's ends, left out
        (:func:`~calibrators.estimators.consider.indicator_end`)."""
        # Its own copies: an estimate is a caller's to change.
        every, names, s = columns.every, list(columns.names), columns.scale.copy()
        cov, error_cov = reported.covariance[m], reported.error_covariance[m]
        info = result.information[0]
        seen, unseen = directions(info) if explain else ((), ())
        theta = result.theta[0]
        warnings = [] if judged is None else [judged]
        if reported.misfit[m]:
            chi2_dof = reported.chi2_dof[m]
            widened = ("error bars carry the errors the model leaves out, at the size the "
                       "misfit shows" if reported.left_out[m] else "error bars are scaled by "
                       f"sqrt(chi2/dof) = {np.sqrt(chi2_dof):.2f}")
            warnings.append(
                f"the model does not explain the readings: chi2/dof = "
                f"{chi2_dof:.1f} (chi-square test at {CHI2_LEVEL:g}); {widened}; "
                f"{columns.hint}")
        try:
            if not valid:
                check_validity(MachineParams.from_vector(theta[:len(ERROR_NAMES)],
                                                         design.machine_design))
        except MachineFileError as exc:
            warnings.append(f"the estimate is outside the validity range, where the model "
                            f"holds: {str(exc).replace('machine key', 'estimate key')}; do "
                            f"not compensate with it ({VALIDITY_HINT})")
        if ends:
            # Said, not silent: a technician reading the fit sees why readings are missing.
            warnings.append(f"{ends} reading(s) left out: a digital indicator read them "
                            "within its stroke's last "
                            f"{conditions.size('dial', 'digital_end')[0]:g} mm, where its "
                            "datasheets give no repeatability")
        for cause in ("reading", "unrepeated"):
            mine = [k for k, c in zip(outliers, causes, strict=True) if c == cause]
            if mine:
                where = ", ".join(_where(data, k, every_residual, repeated) for k in mine)
                warnings.append(f"{len(mine)} outlier reading(s) "
                                f"{'kept' if mask[mine].all() else 'left out'} ("
                                f"{CAUSE_WORDS[cause]}): {where}")
        # Of an instrument whose readings the loop leaves out by the cap's fraction, and
        # that no repetition told from model error, the many are the model's error: an
        # honest reading flags once in 6e-5 and a wrong one is rare, so two or more are
        # not chance (the bar's under a fit without the drives' terms was it).
        unrepeated = Counter(instrument_of(data.items[k].gauge)
                             for k, c in zip(outliers, causes, strict=True)
                             if c == "unrepeated" and not mask[k])
        read = Counter(instrument_of(m.gauge) for m in data.items)
        for kind, n in unrepeated.items():
            if n >= max(2, MAX_OUTLIER_FRACTION * read[kind]):
                warnings.append(f"{n} of the {read[kind]} {kind} readings left out beyond "
                                f"{OUTLIER_K:g} robust sigmas, unrepeated: so many are the "
                                "model's error, not wrong readings: fit the terms that move "
                                "them")
        if len(misfits):
            where = ", ".join(_where(data, k, every_residual, repeated)
                              for k in misfits[:LISTED_MISFITS])
            more = (f" and {len(misfits) - LISTED_MISFITS} more"
                    if len(misfits) > LISTED_MISFITS else "")
            warnings.append(f"{len(misfits)} reading(s) the model does not fit, though their "
                            "repetitions read the same (model error, not a wrong reading; "
                            f"kept): {where}{more}; "
                            + ("try --params extended" if params in ("paper", "paper6") else
                               "look for a gauge that moved or a slipping stand"))
        residuals = result.residuals[0]
        if held.any():
            residuals = np.where(held, held_out_residuals(design, values, theta, mask, held,
                                                          world), residuals)
        return Estimate(
            strategy=self.name, params=params, drho=theta[:3], dL=theta[3:6], covariance=cov,
            residuals=residuals, singular_values=np.sqrt(np.clip(eigenvalues, 0, None)),
            crlb=np.sqrt(np.diag(result.covariance[0])), weak_directions=[],
            n_readings=int(mask.sum()), experiment_time_s=data.experiment_time_s,
            verification_rms_mm=verification_rms(design, values, result, mask, data, world)
            if verify else None,
            iterations=int(result.iterations[0]), sigma=sigma,
            # Physical units, for readings of unit variance (as the paper's fit reports it).
            fisher=info / np.outer(s, s) * weighting_sigma(sigma) ** 2,
            readings=data, names=names, space=every, theta=theta, prior=prior,
            chi2=float(result.chi2[0]), dof=int(result.dof[0]),
            covariance_scale=float(reported.covariance_scale[m]), warnings=warnings,
            identifiable=[describe(d, names) for d in seen],
            unidentifiable=[act_together(d, names) for d in sparse_basis(unseen)]
            if explain else [],
            outliers=outliers, outlier_causes=causes,
            outlier_residuals=[float(every_residual[k]) for k in outliers],
            misfits=misfits.tolist(),
            information=info, scale=s, error_covariance=error_cov,
            holdout_rms_mm=float(np.sqrt(np.mean(residuals[held] ** 2))) if held.any() else None,
            considered=considered.effects, world_scales=world_scales,
            **_lead(result, columns, considered.names, error_cov, conditions, spacing),
        )

def _world_terms(design: ReadingLayout, times: np.ndarray | None,
                 temperatures: np.ndarray | None, conditions: Conditions,
                 spacing: float | None) -> Callable[[str | Conditions, np.ndarray], Consider]:
    """The consider terms of experiments' readings (given as (M, N) values: those the
    geometry predicts, :func:`~calibrators.estimators.world_sizes.noiseless_readings`)
    read at ``times`` and ``temperatures`` (:func:`_every_reading`), under the named
    conditions, every effect acting and the told conditions' indicator (or under given
    conditions): what the told world is measured against."""
    indicator = conditions.indicator

    def of(name: str | Conditions, readings: np.ndarray) -> Consider:
        world = name if isinstance(name, Conditions) else Conditions(name, indicator=indicator)
        return consider_terms(design, readings, times, world, spacing, temperatures)

    return of


def _estimated_world(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                     noise: np.ndarray, free: np.ndarray, fixed: np.ndarray,
                     priors: np.ndarray, scale: np.ndarray, unmodelled: np.ndarray,
                     spread: np.ndarray, solver: str,
                     terms: Callable[[str, np.ndarray], Consider]) -> np.ndarray:
    """(M, F) the families' scales of the base world's terms (``terms`` of
    :data:`BASE_WORLD`) that the readings show (:mod:`calibrators.estimators.world_sizes`),
    at least :data:`FLOOR_WORLD`'s: the geometry is fitted first with every base term
    considered, then the scales are the restricted likelihood's maximum over what it
    leaves."""
    geometry = fit_batch(design, values, mask, noise, free, fixed, priors, scale,
                         unmodelled=unmodelled, solver=solver, left_out=spread)
    clean = noiseless_readings(design, values, mask, geometry.theta)
    base, floor = terms(BASE_WORLD, clean), terms(FLOOR_WORLD, clean)
    columns = world_columns(design, base)
    gram, b = restricted_statistics(design, values, mask, 1.0 / weighting_sigma(noise),
                                    geometry.theta, free, scale, columns)
    lowest = told_scales(base, floor, columns, world_columns(design, floor))
    member = family_index(base.names)
    return np.maximum(judge(gram, b, member, lowest).estimated, lowest)


def _world_warnings(design: ReadingLayout, values: np.ndarray, mask: np.ndarray,
                    noise: np.ndarray, theta: np.ndarray, free: np.ndarray,
                    scale: np.ndarray, told: Consider,
                    terms: Callable[[str | Conditions, np.ndarray], Consider],
                    conditions: Conditions,
                    covariance: np.ndarray, moved_by: Callable[[Consider], np.ndarray]
                    ) -> list[str | None]:
    """Per machine, the words of the test that its readings show a world worse than the
    ``told`` terms' (:func:`~calibrators.estimators.world_sizes.warning`), or, where it
    does not, of the told world's blind spot against the mildest named world harsher than
    it whose unseen effects would widen the error bars beyond the band
    (:func:`~calibrators.estimators.world_sizes.blind_spot`), or None.  ``covariance``
    (M, P, P): the estimates' over the free parameters; ``moved_by``: how far a
    :class:`Consider`'s terms move them (M, P, K), as the fit's gain takes them."""
    clean = noiseless_readings(design, values, mask, theta)
    base = terms(BASE_WORLD, clean)
    columns = world_columns(design, base)
    n = len(design.space.names)
    gram, b = restricted_statistics(design, values, mask, 1.0 / weighting_sigma(noise),
                                    theta[:, :n], free[:n], scale[:n], columns)
    told_columns = (world_columns(design, told) if not told.empty
                    else np.zeros((*values.shape, 0)))
    member = family_index(base.names)
    told_sizes = told_scales(base, told, columns, told_columns)
    sizes = judge(gram, b, member, told_sizes)
    words = [warning(sizes, m, conditions.label) for m in range(len(values))]
    count = len(TERM_FAMILIES)
    seen = seen_families(gram, member, count)
    idx = np.flatnonzero(free)
    machine = idx[idx < len(ERROR_NAMES)]
    rows = np.flatnonzero(idx < len(ERROR_NAMES))
    prior = default_scales(ParameterSpace())[machine]
    cov = covariance[:, rows][:, :, rows]
    mine = terms(conditions, clean)
    mine_columns = (world_columns(design, mine) if not mine.empty
                    else np.zeros((*values.shape, 0)))
    pending = ~sizes.worse
    # A world the readings cannot tell from the told one, and in which its error bars
    # would be too narrow, is a blind spot whichever world the readings came from: each
    # named world at least as harsh as the told one's name is asked, mildest first.
    for harsher in CONDITION_NAMES[CONDITION_NAMES.index(conditions.name):]:
        wider = terms(harsher, clean)
        if wider.empty:
            continue
        wider_columns = world_columns(design, wider)
        wider_sizes = told_scales(base, wider, columns, wider_columns)
        # The told world's share of the harsher one's, per family, both at the same
        # readings: below 1 is a blind spot's candidate, and the harsher world's terms at
        # the rest of their size are what it leaves out.
        share = np.minimum(told_scales(wider, mine, wider_columns, mine_columns), 1.0)
        share = np.where(wider_sizes > 0, share, 1.0)
        quiet = pending & (share < 1.0).any(axis=1)
        if not quiet.any():
            continue
        power = power_against(gram, member, told_sizes, np.maximum(wider_sizes, told_sizes),
                              seen)
        moved = moved_by(scaled(wider, np.clip(1.0 - share, 0.0, None)))
        own = family_index(wider.names)
        factors = np.ones_like(share)
        for f in np.flatnonzero(np.isin(np.arange(count), own)):
            factors[:, f] = widening(cov, moved[:, rows][:, :, own == f], prior)
        for m in np.flatnonzero(quiet):
            words[m] = blind_spot(conditions.label, harsher, TERM_FAMILIES,
                                  np.where(share[m] < 1.0, factors[m], 1.0), power[m])
        pending &= np.array([w is None for w in words])
    return words


class _Columns(NamedTuple):
    """The parameters of a group's fits, the same for each of its machines: their names,
    the free ones' names, columns and scales, and the lead error's terms, fitted
    (columns of ``every``) and considered (of the considered terms)."""

    every: list[str]
    names: list[str]
    free: np.ndarray
    scale: np.ndarray
    fitted_lead: list[int]
    other_lead: list[int]
    #: What a fit the model does not explain should try.
    hint: str

    @classmethod
    def of(cls, every: list[str], free: np.ndarray, scale: np.ndarray,
           considered: tuple[str, ...], groups: tuple[str, ...]) -> _Columns:
        """The columns of fits over the parameters ``every`` (``free``: which are free;
        ``scale``: each one's; ``groups``: the reading model's groups of its first ones)
        that consider the terms ``considered``."""
        idx = np.flatnonzero(free)
        beyond = [g not in ("drho", "dL", "tracker_rotation", "ballbar_centre") for g in groups]
        return cls(every, [n for n, f in zip(every, free, strict=True) if f], idx, scale[idx],
                   [k for k, name in enumerate(every) if name.startswith(f"{WORLD_PREFIX}lead.")],
                   [k for k, name in enumerate(considered) if name.startswith("lead.")],
                   "try --params extended" if not free[:len(beyond)][beyond].any() else
                   "look for outliers, a gauge that moved, or a slipping stand")


class _Reported(NamedTuple):
    """What a group's estimates report of their fits, over the arrays of machines at once:
    the covariances over the free parameters (:attr:`~calibrators.estimators.exact_fit.
    BatchFit.scaled_covariance`) and, with the errors the model leaves out, over every
    parameter; the chi-square test's verdict, chi2/dof and the covariance's scale; and
    whether the model's error bars carry errors it leaves out."""

    covariance: np.ndarray
    error_covariance: np.ndarray
    misfit: np.ndarray
    chi2_dof: np.ndarray
    covariance_scale: np.ndarray
    left_out: np.ndarray

    @classmethod
    def of(cls, whole: BatchFit, columns: _Columns) -> _Reported:
        """The figures of the fits ``whole`` over the parameters ``columns``."""
        covariance = whole.scaled_covariance
        error_covariance = whole.error_covariance.copy()
        error_covariance[:, columns.free[:, None], columns.free] = covariance
        left_out = np.diagonal(whole.error_covariance, axis1=1, axis2=2)[:, ~whole.free]
        return cls(covariance, error_covariance, whole.misfit, whole.chi2_dof,
                   whole.covariance_scale, left_out.any(axis=1))


def _lead(result: BatchFit, columns: _Columns, considered: tuple[str, ...],
          error_cov: np.ndarray, conditions: Conditions, spacing: float | None
          ) -> dict[str, Any]:
    """The lead error's terms of an estimate (fitted or considered), with the joint
    covariance of (estimate - truth) over the 27 machine errors and their coefficients
    (a considered term's estimate is 0; the estimate moved with it): what the tool's
    position after compensation needs."""
    n = len(ERROR_NAMES)
    every, fitted, other = columns.every, columns.fitted_lead, columns.other_lead
    if not fitted and not other:
        return {}
    rows = list(range(n)) + fitted
    size = len(rows) + len(other)
    joint = np.zeros((size, size))
    joint[:len(rows), :len(rows)] = error_cov[np.ix_(rows, rows)]
    free = np.flatnonzero(result.free)
    position = {int(k): j for j, k in enumerate(free)}
    gain = result.considered_gain[0]  # (nf, K) over every considered term
    for i, k in enumerate(rows):
        if k in position:
            joint[i, len(rows):] = -gain[position[k], other]
    joint[len(rows):, :len(rows)] = joint[:len(rows), len(rows):].T
    joint[len(rows):, len(rows):] = np.eye(len(other))
    return {"lead_terms": [every[k][len(WORLD_PREFIX):] for k in fitted]
            + [considered[k] for k in other],
            "lead_values": np.concatenate([result.theta[0][fitted], np.zeros(len(other))]),
            "lead_covariance": joint, "conditions": conditions.to_dict(),
            "node_spacing": spacing}


def _where(data: Measurements, k: int, residuals: np.ndarray | None = None,
           repeated: np.ndarray | None = None) -> str:
    m = data.items[k]
    place = f"line {m.line}" if m.line else f"reading {k + 1}"
    detail = ""
    if residuals is not None and repeated is not None:
        detail = f", residual {residuals[k]:+.4f} mm" + (
            f", its repetitions {repeated[k]:+.4f} mm" if np.isfinite(repeated[k]) else "")
    return f"{place} ({m.gauge.slot}, {m.posture}, repetition {m.repetition}{detail})"


#: The earlier name of :func:`layout_and_values`, kept for scripts that import it.
design_of = layout_and_values

__all__ = ["GaussNewtonCalibrator", "ParameterSpace", "design_of", "layout_and_values"]
