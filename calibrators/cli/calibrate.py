"""``orthoglide calibrate``: calibrate a virtual machine with one strategy."""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import orthoglide_env
from orthoglide_env.gauges import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.geometry import DEFAULT_PRESET, PRESETS, MachineParams, random_machine
from orthoglide_env.reading_model import parameters_of

from ..base import Estimate, Measurements, get_strategy
from ..estimator import z_scores
from ..gauss_newton import design_of
from . import estimator_options
from .output import emit, report


def _setup(args: argparse.Namespace) -> tuple[MachineParams, str, float, float]:
    """The true machine, the preset of gauge installation errors, and the gauge noise.

    A machine file defines every true error: its gauges are installed perfectly and read
    without noise unless ``--errors`` or ``--sigma`` ask for them.  A random machine is
    drawn from ``--errors`` (default realistic) with its gauge errors and noise."""
    if args.machine:
        machine = MachineParams.from_json(args.machine)
        preset = args.errors or "nominal"
        noisy = args.sigma is not None
    else:
        preset = args.errors or DEFAULT_PRESET
        machine = random_machine(args.seed, preset)
        noisy = not args.noise_free
    if not noisy:
        return machine, preset, 0.0, 0.0
    return machine, preset, DEFAULT_SIGMA if args.sigma is None else args.sigma, (
        DEFAULT_RESOLUTION)


def _z_rms(est: Estimate, data: Measurements, env: gym.Env) -> float | None:
    """RMS of the z-scores of the identifiable combinations against the truth (exact-model
    estimates only: the paper's linear fit reports no information matrix)."""
    if not est.information.size:
        return None
    design, _ = design_of(data)
    truth = parameters_of(design, env.unwrapped.true_machine, env.unwrapped.true_gauges)
    free = [est.space.index(n) for n in est.names]
    z = z_scores(est.theta[free], truth[free], est.covariance, est.information, est.scale)
    return float(np.sqrt(np.mean(z**2))) if len(z) else None


def run(args: argparse.Namespace) -> None:
    strategy = get_strategy(args.strategy)
    options = estimator_options.options(args)
    machine, preset, sigma, resolution = _setup(args)
    env = gym.make(orthoglide_env.ENV_ID, errors=preset, gauge_sigma=sigma,
                   gauge_resolution=resolution, backend=args.backend)
    try:
        env.reset(seed=args.seed, options={"machine": machine.to_dict()})
        data = strategy.collect(env)
        if args.save_measurements:
            data.to_csv(args.save_measurements)
        est = strategy.estimate(data, args.params, env.unwrapped.gauge_noise.effective_sigma,
                                **options)
        emit(report(est, env.unwrapped.true_machine, _z_rms(est, data, env)), args.json)
    finally:
        env.close()


def add(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate a virtual machine with one strategy")
    p.add_argument("--machine", help="machine JSON file: it defines every true error, and its "
                   "gauges are ideal unless --errors or --sigma ask for installation errors "
                   "or noise (default: a random machine drawn from --errors)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the random machine, its gauge installation and noise "
                        "(default: %(default)s)")
    p.add_argument("--errors", choices=sorted(PRESETS), default=None,
                   help="error preset: of the random machine and its gauges; with --machine, "
                        "of the gauge installation only (default: realistic, or none with "
                        "--machine)")
    p.add_argument("--backend", choices=["pybullet", "exact"], default="pybullet",
                   help="simulator of the virtual machine (default: %(default)s)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--noise-free", action="store_true",
                       help="ideal gauges: no noise, no display resolution")
    group.add_argument("--sigma", type=float, default=None,
                       help=f"gauge repeatability (mm; default {DEFAULT_SIGMA} for a random "
                            f"machine, 0 with --machine), with a {DEFAULT_RESOLUTION} mm dial")
    estimator_options.add(p)
    p.add_argument("--save-measurements", metavar="FILE.csv",
                   help="write the experiment's readings in the format that `fit` reads")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)
