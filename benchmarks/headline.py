"""The headline under each world: compare's trials as a table with intervals.

    orthoglide compare --machines 50 --seed 1 --agents paper,random,tracker,optimal,active \
        --estimators paper6,extended --conditions C --jobs 2 --out results/head/C
    python benchmarks/headline.py results/head/ideal results/head/lab results/head/workshop

Per agent x estimator and per folder (one compare run each, its conditions in its
config): the TCP error after rigid motion (um), median with its 95 % distribution-free
interval, and p95; z-RMS; the fraction of trials whose chi-square test rejects the
model; failed trials (which enter no median: the column says how many).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from calibrators.compare import Trial, median_interval

UM = 1e3  # per mm


def cell(trials: list[Trial]) -> str:
    ok = [t for t in trials if not t.failed]
    rigid = np.array([t.tcp_after["rigid"] for t in ok]) * UM
    low, high = median_interval(rigid)
    z = np.concatenate([t.z for t in ok])
    rejected = np.mean([bool(t.chi2_rejected) for t in ok])
    return (f"{np.median(rigid):.1f} [{low:.1f}, {high:.1f}] ({np.percentile(rigid, 95):.1f}),"
            f" {np.sqrt(np.mean(z**2)):.2f}, {rejected:.2f}, {len(trials) - len(ok)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="compare --out folders")
    args = parser.parse_args()
    runs = {}
    for folder in args.folders:
        config = json.loads((folder / "config.json").read_text())
        trials = [Trial.from_json(line) for line in (folder / "trials.jsonl").open()]
        runs[config.get("conditions", "ideal")] = trials
    print("| agent | estimator | " + " | ".join(
        f"{name}: rigid µm median [95 % interval] (p95), z-RMS, chi2 rejected, failed"
        for name in runs) + " |")
    print("|---|---|" + "---|" * len(runs))
    first = next(iter(runs.values()))
    rows = list(dict.fromkeys((t.agent, t.estimator) for t in first))
    for agent, estimator in rows:
        cells = [cell([t for t in trials if (t.agent, t.estimator) == (agent, estimator)])
                 for trials in runs.values()]
        print(f"| `{agent}` | `{estimator}` | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
