"""Estimator statistics against the Cramér-Rao bound, per parameter.

    python benchmarks/statistics.py [--machines 200] [--sigma 0.01] [--resolution 0]

Paper-preset machines (only drho, dL), gauges of repeatability ``sigma``; for each
strategy and parameter: RMS error, mean error (bias), the CRLB, the reported std, and the
ratios RMS/CRLB and RMS/reported std.  With 200 machines an RMS is known to ~5%.
"""

from __future__ import annotations

import argparse

import numpy as np

from calibrators.base import PARAM_NAMES
from calibrators.compare import Config, run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=200)
    parser.add_argument("--sigma", type=float, default=0.01)
    parser.add_argument("--resolution", type=float, default=0.0)
    args = parser.parse_args()
    config = Config(("paper", "gauss-newton"), "paper", args.sigma, args.resolution, "exact",
                    "full", 11)
    trials = run(config, args.machines, progress=True)
    print(f"{args.machines} paper-preset machines, sigma {args.sigma} mm, resolution "
          f"{args.resolution} mm (errors in mm)")
    print(f"{'strategy':14}{'param':8}{'RMS':>8}{'mean':>9}{'CRLB':>8}{'std':>8}"
          f"{'RMS/CRLB':>10}{'RMS/std':>9}")
    for name in config.strategies:
        mine = [t for t in trials if t.strategy == name and np.isfinite(t.tcp_after_rigid_rms)]
        err = np.array([t.param_error for t in mine])
        rms = np.sqrt(np.mean(err**2, axis=0))
        crlb = np.sqrt(np.mean(np.array([t.crlb for t in mine]) ** 2, axis=0))
        std = np.sqrt(np.mean(np.array([t.std for t in mine]) ** 2, axis=0))
        for k, param in enumerate(PARAM_NAMES):
            print(f"{name:14}{param:8}{rms[k]:8.4f}{err[:, k].mean():9.4f}{crlb[k]:8.4f}"
                  f"{std[k]:8.4f}{rms[k] / crlb[k]:10.3f}{rms[k] / std[k]:9.3f}")


if __name__ == "__main__":
    main()
