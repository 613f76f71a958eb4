"""Speed of one posture: move + settle + read, PyBullet (both modes) against the exact model.

    python benchmarks/bench_machine.py [--postures 300]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.lab.machines import ExactMachine
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import PRESETS, random_machine
from orthoglide_env.sim.pybullet import OrthoglideMachine


def timed(fn: Callable[[], object], repeats: int) -> np.ndarray:
    out = np.empty(repeats)
    for k in range(repeats):
        start = time.perf_counter()
        fn()
        out[k] = time.perf_counter() - start
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--postures", type=int, default=300)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    machine = random_machine(rng, "realistic", design=PROTOTYPE)
    gauges = installed_on(machine, install(PAPER_LAYOUT, machine, preset=PRESETS["realistic"],
                                           rng=rng))
    targets = rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (args.postures, 3))
    build = timed(lambda: OrthoglideMachine(machine, gauges).close(), 20)
    sim, exact = OrthoglideMachine(machine, gauges), ExactMachine(machine, gauges)
    results = {}
    for name, backend, mode in (("exact model", exact, "quasi-static"),
                                ("pybullet quasi-static", sim, "quasi-static"),
                                ("pybullet dynamic", sim, "dynamic")):
        it = iter(targets)

        def one(backend=backend, mode=mode, it=it) -> None:
            backend.move(next(it), mode)
            backend.tcp()
            backend.gauge_distances()

        results[name] = timed(one, args.postures)
    sim.close()
    base = np.median(results["exact model"])
    print(f"machine construction (URDF write + load + closures): median "
          f"{1e3 * np.median(build):.1f} ms")
    print(f"{'backend':24} {'median ms':>10} {'p95 ms':>8} {'x exact':>8}")
    for name, t in results.items():
        print(f"{name:24} {1e3 * np.median(t):10.3f} {1e3 * np.percentile(t, 95):8.3f} "
              f"{np.median(t) / base:8.1f}")


if __name__ == "__main__":
    main()
