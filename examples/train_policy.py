"""Train a learned calibration agent with stable-baselines3 and compare it on held-out
machines.

    pip install torch --index-url https://download.pytorch.org/whl/cpu  # CPU-only: not GBs
    pip install -e '.[rl]'
    python examples/train_policy.py [--steps 120000] [--envs 8] [--reward information]
        [--budget 600] [--conditions lab] [--sigma 0.02] [--out results/policy.zip]
        [--machines 20]
    orthoglide compare --agents policy:results/policy.zip,random,paper --estimators full \
        --conditions lab

PPO learns on ``OrthoglideLab-v0`` under ``--conditions`` (default ``lab``: the screws,
heat and indicators of a real lab, the world every agent is compared in) through its flat
view (one Box of actions, one of observations, :mod:`orthoglide_env.wrappers`),
several envs in parallel, observations normalised by ``VecNormalize`` (its statistics are
saved with the policy: the agent ``policy:FILE`` normalises as training did).  Every
``--every`` steps the policy so far is saved and played on the first ``--curve-machines``
held-out machines, scored by :func:`calibrators.study.compare.run` exactly as ``orthoglide
compare`` scores any agent; the learning curve goes to ``<out>.curve.csv`` and
``<out>.curve.png``.  At the end the policy is compared with ``random``, ``paper`` and
every other designed agent that is registered on ``--machines`` held-out machines.

Why PPO: the CPU is the limit (an env step costs ~3 ms), and PPO's updates cost little per
step, where SAC or TD3 take a gradient step per env step; the information reward is dense
enough for an on-policy learner.

Held-out machines: comparison machine ``i`` of seed ``s`` is drawn from seed
``s * 1000003 + i``; training machines come from each env's own stream, seeded
``--seed + rank`` once, so with ``--eval-seed`` >= 1 no held-out machine is a training
machine.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass
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
    silent_logger,
)

from calibrators.agents import available
from calibrators.agents.names import POLICY_PREFIX
from calibrators.agents.policy import PolicySpec, save_policy, spec_of
from calibrators.study import compare, statistics
from calibrators.study.episodes import DEFAULT_BUDGET_S, make_estimator
from orthoglide_env.instruments.dial import DEFAULT_SIGMA
from orthoglide_env.lab.operations import V0_OPS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.wrappers import flat_lab_env

LAB = Conditions("lab")

#: The estimator that scores every evaluation (the comparison's headline; under ``ideal``
#: it is ``extended``, bit for bit).
ESTIMATOR: str = "full"
#: The untrained policy (:func:`start_near_zero`): log standard deviation of its actions,
#: the bias of ``move`` in the operation block (another operation wins an untrained step's
#: arg-max about once in 30 steps), and the spread of its joint targets around Zero (mm;
#: every paper gauge reads within about 5 mm of Zero).
LOG_STD_INIT: float = -1.0
MOVE_BIAS: float = 0.6
RHO_SPREAD_MM: float = 5.0
#: Agents of the final table besides the policy, when registered (``optimal`` and
#: ``active`` are designed experiments; ``tracker`` reads another instrument).
BASELINES: tuple[str, ...] = ("random", "paper", "optimal", "active")


@dataclass(frozen=True)
class Lab:
    """The lab of training and of every evaluation (docs/agents.md, 'A learned agent', the
    real-world comparison: ``lab`` conditions, dials of sigma 0.02 mm, the default hour for
    every agent; the policy stops after its training episodes' time)."""

    errors: str = DEFAULT_PRESET
    sigma: float = DEFAULT_SIGMA
    budget_s: float = DEFAULT_BUDGET_S
    conditions: Conditions = LAB

    def env_kwargs(self, reward: str, budget_s: float) -> dict[str, Any]:
        """Keyword arguments of the training lab env, episodes of ``budget_s`` (the
        conditions as their dict, so that the policy file records them)."""
        kwargs: dict[str, Any] = {"errors": self.errors, "gauge_sigma": self.sigma,
                                  "budget_s": budget_s, "reward": reward,
                                  "conditions": self.conditions.to_dict()}
        if reward == "accuracy":
            kwargs["estimator"] = make_estimator(ESTIMATOR)
        return kwargs

    def config(self, agents: tuple[str, ...], seed: int) -> compare.Config:
        return compare.Config(agents, (ESTIMATOR,), budget_s=self.budget_s, errors=self.errors,
                              sigma=self.sigma, seed=seed, conditions=self.conditions)


def start_near_zero(model: Any) -> None:
    """Start from small moves around Zero.  The untrained policy's mean action is 0: every
    operation as likely (a fifth of the steps stop the episode) and every move to the
    middle of the joint range, where the bars push most engaged gauges past their travel
    (they fault, and read nothing more).  Its first episodes would teach little.  Biasing
    the operation block towards ``move`` (:data:`MOVE_BIAS` against the spread
    ``exp(LOG_STD_INIT)``) and centring the joint targets on Zero with a spread of
    :data:`RHO_SPREAD_MM`, inside the travel of the gauges, makes them experiments that
    read; training then learns where to go, and whether to lift, re-mount or stop."""
    import torch

    low, high = PROTOTYPE.rho_min, PROTOTYPE.rho_max
    middle, half = (high + low) / 2, (high - low) / 2
    bias, log_std = model.policy.action_net.bias, model.policy.log_std
    with torch.no_grad():
        bias[:3] = (0.0 - middle) / half
        log_std[:3] = float(np.log(RHO_SPREAD_MM / half))
        bias[3:3 + V0_OPS] = -MOVE_BIAS
        bias[3 + Op.MOVE] = MOVE_BIAS


def make_vec_env(n_envs: int, env_kwargs: dict[str, Any], seed: int, subprocesses: bool
                 ) -> Any:
    """``n_envs`` flat lab envs as a stable-baselines3 ``VecEnv``, env ``k`` seeded
    ``seed + k``, each in a ``Monitor`` (episode rewards for the curve).

    The one place the training envs are made: a native lab vector env (all machines
    stepped as arrays in one process) plugs in here behind stable-baselines3's
    ``VecEnv`` interface, and nothing else changes."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    def factory() -> Any:
        return Monitor(flat_lab_env(**env_kwargs))

    vec = (SubprocVecEnv([factory] * n_envs, start_method="spawn") if subprocesses
           else DummyVecEnv([factory] * n_envs))
    vec.seed(seed)
    return vec


def evaluate(path: Path, lab: Lab, seed: int, machines: int) -> list[dict]:
    """``compare``'s summary of the policy in ``path`` on held-out machines."""
    config = lab.config((POLICY_PREFIX + str(path),), seed)
    return statistics.summary(compare.run(config, machines), config.target_mm)


def curve_score(lab: Lab, env_kwargs: dict[str, Any], seed: int, machines: int) -> Any:
    """A learning-curve point: the policy (with its normaliser) saved at the path it is
    given and scored on ``machines`` held-out machines of ``seed``, with the mean reward
    of its last 100 training episodes."""

    def score(model: Any, path: Path) -> dict[str, float]:
        save_policy(model, path, policy_spec(env_kwargs, model.get_vec_normalize_env()))
        row = evaluate(path, lab, seed, machines)[0]
        return {"mean_episode_reward": mean_episode_reward(model),
                "tcp_rigid_median_mm": median_rigid(row)}

    return score


def policy_spec(env_kwargs: dict[str, Any], normaliser: Any) -> PolicySpec:
    """What a PPO policy trained on the flat lab of ``env_kwargs`` is saved with: the
    lab's sizes, the env's keyword arguments a JSON file can keep (not the estimator) and
    ``normaliser``'s statistics."""
    recordable = {k: v for k, v in env_kwargs.items() if k != "estimator"}
    return spec_of(flat_lab_env(**env_kwargs), "PPO", recordable, normaliser)


def print_table(rows: list[dict], minutes: float, steps: int) -> None:
    print(f"\nheld-out machines, estimator {ESTIMATOR}; policy trained {steps} steps in "
          f"{minutes:.1f} min")
    print(f"{'agent':34}{'TCP rigid med mm':>17}{'p95':>9}{'time med min':>13}"
          f"{'readings':>10}{'failed':>8}")
    for r in rows:
        rigid = r["tcp_after_mm"]["rigid"]
        p95 = float("nan") if rigid["p95"] is None else rigid["p95"]
        print(f"{r['agent']:34}{median_rigid(r):17.4f}{p95:9.4f}"
              f"{r['time_s']['median'] / 60:13.1f}{r['readings_median']:10.0f}{r['failed']:8d}")


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_options(parser, steps=120_000, envs=8, envs_help="envs stepped in parallel",
                budget=600.0, budget_help="lab seconds of a training episode; the policy "
                "stops there", every=20_000, out="results/policy.zip")
    parser.add_argument("--subprocesses", action="store_true",
                        help="one process per env (SubprocVecEnv) instead of one for all")
    parser.add_argument("--reward", default="information",
                        choices=["information", "accuracy"],
                        help="information gained per second, or the fall of the TCP error")
    args = parser.parse_args()
    check_options(parser, args)
    # One thread each: the learner shares the cores with the envs (and other jobs).
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(1)
    lab = Lab(sigma=args.sigma, conditions=Conditions(args.conditions))
    env_kwargs = lab.env_kwargs(args.reward, args.budget)
    vec = VecNormalize(make_vec_env(args.envs, env_kwargs, args.seed, args.subprocesses),
                       norm_obs=True, norm_reward=True, gamma=0.99)
    model = PPO("MlpPolicy", vec, n_steps=128, batch_size=256, gamma=0.99, seed=args.seed,
                policy_kwargs={"log_std_init": LOG_STD_INIT}, verbose=0)
    silent_logger(model)
    start_near_zero(model)
    curve = curve_callback(args.out, args.every, args.max_minutes,
                           curve_score(lab, env_kwargs, args.eval_seed, args.curve_machines))
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=curve)
    minutes = (time.perf_counter() - start) / 60
    save_policy(model, args.out, policy_spec(env_kwargs, vec))
    vec.close()
    print(f"wrote {args.out}")
    known = available()
    agents = (POLICY_PREFIX + str(args.out), *(a for a in BASELINES if a in known))
    config = lab.config(agents, args.eval_seed)
    rows = statistics.summary(compare.run(config, args.machines, args.jobs), config.target_mm)
    print_table(rows, minutes, model.num_timesteps)
    path = plot_curve(curve.rows, rows[1:], args.out.with_suffix(".curve.png"),
                      reward_label="mean episode reward",
                      footnote=f"{config.world}; {ESTIMATOR}; curve machines of the held-out "
                      "seed")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
