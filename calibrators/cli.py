"""The ``orthoglide`` command: pose, render, calibrate, fit, compare.

It lives with the calibrators because it runs them; the machine and env package never
import calibrators.  Every failure a user can cause ends in one line on stderr and exit
status 2, without a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import NoReturn

import gymnasium as gym
import numpy as np

import orthoglide_env
from orthoglide_env.gauges import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.geometry import PRESETS, MachineParams, check_rho, random_machine
from orthoglide_env.scoring import score

from .base import PARAM_SETS, Estimate, Measurements, get_strategy
from .prediction import predicted_correction, predicted_tcp_std


class UsageError(Exception):
    """Bad input from the user: reported in one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """Reports a bad command line in one line (argparse adds a usage block; ``-h`` has it)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def _machine(args: argparse.Namespace) -> MachineParams:
    if getattr(args, "machine", None):
        return MachineParams.from_json(args.machine)
    return random_machine(args.seed, args.errors)


def _vec(values: list[float], digits: int) -> str:
    return "(" + ", ".join(f"{v:.{digits}f}" for v in values) + ")"


def _rho(values: list[float]) -> np.ndarray:
    return check_rho(np.array(values, dtype=float))


# -- pose / render --------------------------------------------------------------------------
def cmd_pose(args: argparse.Namespace) -> None:
    machine, rho = MachineParams.from_json(args.machine), _rho(args.rho)
    from orthoglide_env.report import pose_report  # loads the simulator: after validation

    report = pose_report(machine, rho, noise_free=args.noise_free, seed=args.seed,
                         sigma=DEFAULT_SIGMA if args.sigma is None else args.sigma,
                         resolution=args.resolution)
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"TCP simulated   {_vec(report['tcp'], 6)} mm")
    print(f"TCP exact model {_vec(report['tcp_model'], 6)} mm")
    gap = 1e3 * np.linalg.norm(np.subtract(report["tcp"], report["tcp_model"]))
    print(f"difference      {gap:.2e} µm; loop residual {1e3 * report['loop_residual_mm']:.2e} µm")
    for g in report["gauges"]:
        value = f"{g['reading']:+8.3f} mm" if g["valid"] else f"{'-':>8}    "
        print(f"  gauge {g['leg']}-leg/{g['axis']}: {value}  ({g['status']})")


def cmd_render(args: argparse.Namespace) -> None:
    machine, rho = MachineParams.from_json(args.machine), _rho(args.rho)
    from orthoglide_env.report import render_png

    path = render_png(machine, rho, args.out)
    print(f"wrote {path}")


# -- calibrate / fit -----------------------------------------------------------------------
def _noise(args: argparse.Namespace) -> tuple[float, float]:
    if args.noise_free:
        return 0.0, 0.0
    return (DEFAULT_SIGMA if args.sigma is None else args.sigma), DEFAULT_RESOLUTION


def _report(est: Estimate, truth: MachineParams | None) -> dict:
    data = {
        "strategy": est.strategy,
        "params": est.params,
        "estimate": {"drho": est.drho.tolist(), "dL": est.dL.tolist()},
        "std": est.std,
        "residual_rms_mm": est.residual_rms_mm,
        "verification_rms_mm": est.verification_rms_mm,
        "experiment_time_s": est.experiment_time_s,
        "n_readings": est.n_readings,
        "singular_values": est.singular_values.tolist(),
        "condition_number": est.condition_number,
        "crlb": est.crlb.tolist(),
        "weak_directions": est.weak_directions,
        "iterations": est.iterations,
        "predicted_correction_mm": vars(predicted_correction(est)),
        "predicted_tcp_std_after_mm": vars(predicted_tcp_std(est)),
    }
    if truth is not None:
        report = score(MachineParams(drho=est.drho, dL=est.dL), truth)
        data["truth"] = {"drho": truth.drho.tolist(), "dL": truth.dL.tolist()}
        data["tcp_error_before_mm"] = vars(report.tcp_before)
        data["tcp_error_after_mm"] = vars(report.tcp_after)
    return data


def _print_table(data: dict) -> None:
    print(f"strategy {data['strategy']}, parameters {data['params']}")
    print(f"{'':8}{'estimate':>10}{'std':>9}" + (f"{'truth':>10}{'error':>10}" if "truth" in data
                                                   else ""))
    for group in ("drho", "dL"):
        for k, axis in enumerate("xyz"):
            est = data["estimate"][group][k]
            std = data["std"][group][k]
            shown = f"{std:9.4f}" if std is not None else "    fixed"
            line = f"{group}_{axis:<4}{est:10.4f}{shown}"
            if "truth" in data:
                true = data["truth"][group][k]
                line += f"{true:10.4f}{est - true:10.4f}"
            print(line)
    print(f"residual RMS {data['residual_rms_mm']:.4f} mm over {data['n_readings']} readings"
          + (f"; held-out repetitions {data['verification_rms_mm']:.4f} mm"
             if data["verification_rms_mm"] is not None else ""))
    print("singular values " + ", ".join(f"{s:.4g}" for s in data["singular_values"])
          + f" (condition {data['condition_number']:.1f})")
    print("Cramér-Rao bound (mm) " + ", ".join(f"{c:.4f}" for c in data["crlb"]))
    for weak in data["weak_directions"]:
        print("weakly identified: " + " ".join(f"{v:+.2f} {k}" for k, v in weak.items()))
    print(f"experiment time {data['experiment_time_s']:.0f} s")
    c, u = data["predicted_correction_mm"], data["predicted_tcp_std_after_mm"]
    print(f"predicted over the workspace: correction RMS {c['rms']:.4f} / max {c['max']:.4f} mm,"
          f" TCP std after RMS {u['rms']:.4f} / max {u['max']:.4f} mm")
    if "tcp_error_before_mm" in data:
        b, a = data["tcp_error_before_mm"], data["tcp_error_after_mm"]
        print(f"TCP error over the workspace: before RMS {b['rms']:.4f} / max {b['max']:.4f} mm,"
              f" after RMS {a['rms']:.4f} / max {a['max']:.4f} mm")


def cmd_calibrate(args: argparse.Namespace) -> None:
    strategy = get_strategy(args.strategy)
    sigma, resolution = _noise(args)
    machine = _machine(args)
    env = gym.make(orthoglide_env.ENV_ID, errors=args.errors, gauge_sigma=sigma,
                   gauge_resolution=resolution, backend=args.backend)
    try:
        env.reset(seed=args.seed, options={"machine": machine.to_dict()})
        est = strategy.run(env, args.params)  # sigma: the gauges' spec (0 when ideal)
        truth = env.unwrapped.true_machine
    finally:
        env.close()
    _emit(_report(est, truth), args.json)


def cmd_fit(args: argparse.Namespace) -> None:
    data = Measurements.from_csv(args.file)
    sigma = np.hypot(DEFAULT_SIGMA if args.sigma is None else args.sigma,
                     DEFAULT_RESOLUTION / np.sqrt(12))
    est = get_strategy(args.strategy).estimate(data, args.params, float(sigma))
    _emit(_report(est, None), args.json)


def _emit(data: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(data, indent=2))
    else:
        _print_table(data)


# -- compare ------------------------------------------------------------------------------
def cmd_compare(args: argparse.Namespace) -> None:
    from .compare import Config, run, summary, write_outputs

    names = tuple(s.strip() for s in args.strategies.split(",") if s.strip())
    for name in names:
        get_strategy(name)  # fail before any work on a bad name
    if args.machines < 1:
        raise UsageError("--machines must be at least 1")
    sigma, resolution = _noise(args)
    config = Config(names, args.errors, sigma, resolution, args.backend, args.params, args.seed)
    start = time.perf_counter()
    trials = run(config, args.machines, args.jobs, progress=not args.quiet)
    wall = time.perf_counter() - start
    rows = summary(trials)
    paths = write_outputs(trials, rows, Path(args.out)) if args.out else []
    header = (f"{'strategy':14}{'param err med':>14}{'p95':>8}{'TCP before':>11}{'TCP after':>10}"
              f"{'p95':>8}{'resid':>8}{'time s':>8}{'RMS/CRLB':>15}")
    print(f"{args.machines} machines ({args.errors} errors, sigma {sigma} mm, "
          f"{args.backend} backend), {wall:.1f} s; errors in mm, TCP errors RMS over the workspace")
    print(header)
    for r in rows:
        print(f"{r['strategy']:14}{r['param_err_median_mm']:14.4f}{r['param_err_p95_mm']:8.4f}"
              f"{r['tcp_before_rms_median_mm']:11.4f}{r['tcp_after_rms_median_mm']:10.4f}"
              f"{r['tcp_after_rms_p95_mm']:8.4f}{r['residual_rms_median_mm']:8.4f}"
              f"{r['experiment_time_median_s']:8.0f}"
              f"{r['rms_over_crlb_best']:7.2f}-{r['rms_over_crlb_worst']:<7.2f}")
    for r in rows:
        if r["failed"]:
            print(f"{r['strategy']}: {r['failed']} of {r['machines']} calibrations failed")
    for path in paths:
        print(f"wrote {path}")


# -- parser -------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="orthoglide", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    presets = sorted(PRESETS)

    def machine_posture(p: argparse.ArgumentParser) -> None:
        p.add_argument("--machine", required=True, help="machine JSON file")
        p.add_argument("--rho", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                       help="joint targets, control coordinates (mm)")

    p = sub.add_parser("pose", help="simulate one posture of a machine and read its gauges")
    machine_posture(p)
    p.add_argument("--noise-free", action="store_true", help="ideal gauges (no noise, no "
                   "quantisation)")
    p.add_argument("--sigma", type=float, default=None,
                   help=f"gauge repeatability (mm, default {DEFAULT_SIGMA})")
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION,
                   help=f"gauge display resolution (mm, default {DEFAULT_RESOLUTION})")
    p.add_argument("--seed", type=int, default=None, help="seed of the gauge noise")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_pose)

    p = sub.add_parser("render", help="write a PNG picture of a machine at a posture")
    machine_posture(p)
    p.add_argument("--out", required=True, help="PNG file to write")
    p.set_defaults(func=cmd_render)

    def noise(p: argparse.ArgumentParser) -> None:
        group = p.add_mutually_exclusive_group()
        group.add_argument("--noise-free", action="store_true", help="ideal gauges")
        group.add_argument("--sigma", type=float, default=None,
                           help=f"gauge repeatability (mm, default {DEFAULT_SIGMA})")

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--params", choices=list(PARAM_SETS), default="full")
        p.add_argument("--errors", choices=presets, default="realistic",
                       help="error preset of random machines")
        p.add_argument("--backend", choices=["pybullet", "exact"], default="pybullet")
        noise(p)

    p = sub.add_parser("calibrate", help="calibrate a virtual machine with one strategy")
    p.add_argument("--strategy", default="paper")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--machine", help="machine JSON file (default: a random machine)")
    group.add_argument("--seed", type=int, default=0, help="seed of the random machine")
    common(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_calibrate, seed=0)

    p = sub.add_parser("fit", help="calibrate a real machine from measured gauge readings")
    p.add_argument("file", help="CSV: leg,axis,posture,repetition,reading_mm")
    p.add_argument("--strategy", default="gauss-newton")
    p.add_argument("--params", choices=list(PARAM_SETS), default="full")
    p.add_argument("--sigma", type=float, default=None,
                   help=f"gauge repeatability (mm, default {DEFAULT_SIGMA})")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("compare", help="Monte-Carlo comparison of strategies")
    p.add_argument("--strategies", default="paper,gauss-newton")
    p.add_argument("--machines", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=None, help="processes (default: every core)")
    p.add_argument("--out", default=None, help="folder for CSV files and PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    common(p)
    p.set_defaults(func=cmd_compare)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        for option in ("sigma", "resolution"):
            value = getattr(args, option, None)
            if value is not None and not (np.isfinite(value) and value >= 0):
                raise UsageError(f"--{option} must be a finite number >= 0")
        args.func(args)
    except (UsageError, ValueError, OSError, RuntimeError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"orthoglide {args.command}: error: {message}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
