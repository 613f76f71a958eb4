"""The estimator's options, shared by ``calibrate`` and ``fit``: one table over the
catalogue (:mod:`calibrators.estimators.catalogue`).

``--estimator NAME`` takes the names of ``compare --estimators``; every other option
changes one parameter of that estimator, and only when it is given, so that a named
estimator keeps its own configuration otherwise.  ``--strategy`` is the earlier word for
it: ``gauss-newton`` is ``--estimator full``, ``paper`` is ``--estimator paper``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Any

from calibrators.cli.common import UsageError
from calibrators.estimators.base import Estimate, Estimator
from calibrators.estimators.catalogue import (
    CATALOGUE,
    DEFAULT_ESTIMATOR,
    exact_estimators,
    for_readings,
    get_estimator,
)
from calibrators.estimators.consider import (
    DEFAULT_NODE_SPACING,
    FULL_TERMS,
    TERM_FAMILIES,
    check_families,
)
from calibrators.estimators.constraints import InvalidParameterError
from calibrators.estimators.outliers import MAX_OUTLIER_FRACTION, OUTLIER_K
from calibrators.estimators.paper_linear import NeedsExactFit
from calibrators.estimators.parameters import parse_assignments
from calibrators.estimators.solvers import SOLVERS
from calibrators.measurements import Measurements
from orthoglide_env.model.errors import DEFAULT_PRESET, PRESETS
from orthoglide_env.world.conditions import IDEAL, Conditions

#: ``--strategy``'s names (the estimator classes' names) and the catalogue's estimators
#: they stand for.
STRATEGIES: dict[str, str] = {"gauss-newton": "full", "paper": "paper"}


@dataclass(frozen=True)
class Option:
    """A command-line option that sets the estimator's parameter ``parameter``."""

    flag: str
    parameter: str
    kwargs: dict[str, Any] = field(default_factory=dict)


#: The options that set one parameter each, in the order a refusal names them.
OPTIONS: tuple[Option, ...] = (
    Option("--params", "params", {
        "help": "free parameters, instead of the estimator's: paper6 (drho, dL), extended "
                "(all 27 machine errors and 4 per gauge stand), full (extended, and under "
                "--conditions lab or workshop the lab's terms of --terms, the lead error as a "
                "pitch-error table), or a comma list of groups (drho, dL, axis_tilt, "
                "axis_offset, attach, stands) and names (drho_x, attach_y.z, "
                "x-leg/y@0.5.tilt_z); the paper estimator takes paper6, drho or dL"}),
    Option("--prior", "prior", {
        "help": "zero-mean normal prior: none (base parameters: combinations the readings "
                "cannot see stay nominal), a preset name (its sigmas), and/or GROUP=SIGMA or "
                "NAME=SIGMA (mm, rad); auto = the realistic preset's when more than paper6 is "
                "free, else none (default: the estimator's: auto, none for paper6 and "
                "extended-base)"}),
    Option("--fix", "fix", {
        "action": "append", "metavar": "NAME=VALUE",
        "help": "hold a parameter at a known value (mm, rad); repeatable"}),
    Option("--holdout", "holdout", {
        "type": float, "metavar": "FRACTION",
        "help": "fit on the other readings and report the prediction residual of this "
                "random fraction (default: none)"}),
    Option("--keep-outliers", "keep_outliers", {
        "action": "store_true",
        # argparse %-formats help text: a percent sign is written twice.
        "help": f"flag readings beyond {OUTLIER_K:g} robust sigma but keep them in the fit "
                f"(default: leave them out, at most {100 * MAX_OUTLIER_FRACTION:g}%% of the "
                "readings)"}),
    Option("--solver", "solver", {
        "choices": list(SOLVERS),
        "help": "batched damped Gauss-Newton, or scipy's least_squares as a cross-check "
                "(default: gauss-newton)"}),
    Option("--fit-world", "fit_world", {
        "action": "store_true",
        "help": "under --conditions lab or workshop, fit every one of the lab's terms (their "
                "sizes as priors) instead of only carrying them in the error bars"}),
    Option("--terms", "fit_world", {
        "metavar": "LIST",
        "help": f"the lab's terms to fit, a comma list of {', '.join(TERM_FAMILIES)} (the "
                f"others are carried in the error bars) (default with --params full: "
                f"{','.join(FULL_TERMS)})"}),
    Option("--node-spacing", "node_spacing", {
        "type": float, "metavar": "MM",
        "help": f"fit the lead error as a controller's pitch-error table with nodes this far "
                f"apart, its prior the lead curve the lab draws (default with --params full: "
                f"{DEFAULT_NODE_SPACING:g})"}),
    Option("--check-world", "world_check", {
        "action": "store_const", "const": True,
        "help": "test whether the readings show a world worse than the conditions the fit "
                "is told, and warn (warning 'world') with the effects that show it, or "
                "with those of the default lab it leaves out and cannot see (see "
                "docs/world.md)"}),
    Option("--left-out", "left_out", {
        "choices": sorted(PRESETS),
        "help": "the error preset whose sizes the errors --params leaves out have a priori: "
                "their spread goes into the error bars (paper or nominal: they do not "
                "exist) (default: the preset a random machine is drawn from, --errors; else "
                f"{DEFAULT_PRESET}: a real machine's, or a machine file's, is not known)"}),
)


def add(p: argparse.ArgumentParser) -> None:
    """The estimator's options, and where its estimate is written."""
    p.add_argument("--estimator", default=None, metavar="NAME",
                   help=f"the estimator, by the names of compare --estimators: "
                        f"{', '.join(CATALOGUE)} (default: {DEFAULT_ESTIMATOR})")
    p.add_argument("--strategy", default=None,
                   help="the earlier word for --estimator, kept as an alias: gauss-newton "
                        "is --estimator full (give --params for another parameter set), "
                        "paper is --estimator paper")
    for option in OPTIONS:
        p.add_argument(option.flag, default=None, **option.kwargs)
    p.add_argument("--save-estimate", metavar="FILE.json",
                   help="write the estimate file: a machine file of the estimated machine "
                        "(pose --machine reads it) with the fit under 'calibration', which "
                        "orthoglide compensate reads")
    p.add_argument("--save-pitch-table", metavar="FILE.csv",
                   help="write the fitted lead error as per-axis pitch-error tables for the "
                        "controller: axis, position_mm, error_mm (where the carriage is minus "
                        "where its encoder says; the controller commands rho - error), "
                        "sigma_mm")


def name_of(args: argparse.Namespace) -> str:
    """The catalogue's name of the estimator ``--estimator`` or ``--strategy`` asks for."""
    if args.estimator is not None and args.strategy is not None:
        raise UsageError("--strategy is the earlier word for --estimator: give one")
    if args.strategy is not None:
        if args.strategy not in STRATEGIES:
            raise UsageError(f"unknown strategy '{args.strategy}'; choose from "
                             f"{list(STRATEGIES)} (or --estimator {'|'.join(CATALOGUE)})")
        return STRATEGIES[args.strategy]
    return DEFAULT_ESTIMATOR if args.estimator is None else args.estimator


def config(args: argparse.Namespace) -> dict[str, Any]:
    """The parameters the given options set (an option not given sets none)."""
    if args.fit_world and args.terms is not None:
        raise UsageError("--fit-world fits every term; give it or --terms, not both")
    out: dict[str, Any] = {}
    for option in OPTIONS:
        value = getattr(args, option.flag[2:].replace("-", "_"))
        if value is None:
            continue
        if option.flag == "--fix":
            value = parse_assignments(value, "--fix")
        elif option.flag == "--terms":
            try:
                value = check_families([t.strip() for t in value.split(",") if t.strip()])
            except ValueError as exc:
                raise UsageError(f"--terms: {exc}") from None
        out[option.parameter] = value
    return out


def estimator(args: argparse.Namespace, sigma: float | None = None,
              conditions: Conditions = IDEAL) -> Estimator:
    """The estimator the options ask for, for readings of noise ``sigma`` (mm; None: its
    own) taken under ``conditions`` (whose effects an exact-model fit puts into its error
    bars); what only the exact-model fit can do is refused with the option that asks for
    it, a bad value with the option that gave it."""
    name = name_of(args)
    try:
        chosen = get_estimator(name)
        given = config(args)
        # The machine's preset and the run's seed (which draws the hold-out) are facts
        # of the run; an estimator that has no use for them is not refused for them.
        context = {"left_out": left_out(args), "seed": args.seed}
        given.update({key: value for key, value in context.items()
                      if chosen.takes(key) and key not in given})
        chosen = chosen.clone(**given)
        return chosen if sigma is None else for_readings(chosen, sigma, conditions)
    except NeedsExactFit as exc:
        raise use_exact(exc) from None
    except InvalidParameterError as exc:
        flags = [o.flag for o in OPTIONS if o.parameter == exc.parameter]
        raise UsageError(f"{flags[0] if flags else '--estimator'}: {exc}") from None
    except UsageError:
        raise
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def use_exact(exc: NeedsExactFit) -> UsageError:
    """What the paper's fit refuses, with the estimators that can."""
    exact = exact_estimators()
    return UsageError(f"{exc}: use an exact-model estimator, --estimator {' or '.join(exact)}")


def left_out(args: argparse.Namespace) -> str:
    """``--left-out``, or the preset the machine was drawn from when it was (``calibrate``'s
    random machine: its ``--errors``), else :data:`DEFAULT_PRESET`, as ``compare`` does."""
    if args.left_out is not None:
        return args.left_out
    drawn = getattr(args, "errors", None) if not getattr(args, "machine", None) else None
    return drawn or DEFAULT_PRESET


def estimate(args: argparse.Namespace, data: Measurements, sigma: float,
             conditions: Conditions = IDEAL) -> Estimate:
    """The estimate of the estimator the options ask for (:func:`estimator`) from
    ``data``; the fit's own refusals (a tracker's readings for the paper's fit) name the
    option that chooses an estimator that can."""
    try:
        return estimator(args, sigma, conditions).fit(data)
    except NeedsExactFit as exc:
        raise use_exact(exc) from None
