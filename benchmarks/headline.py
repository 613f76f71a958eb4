"""The headline under each world: compare's trials as a table with intervals.

    orthoglide compare --machines 50 --seed 1 --agents paper,random,tracker,optimal,active \
        --estimators extended,full --conditions C --jobs 2 --out results/head/C
    python benchmarks/headline.py results/head/ideal results/head/lab results/head/workshop

Per agent x estimator and per folder (one compare run each, its conditions in its
config): the TCP error after rigid motion (um), median with its 95 % distribution-free
interval, and p95; the median lab time (min); z-RMS; the fraction of trials whose
chi-square test rejects the model; failed trials (each counted as its uncalibrated
machine, as compare's summary counts them).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from calibrators.study.compare import Trial
from calibrators.study.statistics import summary

UM = 1e3  # per mm


def cell(trials: list[Trial]) -> str:
    """One agent x estimator's row of compare's summary, in um."""
    (row,) = summary(trials)
    rigid = row["tcp_after_mm"]["rigid"]
    low, high = (UM * v for v in rigid["ci95"])
    return (f"{UM * rigid['median']:.1f} [{low:.1f}, {high:.1f}] ({UM * rigid['p95']:.1f}),"
            f" {row['time_s']['median'] / 60:.0f}, {row['z_rms']:.2f},"
            f" {row['chi2_rejected']:.2f}, {row['failed']}")


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
        f"{name}: rigid µm median [95 % interval] (p95), min, z-RMS, chi2 rejected, failed"
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
