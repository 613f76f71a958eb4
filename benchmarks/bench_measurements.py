"""Measurement files at their size limit: reading and differencing must stay linear.

    python benchmarks/bench_measurements.py [--rows 100000 1000000]

Each file holds four readings per repetition (the x leg's two gauges at Zero and XMax),
so a million rows span 250,000 repetitions.  Printed per size and format: the time to
read the file, to compute the averaged differences, and both per row; linear cost shows
as a constant time per row.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from calibrators.estimators.differences import differences
from calibrators.measurements import Measurements


def write_files(rows: int, folder: Path) -> dict[str, Path]:
    """The same readings as CSV and as JSON, written as text (not timed)."""
    reps = np.repeat(np.arange(1, rows // 4 + 1), 4)
    gauges = np.tile(["x", "x", "x", "x"], rows // 4)
    axes = np.tile(["y", "z", "y", "z"], rows // 4)
    postures = np.tile(["Zero", "Zero", "XMax", "XMax"], rows // 4)
    readings = np.random.default_rng(0).normal(0.0, 0.5, rows)
    csv_path, json_path = folder / "m.csv", folder / "m.json"
    csv_path.write_text("leg,axis,posture,repetition,reading_mm\n" + "".join(
        f"{g},{a},{p},{r},{v!r}\n" for g, a, p, r, v in
        zip(gauges, axes, postures, reps.tolist(), readings.tolist(), strict=True)))
    json_path.write_text('{"readings": [\n' + ",\n".join(
        f'{{"leg": "{g}", "axis": "{a}", "posture": "{p}", "repetition": {r}, '
        f'"reading_mm": {v!r}}}' for g, a, p, r, v in
        zip(gauges, axes, postures, reps.tolist(), readings.tolist(), strict=True)) + "\n]}\n")
    return {"csv": csv_path, "json": json_path}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, nargs="+", default=[100_000, 1_000_000])
    args = parser.parse_args()
    print(f"{'rows':>9} {'format':>6} {'read s':>8} {'diff s':>8} {'read µs/row':>12} "
          f"{'diff µs/row':>12}")
    with tempfile.TemporaryDirectory() as folder:
        for rows in args.rows:
            for fmt, path in write_files(rows, Path(folder)).items():
                start = time.perf_counter()
                data = Measurements.read(path)
                read = time.perf_counter() - start
                start = time.perf_counter()
                rows_out = differences(data)
                diff = time.perf_counter() - start
                assert len(data) == rows and len(rows_out) == 2
                print(f"{rows:>9} {fmt:>6} {read:>8.2f} {diff:>8.2f} {1e6 * read / rows:>12.2f} "
                      f"{1e6 * diff / rows:>12.2f}")


if __name__ == "__main__":
    main()
