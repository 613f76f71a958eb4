"""Realistic machines: what the paper's six-parameter model leaves of noise-free readings.

    python benchmarks/realistic.py [--machines 200]

On machines of the default ``realistic`` preset (paper errors plus tilted and offset
actuator axes, platform attachment and gauge installation errors), the paper's
experiment done in the lab with noise-free gauges, so that what remains is model error:
the RMS of the twelve gauge differences before calibration (the nominal model's
residual), the residual the paper's linear fit leaves (the paper reports 0.32 -> 0.12 mm
on its prototype), and the TCP error over the workspace in the three frames: raw (world
frame), after the best-fit translation and after the best-fit rigid motion.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.estimators.catalogue import for_study
from calibrators.estimators.differences import differences
from calibrators.study.episodes import run_episode
from orthoglide_env.scoring import FRAMES, score

ESTIMATORS: tuple[str, ...] = ("paper", "paper6", "extended")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=200)
    args = parser.parse_args()
    env = gym.make(orthoglide_env.LAB_ENV_ID, gauge_sigma=0.0, gauge_resolution=0.0,
                   conditions="ideal")
    nominal, residual = [], []
    tcp: dict[str, list] = {name: [] for name in ("uncalibrated", *ESTIMATORS)}
    for k in range(args.machines):
        episode = run_episode(env, get_agent("paper"), 7_000_000 + k)
        data, truth = episode.measurements, episode.truth
        nominal.append(np.sqrt(np.mean(differences(data).values ** 2)))
        for name in ESTIMATORS:
            est = for_study(name, 0.0).fit(data)
            report = score(est.machine, truth)
            tcp[name].append([getattr(report.tcp_after, f).rms for f in FRAMES])
            if name == "paper":
                residual.append(est.residual_rms_mm)
        tcp["uncalibrated"].append([getattr(report.tcp_before, f).rms for f in FRAMES])
    print(f"{args.machines} realistic machines, noise-free gauges, the paper's experiment")
    print(f"gauge differences RMS: nominal model {np.median(nominal):.4f} mm median "
          f"(p90 {np.percentile(nominal, 90):.4f}); after the paper's fit "
          f"{np.median(residual):.4f} (p90 {np.percentile(residual, 90):.4f})")
    print(f"{'':14}TCP error RMS, median over machines (mm): "
          + " / ".join(FRAMES) + "; rigid p90")
    for name, values in tcp.items():
        values = np.array(values)
        print(f"{name:14}" + " / ".join(f"{v:.3f}" for v in np.median(values, axis=0))
              + f"; {np.percentile(values[:, 2], 90):.3f}")


if __name__ == "__main__":
    main()
