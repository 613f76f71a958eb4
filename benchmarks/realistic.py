"""Realistic machines: what the six-parameter model leaves, before and after calibration.

    python benchmarks/realistic.py [--machines 200] [--backend exact]

On machines of the default ``realistic`` preset (paper errors plus tilted and offset
actuator axes, platform attachment and gauge installation errors), with noise-free gauges
so that what remains is model error: the gauge-difference RMS before calibration (the
nominal model's residual), the residual each strategy's six-parameter fit leaves (the
paper reports 0.32 -> 0.12 mm on its prototype), and the TCP error over the workspace in
the three frames of the scoring: raw (world frame), after the best-fit translation and
after the best-fit rigid motion (what a user who touches off the workpiece sees).
"""

from __future__ import annotations

import argparse

import numpy as np

from calibrators.compare import Config, Trial, run
from orthoglide_env.scoring import FRAMES


def _medians(trials: list[Trial], when: str) -> str:
    """Median TCP error RMS of ``trials`` (mm) in each frame, as 'raw / translation / rigid'."""
    return " / ".join(f"{np.median([getattr(t, f'tcp_{when}_{frame}_rms') for t in trials]):.3f}"
                      for frame in FRAMES)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=200)
    parser.add_argument("--backend", default="exact")
    args = parser.parse_args()
    config = Config(("paper", "gauss-newton"), "realistic", 0.0, 0.0, args.backend, "full", 7)
    trials = run(config, args.machines, progress=True)
    print(f"{args.machines} realistic machines, noise-free gauges, {args.backend} backend")
    nominal = np.array([t.nominal_residual_rms for t in trials
                        if t.strategy == config.strategies[0]])
    print(f"nominal model (no calibration): residual median {np.median(nominal):.4f}, "
          f"p90 {np.percentile(nominal, 90):.4f} mm")
    frames = " / ".join(FRAMES)
    print(f"{'strategy':14}{'residual med':>13}{'p90':>8}{f'TCP before med ({frames})':>44}"
          f"{f'TCP after med ({frames})':>43}{'rigid p90':>10}{'max':>8}")
    for name in config.strategies:
        mine = [t for t in trials if t.strategy == name]
        res = np.array([t.residual_rms for t in mine])
        rigid = np.array([t.tcp_after_rigid_rms for t in mine])
        worst = max(t.tcp_after_rigid_max for t in mine)
        print(f"{name:14}{np.median(res):13.4f}{np.percentile(res, 90):8.4f}"
              f"{_medians(mine, 'before'):>44}{_medians(mine, 'after'):>43}"
              f"{np.percentile(rigid, 90):10.4f}{worst:8.4f}")
    print("mm; residual = RMS of the twelve gauge differences left by the fit; TCP = RMS over "
          "the workspace grid, raw (world frame), after the best-fit translation, after the "
          "best-fit rigid motion; p90 and max after the rigid motion")


if __name__ == "__main__":
    main()
