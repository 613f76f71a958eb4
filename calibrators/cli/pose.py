"""``orthoglide pose``: simulate one posture of a machine and read its gauges."""

from __future__ import annotations

import argparse

import numpy as np

from calibrators.cli.common import (
    add_conditions,
    add_machine_posture,
    conditions_of,
    print_json,
    rho_of,
    truth_of,
    vec,
)
from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    MAX_NOISE_FRACTION,
    MIN_RESOLUTION,
)
from orthoglide_env.instruments.gauges import DEFAULT_TRAVEL

#: Largest sigma and resolution of the default gauges, as check_noise has it (mm).
NOISE_LIMIT = (f"travel/{1 / MAX_NOISE_FRACTION:g} = "
               f"{DEFAULT_TRAVEL * MAX_NOISE_FRACTION:g}")
SIGMA_HELP = (f"gauge repeatability, standard deviation of a reading (mm, 0 to {NOISE_LIMIT};"
              f" default {DEFAULT_SIGMA})")


def run(args: argparse.Namespace) -> None:
    machine, world = truth_of(args)
    rho = rho_of(args.rho, machine.design)
    # The simulator loads after validation.
    from orthoglide_env.sim.report import pose_in_world, pose_report

    sigma = DEFAULT_SIGMA if args.sigma is None else args.sigma
    conditions = conditions_of(args, world)
    if conditions.active:
        noise = (0.0, 0.0) if args.noise_free else (sigma, args.resolution)
        report = pose_in_world(machine, rho, conditions, seed=args.seed, sigma=noise[0],
                               resolution=noise[1], world=world)
    else:
        report = pose_report(machine, rho, noise_free=args.noise_free, seed=args.seed,
                             sigma=sigma, resolution=args.resolution)
    if args.json:
        print_json(report)
        return
    print(f"TCP simulated   {vec(report['tcp'], 6)} mm")
    print(f"TCP exact model {vec(report['tcp_model'], 6)} mm")
    gap = 1e3 * np.linalg.norm(np.subtract(report["tcp"], report["tcp_model"]))
    print(f"difference      {gap:.2e} µm; loop residual {1e3 * report['loop_residual_mm']:.2e} µm")
    for g in report["gauges"]:
        value = f"{g['reading']:+8.3f} mm" if g["valid"] else f"{'-':>8}    "
        print(f"  gauge {g['leg']}-leg/{g['axis']}: {value}  ({g['status']})")


def add(p: argparse.ArgumentParser) -> None:
    add_machine_posture(p)
    p.add_argument("--noise-free", action="store_true", help="ideal gauges (no noise, no "
                   "quantisation; overrides --sigma and --resolution)")
    p.add_argument("--sigma", type=float, default=None, help=SIGMA_HELP)
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION,
                   help="gauge display resolution, the step readings are rounded to (mm, 0 "
                   f"for none, or {MIN_RESOLUTION:g} to {NOISE_LIMIT}; default %(default)s)")
    p.add_argument("--seed", type=int, default=None, help="seed of the gauge noise "
                   "(default: %(default)s, fresh noise on every run)")
    add_conditions(p, replays=True)
    p.add_argument("--json", action="store_true", help="print one JSON object (mm, rad) "
                   "instead of a table")
    p.set_defaults(func=run)
