"""``orthoglide calibrate``: calibrate a virtual machine with one strategy."""

from __future__ import annotations

import argparse

import gymnasium as gym

import orthoglide_env
from orthoglide_env.geometry import PRESETS

from ..base import PARAM_SETS, get_strategy
from .common import add_noise_options, machine_of, noise_of
from .output import emit, report


def run(args: argparse.Namespace) -> None:
    strategy = get_strategy(args.strategy)
    sigma, resolution = noise_of(args)
    machine = machine_of(args)
    env = gym.make(orthoglide_env.ENV_ID, errors=args.errors, gauge_sigma=sigma,
                   gauge_resolution=resolution, backend=args.backend)
    try:
        env.reset(seed=args.seed, options={"machine": machine.to_dict()})
        est = strategy.run(env, args.params)  # sigma: the gauges' spec (0 when ideal)
        truth = env.unwrapped.true_machine
    finally:
        env.close()
    emit(report(est, truth), args.json)



def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--params", choices=list(PARAM_SETS), default="full")
    p.add_argument("--errors", choices=sorted(PRESETS), default="realistic",
                   help="error preset of random machines")
    p.add_argument("--backend", choices=["pybullet", "exact"], default="pybullet")
    add_noise_options(p)


def add(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate a virtual machine with one strategy")
    p.add_argument("--strategy", default="paper")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--machine", help="machine JSON file (default: a random machine)")
    group.add_argument("--seed", type=int, default=0, help="seed of the random machine")
    add_common(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run, seed=0)
