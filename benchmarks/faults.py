"""The fault table: per kind of fault, how often the fit names it, and how often a clean
run raises a false alarm or a faulted one fails silently.

    python benchmarks/faults.py [--machines 50] [--budget 3600] [--jobs 2] [--out FILE]

Every row is a comparison of the same machines (realistic errors, seed 1) under ``lab``
conditions, dial sigma 0.02 mm read to 0.01 mm, the ``optimal`` agent and the ``full``
estimator: one without faults, then one per kind with only that kind.  Columns: the
trials in which a fault of the kind acted, the fraction of them whose fit named the kind
(``faults_detected``), the fraction of all trials that fail silently (off by more than 3
sigma along a determined combination with no warning, :func:`calibrators.study.statistics.
silent`), and for the clean run the false alarms: trials whose fit named any fault.  Each
row's JSON goes to ``--out`` as soon as it is done (one line each).
"""

from __future__ import annotations

import argparse
import json
import time

from calibrators.study.compare import Config, run
from calibrators.study.statistics import fault_keys, silent
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.faults import FAULT_KINDS, NO_FAULTS, Faults


def row(kind: str, machines: int, budget: float, jobs: int) -> dict:
    """The comparison with faults of ``kind`` only ("clean": none), summarised."""
    config = Config(("optimal",), ("full",), budget_s=budget, errors="realistic", sigma=0.02,
                    seed=1, conditions=Conditions("lab"),
                    faults=NO_FAULTS if kind == "clean" else Faults((kind,)))
    start = time.perf_counter()
    trials = run(config, machines, jobs)
    alarms = [any(w.startswith("fault ") for w in t.warnings) for t in trials]
    return {"kind": kind, "machines": machines, "budget_s": budget,
            "with_fault": sum(bool(t.faults) for t in trials),
            "failed": sum(bool(t.failed) for t in trials),
            "fault_alarms": sum(alarms) / len(trials),
            "silent": sum(silent(t) for t in trials),
            **fault_keys(trials), "seconds": time.perf_counter() - start}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--machines", type=int, default=50)
    parser.add_argument("--budget", type=float, default=3600.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--kinds", default=",".join(("clean", *FAULT_KINDS)),
                        help="clean and the fault kinds, comma-separated (default: all)")
    parser.add_argument("--out", default=None, help="JSON lines, one row each")
    args = parser.parse_args()
    print(f"{'kind':14}{'with fault':>11}{'named':>8}{'any fault named':>17}"
          f"{'silent':>8}{'failed':>8}")
    for kind in args.kinds.split(","):
        r = row(kind, args.machines, args.budget, args.jobs)
        if args.out:
            with open(args.out, "a") as handle:
                handle.write(json.dumps(r) + "\n")
        named = "-" if r["faults_detected"] is None else f"{r['faults_detected']:.0%}"
        print(f"{kind:14}{r['with_fault']:>11}{named:>8}{r['fault_alarms']:>17.0%}"
              f"{r['silent_failures']:>8.1%}{r['failed']:>8}", flush=True)


if __name__ == "__main__":
    main()
