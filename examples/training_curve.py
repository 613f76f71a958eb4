"""What the training scripts (``train_policy.py``, ``train_masked.py``) share: their
command line's common options and checks, and the learning curve -- a callback that saves
the policy and scores it on held-out machines every few steps, its CSV and its picture
with the baselines' levels."""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from orthoglide_env.instruments.dial import DEFAULT_SIGMA
from orthoglide_env.world.conditions import CONDITION_NAMES, DEFAULT_CONDITIONS

#: A curve point's scores of the model saved at the path: column name -> value.
Score = Callable[[Any, Path], dict[str, float]]


def add_options(parser: argparse.ArgumentParser, *, steps: int, envs: int, envs_help: str,
                budget: float, budget_help: str, every: int, out: str) -> None:
    """The options every training script takes, with the script's own defaults."""
    parser.add_argument("--steps", type=int, default=steps,
                        help="training steps (PPO trains in whole rollouts of its n_steps "
                             "per env, so the count is rounded up to a whole number of them)")
    parser.add_argument("--max-minutes", type=float, default=0.0,
                        help="end training after this many minutes, evaluations included "
                             "(0: no limit; the curve says how many steps were done)")
    parser.add_argument("--envs", type=int, default=envs, help=envs_help)
    parser.add_argument("--budget", type=float, default=budget, help=budget_help)
    parser.add_argument("--conditions", default=DEFAULT_CONDITIONS, choices=CONDITION_NAMES,
                        help="the world of training and evaluation")
    parser.add_argument("--sigma", type=float, default=DEFAULT_SIGMA,
                        help="the dials' standard deviation (mm)")
    parser.add_argument("--seed", type=int, default=0, help="seed of training")
    parser.add_argument("--eval-seed", type=int, default=1,
                        help="comparison seed of the held-out machines (>= 1)")
    parser.add_argument("--every", type=int, default=every,
                        help="steps between two points of the learning curve")
    parser.add_argument("--curve-machines", type=int, default=6,
                        help="held-out machines of each learning-curve point")
    parser.add_argument("--machines", type=int, default=20,
                        help="held-out machines of the final table")
    parser.add_argument("--jobs", type=int, default=1, help="processes of the final table")
    parser.add_argument("--out", type=Path, default=Path(out), help="the trained policy's file")


def check_options(parser: argparse.ArgumentParser, args: argparse.Namespace,
                  min_steps: int = 1) -> None:
    """Refuse, in one line each, what :func:`add_options`' values cannot be (``min_steps``:
    the fewest ``--steps``, 0 where a script learns otherwise first)."""
    if args.eval_seed < 1:
        parser.error("--eval-seed must be >= 1: seed 0's machines include training machines")
    if not (np.isfinite(args.sigma) and args.sigma > 0):
        parser.error(f"--sigma must be a positive number of mm, got {args.sigma}")
    if not (np.isfinite(args.budget) and args.budget > 0):
        parser.error(f"--budget must be a positive number of seconds, got {args.budget}")
    if args.steps < min_steps:
        parser.error(f"--steps must be at least {min_steps}")
    for name in ("envs", "every", "curve_machines", "machines", "jobs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1")


def median_rigid(row: dict) -> float:
    """A summary row's median TCP error after rigid motion (mm; NaN when none)."""
    value = row["tcp_after_mm"]["rigid"]["median"]
    return float("nan") if value is None else value


def curve_callback(out: Path, every: int, max_minutes: float, score: Score,
                   earlier: list[dict[str, float]] | None = None) -> Any:
    """A stable-baselines3 callback that, every ``every`` steps and at the end, saves
    nothing itself but asks ``score`` for the model's scores (``score`` saves the policy to
    ``<out>.last.zip``, the path it is given, and evaluates it), appends them to
    ``<out>.curve.csv`` with the steps and minutes, and prints them.  It ends training
    after ``max_minutes`` (0: no limit); its ``rows`` are the curve, after the ``earlier``
    rows of a first stage of training, whose last steps and minutes its own continue."""
    earlier = list(earlier or [])
    steps0, minutes0 = ((earlier[-1]["steps"], earlier[-1]["minutes"]) if earlier
                        else (0, 0.0))
    from stable_baselines3.common.callbacks import BaseCallback

    class Curve(BaseCallback):
        def _on_training_start(self) -> None:
            self.start = time.perf_counter()
            # A first stage's last row already scores the model it hands over.
            self.next = every if earlier else 0
            self.rows: list[dict[str, float]] = list(earlier)

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next:
                self.next += every
                self.record()
            minutes = minutes0 + (time.perf_counter() - self.start) / 60
            return not 0 < max_minutes <= minutes

        def _on_training_end(self) -> None:
            self.record()

        def record(self) -> None:
            minutes = minutes0 + (time.perf_counter() - self.start) / 60
            scores = score(self.model, out.with_suffix(".last.zip"))
            self.rows.append({"steps": steps0 + self.num_timesteps,
                              "minutes": round(minutes, 2),
                              **scores})
            write_curve(self.rows, out.with_suffix(".curve.csv"))
            print(f"{steps0 + self.num_timesteps:>8d} steps {minutes:6.1f} min  " + "  ".join(
                f"{name.replace('_', ' ')} {value:.4f}" for name, value in scores.items()),
                flush=True)

    return Curve()


def silent_logger(model: Any) -> None:
    """Give ``model`` (a stable-baselines3 algorithm) a logger that writes nowhere: without
    one, each ``learn`` call makes stable-baselines3's default logger, which creates an
    empty ``SB3-<date>`` folder in the system's temporary directory (the curve's CSV and
    picture are the record of a run)."""
    from stable_baselines3.common.logger import Logger

    model.set_logger(Logger(folder=None, output_formats=[]))


def mean_episode_reward(model: Any) -> float:
    """The mean reward of the model's last 100 training episodes (NaN before the first)."""
    rewards = [e["r"] for e in model.ep_info_buffer]
    return float(np.mean(rewards)) if rewards else float("nan")


def write_curve(rows: list[dict[str, float]], path: Path) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def plot_curve(rows: list[dict[str, float]], baselines: list[dict], path: Path, *,
               reward_label: str, footnote: str) -> Path:
    """Mean episode reward, and the held-out TCP error against training steps with the
    baselines' medians as horizontal lines; ``footnote`` names the world."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [r["steps"] for r in rows]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    top.plot(steps, [r["mean_episode_reward"] for r in rows], marker="o")
    top.set_ylabel(reward_label)
    bottom.plot(steps, [r["tcp_rigid_median_mm"] for r in rows], marker="o", color="k",
                label="policy (curve machines)")
    for k, row in enumerate(baselines):
        bottom.axhline(median_rigid(row), linestyle="--", linewidth=1, color=f"C{1 + k}",
                       label=f"{row['agent']} ({row['machines']} machines)")
    bottom.set_yscale("log")
    bottom.set_ylabel("TCP error after rigid motion,\nmedian (mm)")
    bottom.set_xlabel("training steps")
    bottom.legend(fontsize=8)
    fig.text(0.01, 0.005, footnote, fontsize=7)
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
