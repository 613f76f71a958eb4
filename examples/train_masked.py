"""Train a masked policy on the lab's design view with sb3-contrib's MaskablePPO (CPU), and
compare it with the designed agents on held-out machines.

    pip install torch --index-url https://download.pytorch.org/whl/cpu  # CPU-only: not GBs
    pip install -e '.[rl]'
    python examples/train_masked.py [--steps 100000] [--budget 330] [--conditions lab]
        [--sigma 0.02] [--seed 0] [--out results/masked.zip] [--max-minutes 30]
    orthoglide compare --agents policy:results/masked.zip,active --estimators full \
        --conditions lab --budget 330 --machines 50 --seed 1

MaskablePPO learns on ``OrthoglideLabDesign-v0`` (:class:`orthoglide_env.wrappers.DesignLab`):
one discrete action over the experiment planner's candidate operations (a move to one of
the slot table's postures with its lever flicks, a re-mount, stop), masked to those open
now; an observation of what the readings so far determine (the predicted TCP error's
spectrum, the stands, the posture, the clock); and, by default, the fall of the log of
the predicted mean-square TCP error at each step, whose sum over an episode is the log of
the prior's over the last: the return is the final predicted error, and ``gamma`` is 1.
``--envs`` envs in one process (DummyVecEnv), env ``k`` seeded ``--seed + k``.

Every ``--every`` steps the policy so far is saved to ``<out>.last.zip`` and played on the
first ``--curve-machines`` held-out machines, scored against their truth by
:func:`calibrators.study.compare.run` exactly as ``orthoglide compare`` scores any agent
(estimator ``full``); the baselines (``--baselines``) are scored once on the same machines.
The learning curve goes to ``<out>.curve.csv`` and ``<out>.curve.png`` (the baselines as
horizontal lines).  At the end the policy and the baselines are compared on ``--machines``
held-out machines, with the paired ratio of every two agents.

Held-out machines: comparison machine ``i`` of seed ``s`` is drawn from seed
``s * 1000003 + i``; training machines come from each env's own stream, seeded
``--seed + k`` once, so with ``--eval-seed`` >= 1 no held-out machine is a training
machine.  The same command and seed give the same policy (one torch thread, CPU).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from training_curve import (
    add_options,
    check_options,
    curve_callback,
    mean_episode_reward,
    median_rigid,
    plot_curve,
)

from calibrators.agents.names import POLICY_PREFIX
from calibrators.agents.policy import save_policy, spec_of
from calibrators.study import compare, statistics
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.wrappers import DESIGN_PER, DESIGN_REWARDS, design_lab_env

#: The estimator that scores every evaluation (the comparison's headline).
ESTIMATOR: str = "full"
#: The designed agents whose levels the curve draws and the final table compares.
BASELINES: str = "paper,optimal,active,random"


def env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The design view's keyword arguments in training (all JSON: the policy file records
    them)."""
    return {"errors": DEFAULT_PRESET, "gauge_sigma": args.sigma, "budget_s": args.budget,
            "conditions": Conditions(args.conditions).to_dict(), "reward": args.reward,
            "per": args.per}


def config(args: argparse.Namespace, agents: tuple[str, ...]) -> compare.Config:
    return compare.Config(agents, (ESTIMATOR,), budget_s=args.budget, errors=DEFAULT_PRESET,
                          sigma=args.sigma, seed=args.eval_seed,
                          conditions=Conditions(args.conditions))


def make_vec_env(n_envs: int, kwargs: dict[str, Any], seed: int) -> Any:
    """``n_envs`` design views as a stable-baselines3 ``DummyVecEnv``, env ``k`` seeded
    ``seed + k``, each in a ``Monitor`` that keeps its episodes' final predicted error."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    def factory() -> Any:
        return Monitor(design_lab_env(**kwargs), info_keywords=("predicted_rigid_mm",))

    vec = DummyVecEnv([factory] * n_envs)
    vec.seed(seed)
    return vec


def curve_score(args: argparse.Namespace, kwargs: dict[str, Any]
                ) -> Any:
    """A learning-curve point: the policy saved at the path it is given and scored on the
    curve machines, with its training episodes' reward and final predicted error."""

    def score(model: Any, path: Path) -> dict[str, float]:
        save_policy(model, path, spec_of(design_lab_env(**kwargs), "MaskablePPO", kwargs))
        row = statistics.summary(compare.run(config(args, (POLICY_PREFIX + str(path),)),
                                             args.curve_machines))[0]
        predicted = [e["predicted_rigid_mm"] for e in model.ep_info_buffer]
        return {"mean_episode_reward": mean_episode_reward(model),
                "training_predicted_mm": (float(np.median(predicted)) if predicted
                                          else float("nan")),
                "tcp_rigid_median_mm": median_rigid(row)}

    return score


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_options(parser, steps=100_000, envs=4, envs_help="envs stepped in turn",
                budget=330.0, budget_help="lab seconds of an episode, in training and "
                "evaluation", every=10_000, out="results/masked.zip")
    parser.add_argument("--reward", default="log_mse", choices=DESIGN_REWARDS,
                        help="the fall of the predicted mean-square TCP error, or of its log")
    parser.add_argument("--per", default="step", choices=DESIGN_PER,
                        help="the reward per step or per second")
    parser.add_argument("--baselines", default=BASELINES,
                        help="agents of the curve's lines and the final table")
    args = parser.parse_args(argv)
    check_options(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    # One thread: reproducible from the seed, and the learner shares the cores.
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch
    from sb3_contrib import MaskablePPO

    torch.set_num_threads(1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    kwargs = env_kwargs(args)
    baselines = tuple(a for a in args.baselines.split(",") if a)
    levels = (statistics.summary(compare.run(config(args, baselines), args.curve_machines))
              if baselines else [])
    for row in levels:
        print(f"{row['agent']:>10}: held-out TCP (rigid) median {median_rigid(row):.4f} mm "
              f"on {args.curve_machines} curve machines", flush=True)
    vec = make_vec_env(args.envs, kwargs, args.seed)
    model = MaskablePPO("MlpPolicy", vec, n_steps=256, batch_size=256, n_epochs=5,
                        gamma=1.0, gae_lambda=0.95, ent_coef=0.01, seed=args.seed,
                        device="cpu", policy_kwargs={"net_arch": [128, 128]}, verbose=0)
    curve = curve_callback(args.out, args.every, args.max_minutes, curve_score(args, kwargs))
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=curve)
    minutes = (time.perf_counter() - start) / 60
    save_policy(model, args.out, spec_of(design_lab_env(**kwargs), "MaskablePPO", kwargs))
    vec.close()
    print(f"wrote {args.out} ({model.num_timesteps} steps in {minutes:.1f} min)")
    world = config(args, ()).world
    path = plot_curve(curve.rows, levels, args.out.with_suffix(".curve.png"),
                      reward_label="mean episode reward\n(log fall of predicted MSE)",
                      footnote=f"{world}; {ESTIMATOR}; curve machines of the held-out seed")
    print(f"wrote {path}")
    from calibrators.cli import main as orthoglide

    orthoglide(["compare", "--agents", ",".join((POLICY_PREFIX + str(args.out), *baselines)),
                "--estimators", ESTIMATOR, "--budget", str(args.budget), "--machines",
                str(args.machines), "--seed", str(args.eval_seed), "--conditions",
                args.conditions, "--sigma", str(args.sigma), "--jobs", str(args.jobs)])


if __name__ == "__main__":
    main()
