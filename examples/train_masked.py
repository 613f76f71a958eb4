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
import csv
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from calibrators.agents.names import POLICY_PREFIX
from calibrators.agents.policy import save_policy, spec_of
from calibrators.study import compare, statistics
from orthoglide_env.instruments.dial import DEFAULT_SIGMA
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import CONDITION_NAMES, Conditions
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


def median_rigid(row: dict) -> float:
    value = row["tcp_after_mm"]["rigid"]["median"]
    return float("nan") if value is None else value


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


def make_curve_callback(args: argparse.Namespace, kwargs: dict[str, Any]) -> Any:
    """Every ``--every`` steps: save the policy, score it on the curve machines, append a
    row to ``<out>.curve.csv``; end training after ``--max-minutes`` (0: no limit)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Curve(BaseCallback):
        def _on_training_start(self) -> None:
            self.start = time.perf_counter()
            self.next = 0
            self.rows: list[dict[str, float]] = []
            self.path = args.out.with_suffix(".last.zip")

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next:
                self.next += args.every
                self.record()
            minutes = (time.perf_counter() - self.start) / 60
            return not 0 < args.max_minutes <= minutes

        def _on_training_end(self) -> None:
            self.record()

        def record(self) -> None:
            minutes = (time.perf_counter() - self.start) / 60
            episodes = list(self.model.ep_info_buffer)
            save_policy(self.model, self.path, spec_of(design_lab_env(**kwargs),
                                                       "MaskablePPO", kwargs))
            setup = config(args, (POLICY_PREFIX + str(self.path),))
            row = statistics.summary(compare.run(setup, args.curve_machines))[0]
            self.rows.append({
                "steps": self.num_timesteps, "minutes": round(minutes, 2),
                "mean_episode_reward": (float(np.mean([e["r"] for e in episodes]))
                                        if episodes else float("nan")),
                "training_predicted_mm": (float(np.median([e["predicted_rigid_mm"]
                                                           for e in episodes]))
                                          if episodes else float("nan")),
                "tcp_rigid_median_mm": median_rigid(row)})
            write_curve(self.rows, args.out.with_suffix(".curve.csv"))
            r = self.rows[-1]
            print(f"{r['steps']:>8d} steps {r['minutes']:6.1f} min  mean episode reward "
                  f"{r['mean_episode_reward']:7.3f}  training episodes' predicted "
                  f"{r['training_predicted_mm']:.4f} mm  held-out TCP (rigid) median "
                  f"{r['tcp_rigid_median_mm']:.4f} mm", flush=True)

    return Curve()


def write_curve(rows: list[dict[str, float]], path: Path) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def plot_curve(rows: list[dict[str, float]], baselines: list[dict], world: str,
               path: Path) -> Path:
    """Mean episode reward, and the held-out TCP error against training steps with the
    baselines' medians on the same machines as horizontal lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [r["steps"] for r in rows]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    top.plot(steps, [r["mean_episode_reward"] for r in rows], marker="o")
    top.set_ylabel("mean episode reward\n(log fall of predicted MSE)")
    bottom.plot(steps, [r["tcp_rigid_median_mm"] for r in rows], marker="o", color="k",
                label="masked policy")
    for k, row in enumerate(baselines):
        bottom.axhline(median_rigid(row), linestyle="--", linewidth=1, color=f"C{1 + k}",
                       label=row["agent"])
    bottom.set_yscale("log")
    bottom.set_ylabel("TCP error after rigid motion,\nmedian (mm)")
    bottom.set_xlabel("training steps")
    bottom.legend(fontsize=8)
    fig.text(0.01, 0.005, f"{world}; {ESTIMATOR}; curve machines of the held-out seed",
             fontsize=7)
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--steps", type=int, default=100_000, help="training steps")
    parser.add_argument("--max-minutes", type=float, default=0.0,
                        help="end training after this many minutes, evaluations included "
                             "(0: no limit; the curve says how many steps were done)")
    parser.add_argument("--envs", type=int, default=4, help="envs stepped in turn")
    parser.add_argument("--reward", default="log_mse", choices=DESIGN_REWARDS,
                        help="the fall of the predicted mean-square TCP error, or of its log")
    parser.add_argument("--per", default="step", choices=DESIGN_PER,
                        help="the reward per step or per second")
    parser.add_argument("--budget", type=float, default=330.0,
                        help="lab seconds of an episode, in training and evaluation")
    parser.add_argument("--conditions", default="lab", choices=CONDITION_NAMES,
                        help="the world of training and evaluation")
    parser.add_argument("--sigma", type=float, default=DEFAULT_SIGMA,
                        help="the dials' standard deviation (mm)")
    parser.add_argument("--seed", type=int, default=0, help="seed of training")
    parser.add_argument("--eval-seed", type=int, default=1,
                        help="comparison seed of the held-out machines (>= 1)")
    parser.add_argument("--every", type=int, default=10_000,
                        help="steps between two points of the learning curve")
    parser.add_argument("--curve-machines", type=int, default=6,
                        help="held-out machines of each learning-curve point")
    parser.add_argument("--machines", type=int, default=20,
                        help="held-out machines of the final table")
    parser.add_argument("--baselines", default=BASELINES,
                        help="agents of the curve's lines and the final table")
    parser.add_argument("--jobs", type=int, default=1, help="processes of the final table")
    parser.add_argument("--out", type=Path, default=Path("results/masked.zip"),
                        help="the trained policy's file")
    args = parser.parse_args(argv)
    if args.eval_seed < 1:
        parser.error("--eval-seed must be >= 1: seed 0's machines include training machines")
    if not (np.isfinite(args.sigma) and args.sigma > 0):
        parser.error(f"--sigma must be a positive number of mm, got {args.sigma}")
    if not (np.isfinite(args.budget) and args.budget > 0):
        parser.error(f"--budget must be a positive number of seconds, got {args.budget}")
    for name in ("steps", "envs", "every", "curve_machines", "machines", "jobs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1")
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
    curve = make_curve_callback(args, kwargs)
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=curve)
    minutes = (time.perf_counter() - start) / 60
    save_policy(model, args.out, spec_of(design_lab_env(**kwargs), "MaskablePPO", kwargs))
    vec.close()
    print(f"wrote {args.out} ({model.num_timesteps} steps in {minutes:.1f} min)")
    world = config(args, ()).world
    print(f"wrote {plot_curve(curve.rows, levels, world, args.out.with_suffix('.curve.png'))}")
    from calibrators.cli import main as orthoglide

    orthoglide(["compare", "--agents", ",".join((POLICY_PREFIX + str(args.out), *baselines)),
                "--estimators", ESTIMATOR, "--budget", str(args.budget), "--machines",
                str(args.machines), "--seed", str(args.eval_seed), "--conditions",
                args.conditions, "--sigma", str(args.sigma), "--jobs", str(args.jobs)])


if __name__ == "__main__":
    main()
