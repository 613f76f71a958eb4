"""``orthoglide fit``: calibrate a real machine from measured gauge readings."""

from __future__ import annotations

import argparse

import numpy as np

from orthoglide_env.gauges import DEFAULT_RESOLUTION, DEFAULT_SIGMA

from ..base import PARAM_SETS, get_strategy
from ..measurements import Measurements
from .output import emit, report


def run(args: argparse.Namespace) -> None:
    data = Measurements.read(args.file)
    sigma = np.hypot(DEFAULT_SIGMA if args.sigma is None else args.sigma,
                     DEFAULT_RESOLUTION / np.sqrt(12))
    est = get_strategy(args.strategy).estimate(data, args.params, float(sigma))
    emit(report(est, None), args.json)



def add(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="calibrate a real machine from measured gauge readings")
    p.add_argument("file", help="readings, .csv or .json (README: the measurement file)")
    p.add_argument("--strategy", default="gauss-newton")
    p.add_argument("--params", choices=list(PARAM_SETS), default="full")
    p.add_argument("--sigma", type=float, default=None,
                   help=f"gauge repeatability (mm, default {DEFAULT_SIGMA})")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)
