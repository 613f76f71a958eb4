"""Realistic machines: what the six-parameter model leaves, before and after calibration.

    python benchmarks/realistic.py [--machines 200] [--backend exact]

On machines of the default ``realistic`` preset (paper errors plus tilted and offset
actuator axes, platform attachment and gauge installation errors), with noise-free gauges
so that what remains is model error: the gauge-difference RMS before calibration (the
nominal model's residual), the residual each strategy's six-parameter fit leaves (the
paper reports 0.32 -> 0.12 mm on its prototype), and the TCP error over the workspace.
"""

from __future__ import annotations

import argparse

import numpy as np

from calibrators.compare import Config, run


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
    print(f"{'strategy':14}{'residual med':>13}{'p90':>8}{'TCP before med':>16}"
          f"{'TCP after med':>15}{'p90':>8}{'max':>8}")
    for name in config.strategies:
        mine = [t for t in trials if t.strategy == name]
        res = np.array([t.residual_rms for t in mine])
        before = np.array([t.tcp_before_rms for t in mine])
        after = np.array([t.tcp_after_rms for t in mine])
        worst = max(t.tcp_after_max for t in mine)
        print(f"{name:14}{np.median(res):13.4f}{np.percentile(res, 90):8.4f}"
              f"{np.median(before):16.4f}{np.median(after):15.4f}"
              f"{np.percentile(after, 90):8.4f}{worst:8.4f}")
    print("mm; residual = RMS of the twelve gauge differences left by the fit; TCP = RMS "
          "over the workspace grid")


if __name__ == "__main__":
    main()
