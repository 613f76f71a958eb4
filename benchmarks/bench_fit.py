"""``orthoglide fit`` on long experiments: its cost must grow linearly with the readings.

    python benchmarks/bench_fit.py [--readings 10000 100000 1000000] [--params full paper6]

The file is the paper's experiment (66 readings of one realistic machine, dial sigma
0.02 mm, ideal conditions) repeated with new repetition numbers up to each size, as a
lab that reads all day writes it.  Each size is fitted by the command a user runs
(``orthoglide fit FILE --params P``, a fresh process: reading the file, the fit, the
leave-repetitions-out verification and the report all count).  Printed per size and
parameter set: wall seconds, microseconds per reading, and the ratio to the target of
10^6 readings within 60 s on the 2-core machine.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.measurements import Measurements
from calibrators.study.episodes import run_episode

#: The target: readings and wall seconds (issue: 10^6 readings within 60 s, 2 cores).
TARGET_READINGS, TARGET_S = 1_000_000, 60.0


def paper_file(readings: int, path: Path, seed: int = 3) -> None:
    """The paper's experiment on machine ``seed``, repeated to ``readings`` rows."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, backend="exact", errors="realistic",
                   conditions="ideal", gauge_sigma=0.02)
    try:
        episode = run_episode(env, get_agent("paper"), seed)
    finally:
        env.close()
    items = episode.measurements.items
    last = max(m.repetition for m in items)
    # Without their times: repeated blocks would run the lab clock backwards.
    Measurements([m.again(m.reading, m.repetition + k // len(items) * last)
                  for k in range(readings) for m in [items[k % len(items)]]]).write(path)

def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readings", type=int, nargs="+", default=[10_000, 100_000,
                                                                    1_000_000])
    parser.add_argument("--params", nargs="+", default=["full", "paper6"])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for n in args.readings:
            path = Path(folder) / f"r{n}.csv"
            paper_file(n, path)
            for params in args.params:
                start = time.perf_counter()
                subprocess.run([sys.executable, "-m", "calibrators.cli", "fit", str(path),
                                "--params", params], check=True, stdout=subprocess.DEVNULL)
                wall = time.perf_counter() - start
                pace = TARGET_S * n / TARGET_READINGS
                print(f"{n:>9} readings, --params {params:<8} {wall:7.1f} s  "
                      f"{1e6 * wall / n:6.1f} us/reading  (target pace {pace:.1f} s: "
                      f"{wall / pace:.2f}x)", flush=True)


if __name__ == "__main__":
    main()
