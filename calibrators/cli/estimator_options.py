"""The estimator's options, shared by ``calibrate`` and ``fit``."""

from __future__ import annotations

import argparse
from typing import Any

from calibrators.cli.common import UsageError
from calibrators.estimators.base import Estimate, get_strategy
from calibrators.estimators.consider import (
    DEFAULT_NODE_SPACING,
    FULL_TERMS,
    TERM_FAMILIES,
    check_families,
)
from calibrators.estimators.exact_fit import SOLVERS
from calibrators.estimators.gauss_newton import MAX_OUTLIER_FRACTION, OUTLIER_K
from calibrators.estimators.paper_linear import NeedsExactFit
from calibrators.estimators.parameters import parse_assignments
from calibrators.measurements import Measurements
from orthoglide_env.model.errors import DEFAULT_PRESET, PRESETS
from orthoglide_env.world.conditions import IDEAL, Conditions

DEFAULT_STRATEGY = "gauss-newton"
#: The parameters each strategy fits when ``--params`` is not given: the exact-model fit
#: frees every error and, under a real lab's conditions, its terms (``full``), because a
#: fit of fewer parameters than the machine has can hand a user a wrong number with small
#: error bars; the paper's linear fit knows only its six.
DEFAULT_PARAMS: dict[str, str] = {"gauss-newton": "full", "paper": "paper6"}


def add(p: argparse.ArgumentParser) -> None:
    p.add_argument("--strategy", default=DEFAULT_STRATEGY,
                   help="estimator: gauss-newton (exact model, any parameters) or paper "
                        "(eq. 10, linear, paper6/drho/dL only) (default: %(default)s)")
    p.add_argument("--params", default=None,
                   help="free parameters: paper6 (drho, dL), extended (all 27 machine errors "
                        "and 4 per gauge stand), full (extended, and under --conditions lab "
                        "or workshop the lab's terms of --terms, the lead error as a "
                        "pitch-error table), or a comma list of groups (drho, dL, "
                        "axis_tilt, axis_offset, attach, stands) and names (drho_x, "
                        "attach_y.z, x-leg/y@0.5.tilt_z) (default: "
                        + ", ".join(f"{v} for {k}" for k, v in DEFAULT_PARAMS.items()) + ")")
    p.add_argument("--prior", default="auto",
                   help="zero-mean normal prior: none (base parameters: combinations the "
                        "readings cannot see stay nominal), a preset name (its sigmas), and/or "
                        "GROUP=SIGMA or NAME=SIGMA (mm, rad); auto = the realistic preset's "
                        "when more than paper6 is free, else none (default: %(default)s)")
    p.add_argument("--left-out", choices=sorted(PRESETS), default=None,
                   help="the error preset whose sizes the errors --params leaves out have a "
                        "priori: their spread goes into the error bars (paper or nominal: "
                        "they do not exist) (default: the preset a random machine is drawn "
                        f"from, --errors; else {DEFAULT_PRESET}: a real machine's, or a "
                        "machine file's, is not known)")
    p.add_argument("--fit-world", action="store_true",
                   help="under --conditions lab or workshop, fit every one of the lab's "
                        "terms (their sizes as priors) instead of only carrying them in the "
                        "error bars")
    p.add_argument("--terms", default=None, metavar="LIST",
                   help=f"the lab's terms to fit, a comma list of {', '.join(TERM_FAMILIES)} "
                        f"(the others are carried in the error bars) (default with --params "
                        f"full: {','.join(FULL_TERMS)})")
    p.add_argument("--node-spacing", type=float, default=None, metavar="MM",
                   help=f"fit the lead error as a controller's pitch-error table with nodes "
                        f"this far apart, with a smoothness prior (default with --params "
                        f"full: {DEFAULT_NODE_SPACING:g})")
    p.add_argument("--save-estimate", metavar="FILE.json",
                   help="write the estimate file: a machine file of the estimated machine "
                        "(pose --machine reads it) with the fit under 'calibration', which "
                        "orthoglide compensate reads")
    p.add_argument("--save-pitch-table", metavar="FILE.csv",
                   help="write the fitted lead error as per-axis pitch-error tables for the "
                        "controller: axis, position_mm, error_mm (where the carriage is minus "
                        "where its encoder says; the controller commands rho - error), "
                        "sigma_mm")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a known value (mm, rad); repeatable")
    p.add_argument("--solver", choices=list(SOLVERS), default="gauss-newton",
                   help="batched damped Gauss-Newton, or scipy's least_squares as a cross-check "
                        "(default: %(default)s)")
    p.add_argument("--keep-outliers", action="store_true",
                   # argparse %-formats help text: a percent sign is written twice.
                   help=f"flag readings beyond {OUTLIER_K:g} robust sigma but keep them in the "
                        f"fit (default: leave them out, at most "
                        f"{100 * MAX_OUTLIER_FRACTION:g}%% of the readings)")
    p.add_argument("--holdout", type=float, default=0.0, metavar="FRACTION",
                   help="fit on the other readings and report the prediction residual of this "
                        "random fraction (default: none)")


def params_of(args: argparse.Namespace) -> str:
    """``--params``, or its strategy's default (:data:`DEFAULT_PARAMS`)."""
    return args.params if args.params is not None else DEFAULT_PARAMS.get(args.strategy,
                                                                          "full")


def options(args: argparse.Namespace) -> dict[str, Any]:
    """Keyword arguments of ``Calibrator.estimate`` from the parsed options."""
    return {"prior": args.prior, "fix": parse_assignments(args.fix, "--fix"),
            "keep_outliers": args.keep_outliers, "holdout": args.holdout,
            "seed": args.seed, "solver": args.solver, "left_out": left_out(args),
            "node_spacing": args.node_spacing, **_fitted(args)}


def left_out(args: argparse.Namespace) -> str:
    """``--left-out``, or the preset the machine was drawn from when it was (``calibrate``'s
    random machine: its ``--errors``), else :data:`DEFAULT_PRESET`, as ``compare`` does."""
    if args.left_out is not None:
        return args.left_out
    drawn = getattr(args, "errors", None) if not getattr(args, "machine", None) else None
    return drawn or DEFAULT_PRESET


def _fitted(args: argparse.Namespace) -> dict[str, Any]:
    """``fit_world`` from ``--fit-world`` or ``--terms`` (one line on an unknown term)."""
    if args.fit_world and args.terms is not None:
        raise UsageError("--fit-world fits every term; give it or --terms, not both")
    if args.terms is not None:
        try:
            return {"fit_world": check_families([t.strip() for t in args.terms.split(",")
                                                 if t.strip()])}
        except ValueError as exc:
            raise UsageError(f"--terms: {exc}") from None
    return {"fit_world": True} if args.fit_world else {}


def estimate(args: argparse.Namespace, data: Measurements, sigma: float,
             conditions: Conditions = IDEAL) -> Estimate:
    """The estimate of ``--strategy`` with the parsed options, for readings taken under
    ``conditions`` (whose effects an exact-model fit puts into its error bars); what only
    the exact-model fit can do is refused with the option that asks for it."""
    try:
        return get_strategy(args.strategy).estimate(data, params_of(args), sigma,
                                                    conditions=conditions, **options(args))
    except NeedsExactFit as exc:
        raise UsageError(f"{exc}: use --strategy {DEFAULT_STRATEGY}") from None
