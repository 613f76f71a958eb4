"""Building a PyBullet machine: in a new client each time, or in one client reused.

    python benchmarks/bench_build.py [--machines 20] [--rounds 5]

"new client, stands drawn" is what every env reset did before clients were reused and
stands were drawn only for pictures: connect, build, draw the gauge stands, disconnect.
"new client" leaves the stands out; "reused client" is what a reset does now: clear the
client's world (``resetSimulation``) and build in it.  All build the same random realistic
machines with the paper's six gauges (URDF written and loaded, loops closed, placed at
Zero); rounds alternate so that a change of load hits all alike.  The last lines time
what makes up the differences, and a whole ``env.reset()`` of the PyBullet backend.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import orthoglide_env
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import PRESETS, random_machine
from orthoglide_env.sim.pybullet import OrthoglideMachine
from orthoglide_env.sim.simulator import Simulator


def per_call(fn: Callable[[], object], calls: int) -> float:
    """Milliseconds per call of ``fn`` over ``calls`` calls."""
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    return 1e3 * (time.perf_counter() - start) / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    machines = []
    for _ in range(args.machines):
        m = random_machine(rng, "realistic", design=PROTOTYPE)
        gauges = install(PAPER_LAYOUT, m, preset=PRESETS["realistic"], rng=rng)
        machines.append((m, installed_on(m, gauges)))
    shared = Simulator()

    def drawn(machine: OrthoglideMachine) -> None:
        machine._draw_stands()
        machine.close()

    variants: dict[str, Callable[[tuple], object]] = {
        "new client, stands drawn": lambda m: drawn(OrthoglideMachine(*m)),
        "new client": lambda m: OrthoglideMachine(*m).close(),
        "reused client (now)": lambda m: OrthoglideMachine(*m, sim=shared),
    }
    times: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.rounds):
        for name, build in variants.items():
            it = iter(machines)
            times[name].append(per_call(lambda it=it, build=build: build(next(it)),
                                        len(machines)))
    clients: list[Simulator] = []
    connect = per_call(lambda: clients.append(Simulator()), 20)
    disconnect = per_call(lambda: clients.pop().close(), 20)
    clear = per_call(shared.clear, 20)
    shared.close()
    env = gym.make(orthoglide_env.ENV_ID, backend="pybullet", conditions="ideal")
    env.reset(seed=0)
    seeds = iter(range(1, 10**6))
    reset = per_call(lambda: env.reset(seed=next(seeds)), args.machines)
    env.close()
    print(f"cpus: {os.cpu_count()}, load average: {os.getloadavg()[0]:.2f}; "
          f"{args.machines} machines x {args.rounds} rounds, ms per machine")
    print(f"{'build':28}{'median':>8}{'min':>8}{'max':>8}{'x now':>8}")
    now = float(np.median(times["reused client (now)"]))
    for name, values in times.items():
        print(f"{name:28}{np.median(values):8.1f}{min(values):8.1f}{max(values):8.1f}"
              f"{np.median(values) / now:8.2f}")
    print(f"connect {connect:.1f} ms, disconnect {disconnect:.1f} ms, clear (resetSimulation "
          f"and settings) {clear:.2f} ms; env.reset() on the pybullet backend {reset:.1f} ms")


if __name__ == "__main__":
    main()
