"""``orthoglide compare``: Monte-Carlo comparison of strategies."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from orthoglide_env.geometry import PRESETS

from ..base import PARAM_SETS, get_strategy
from .common import UsageError, add_noise_options, noise_of


def run(args: argparse.Namespace) -> None:
    from ..compare import Config, run, summary, write_outputs

    names = tuple(s.strip() for s in args.strategies.split(",") if s.strip())
    for name in names:
        get_strategy(name)  # fail before any work on a bad name
    if args.machines < 1:
        raise UsageError("--machines must be at least 1")
    sigma, resolution = noise_of(args)
    config = Config(names, args.errors, sigma, resolution, args.backend, args.params, args.seed)
    start = time.perf_counter()
    trials = run(config, args.machines, args.jobs, progress=not args.quiet)
    wall = time.perf_counter() - start
    rows = summary(trials)
    paths = write_outputs(trials, rows, Path(args.out)) if args.out else []
    header = (f"{'strategy':14}{'param err med':>14}{'p95':>8}{'TCP before (rigid) med':>23}"
              f"{'TCP after (rigid) med':>22}{'p95':>8}{'(raw) med':>10}{'resid':>8}"
              f"{'time s':>8}{'RMS/CRLB':>15}")
    print(f"{args.machines} machines ({args.errors} errors, sigma {sigma} mm, "
          f"{args.backend} backend), {wall:.1f} s; errors in mm, TCP errors RMS over the "
          "workspace after the best-fit rigid motion (raw: world frame)")
    print(header)
    for r in rows:
        print(f"{r['strategy']:14}{r['param_err_median_mm']:14.4f}{r['param_err_p95_mm']:8.4f}"
              f"{r['tcp_before_rigid_rms_median_mm']:23.4f}"
              f"{r['tcp_after_rigid_rms_median_mm']:22.4f}{r['tcp_after_rigid_rms_p95_mm']:8.4f}"
              f"{r['tcp_after_raw_rms_median_mm']:10.4f}{r['residual_rms_median_mm']:8.4f}"
              f"{r['experiment_time_median_s']:8.0f}"
              f"{r['rms_over_crlb_best']:7.2f}-{r['rms_over_crlb_worst']:<7.2f}")
    for r in rows:
        if r["failed"]:
            print(f"{r['strategy']}: {r['failed']} of {r['machines']} calibrations failed")
    for path in paths:
        print(f"wrote {path}")


def add(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="Monte-Carlo comparison of strategies")
    p.add_argument("--strategies", default="paper,gauss-newton")
    p.add_argument("--machines", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=None, help="processes (default: every core)")
    p.add_argument("--out", default=None, help="folder for CSV files and PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--params", choices=list(PARAM_SETS), default="paper6")
    p.add_argument("--errors", choices=sorted(PRESETS), default="realistic",
                   help="error preset of random machines")
    p.add_argument("--backend", choices=["pybullet", "exact"], default="pybullet")
    add_noise_options(p)
    p.set_defaults(func=run)
