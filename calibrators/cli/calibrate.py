"""``orthoglide calibrate``: calibrate a virtual machine: an agent works in the lab
(``OrthoglideLab-v0``), then a strategy's estimator reads its notebook."""

from __future__ import annotations

import argparse
from contextlib import closing

from calibrators.agents import available as agents_available
from calibrators.agents import get_agent
from calibrators.cli import estimator_options
from calibrators.cli.common import (
    add_conditions,
    add_design,
    add_faults,
    add_instruments,
    add_thermometer,
    conditions_of,
    faults_of,
    fit_conditions_of,
    given_design,
    instruments_of,
)
from calibrators.cli.output import emit, report, save
from calibrators.study.episodes import DEFAULT_BUDGET_S, machine_seed, run_episode
from calibrators.study.labs import make_lab
from calibrators.study.z_scores import z_rms
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.model.design import load_design
from orthoglide_env.model.errors import DEFAULT_PRESET, PRESETS, MachineParams
from orthoglide_env.world.machine_file import machine_dict, read_machine_file, write_machine_file
from orthoglide_env.world.truth import World


def _setup(args: argparse.Namespace
           ) -> tuple[MachineParams, World | None, str, float, float]:
    """The true machine and its world (a machine file's, else None: drawn by the lab), the
    preset of gauge installation errors, and the gauge noise.

    A machine file defines every true error (and, when it holds a ``world``, the drawn
    non-geometric truth): its gauges are installed perfectly and read without noise unless
    ``--errors`` or ``--sigma`` ask for them.  A random machine is drawn from ``--errors``
    (default realistic) with its gauge errors and noise."""
    world = None
    if args.machine:
        machine, world = read_machine_file(args.machine, given_design(args))
        preset = args.errors or "nominal"
        noisy = args.sigma is not None
    else:
        preset = args.errors or DEFAULT_PRESET
        # Unused but for its design: the lab draws the machine from the seed.
        machine = MachineParams(design=load_design(args.design))
        noisy = not args.noise_free
    sigma = DEFAULT_SIGMA if args.sigma is None else args.sigma
    noise = (sigma, DEFAULT_RESOLUTION) if noisy else (0.0, 0.0)
    return machine, world, preset, *noise


def run(args: argparse.Namespace) -> None:
    estimator_options.estimator(args)  # an unknown one, or a bad option, is refused early
    agent = get_agent(args.agent)
    machine, world, preset, sigma, resolution = _setup(args)
    conditions = conditions_of(args, world)
    faults = faults_of(args)
    env = make_lab(agent, errors=preset, gauge_sigma=sigma, gauge_resolution=resolution,
                   backend=args.backend, thermometer=args.thermometer, budget_s=args.budget,
                   design=machine.design, conditions=conditions,
                   instruments=instruments_of(args, (agent,)),
                   **({"faults": faults} if faults.active else {}))
    with closing(env):
        # A random machine is drawn by the lab from the seed, as ``compare`` draws its first
        # one: the same seed gives the same machine, installation and readings there and here.
        given = {"machine": machine_dict(machine, world)} if args.machine else None
        episode = run_episode(env, agent, machine_seed(args.seed, 0), options=given)
        data = episode.measurements
        if args.save_measurements:
            data.write(args.save_measurements)
        if args.save_truth:
            write_machine_file(args.save_truth, episode.truth, episode.world)
        est = estimator_options.estimate(args, data, episode.sigma,
                                         fit_conditions_of(args, conditions))
        save(est, args)
        lab = env.unwrapped
        shown = report(est, episode.truth, z_rms(est, data, lab.true_machine, lab.true_gauges),
                       episode.world)
        if faults.active:
            shown["faults"] = episode.faults  # the truth, beside the score
        emit(shown, args.json)


def add(p: argparse.ArgumentParser) -> None:
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
    add_design(p)
    add_conditions(p, replays=True, told=True)
    add_thermometer(p)
    add_instruments(p)
    add_faults(p)
    p.add_argument("--backend", choices=["pybullet", "exact"], default="pybullet",
                   help="simulator of the virtual machine (default: %(default)s)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--noise-free", action="store_true",
                       help="ideal gauges: no noise, no display resolution")
    group.add_argument("--sigma", type=float, default=None,
                       help=f"gauge repeatability (mm; default {DEFAULT_SIGMA} for a random "
                            f"machine, 0 with --machine), with a {DEFAULT_RESOLUTION} mm dial")
    estimator_options.add(p)
    p.add_argument("--agent", default="paper",
                   help=f"who works in the lab: {', '.join(agents_available())}, or "
                        "policy:FILE, a learned policy (default: %(default)s)")
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S,
                   help="lab time budget (s, default %(default)s)")
    p.add_argument("--save-measurements", metavar="FILE.csv",
                   help="write the experiment's readings in the format that `fit` reads")
    p.add_argument("--save-truth", metavar="FILE.json",
                   help="write the true machine as a machine file, with its drawn world "
                        "under --conditions lab or workshop: --machine FILE replays it")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)
