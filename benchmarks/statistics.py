"""Estimator statistics per parameter: is the reported uncertainty the real one?

    python benchmarks/statistics.py [--machines 200] [--sigma 0.01] [--resolution 0]

Paper-preset machines (only drho, dL), the paper's experiment done in the lab, gauges of
repeatability ``sigma``; for each estimator and parameter: RMS error, mean error (bias),
the RMS of the reported std, and their ratio (1 for an efficient, honest estimator; with
200 machines an RMS is known to ~5%).
"""

from __future__ import annotations

import argparse

import numpy as np

from calibrators.study.compare import Config, run
from orthoglide_env.model.errors import ERROR_NAMES
from orthoglide_env.world.conditions import IDEAL


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=200)
    parser.add_argument("--sigma", type=float, default=0.01)
    parser.add_argument("--resolution", type=float, default=0.0)
    args = parser.parse_args()
    config = Config(("paper",), ("paper", "paper6"), errors="paper", sigma=args.sigma,
                    conditions=IDEAL,
                    resolution=args.resolution, seed=11)
    trials = run(config, args.machines, jobs=2)
    print(f"{args.machines} paper-preset machines, sigma {args.sigma} mm, resolution "
          f"{args.resolution} mm (errors in mm)")
    print(f"{'estimator':12}{'param':8}{'RMS':>8}{'mean':>9}{'std':>8}{'RMS/std':>9}")
    for name in config.estimators:
        mine = [t for t in trials if t.estimator == name and not t.failed]
        err = np.array([t.error[:6] for t in mine])
        std = np.sqrt(np.mean(np.array([t.std[:6] for t in mine]) ** 2, axis=0))
        rms = np.sqrt(np.mean(err**2, axis=0))
        for k, param in enumerate(ERROR_NAMES[:6]):
            print(f"{name:12}{param:8}{rms[k]:8.4f}{err[:, k].mean():9.4f}{std[k]:8.4f}"
                  f"{rms[k] / std[k]:9.3f}")


if __name__ == "__main__":
    main()
