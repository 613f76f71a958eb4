"""Fidelity of the PyBullet machine against the exact model.

For N random machines (one posture each across the joint range, plus the Zero reference)
and both ways of reaching a posture, prints the worst and median TCP error, gauge
difference error, platform rotation and loop residual, and the validity agreement.

    python benchmarks/fidelity.py [--machines 200] [--presets realistic,paper]
"""

from __future__ import annotations

import argparse

import numpy as np
from tqdm import tqdm

from orthoglide_env.instruments.rays import exact_ray_distances
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import PRESETS, random_machine
from orthoglide_env.model.kinematics import direct
from orthoglide_env.sim.pybullet import OrthoglideMachine
from orthoglide_env.sim.simulator import PhysicsSettings


def measure(preset: str, n: int, seed: int) -> dict[str, dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out: dict[str, dict[str, list]] = {
        m: {k: [] for k in ("tcp", "gauge", "rot", "loop", "steps")}
        for m in ("quasi-static", "dynamic")
    }
    agree = total = 0
    for _ in tqdm(range(n), desc=preset, leave=False):
        machine = random_machine(rng, preset, design=PROTOTYPE)
        gauges = installed_on(machine, install(PAPER_LAYOUT, machine, preset=PRESETS[preset],
                                               rng=rng))
        sim = OrthoglideMachine(machine, gauges)
        # Half the postures near Zero (gauges in contact), half anywhere in the range.
        rho = (rng.uniform(-8, 8, 3) if rng.random() < 0.5
               else rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, 3))
        exact_t = exact_ray_distances(machine, gauges, rho) - exact_ray_distances(
            machine, gauges, np.zeros(3))
        for mode, stats in out.items():
            sim.move(np.zeros(3), mode)
            t0 = sim.gauge_distances()
            sim.move(rho, mode)
            t = sim.gauge_distances() - t0
            stats["tcp"].append(np.max(np.abs(sim.tcp() - direct(machine, rho))))
            ok = np.isfinite(t) & np.isfinite(exact_t)
            stats["gauge"].extend(np.abs(t - exact_t)[ok])
            stats["rot"].append(sim.platform_orientation_error())
            stats["loop"].append(sim.loop_residual())
            stats["steps"].append(sim.last_settle_steps)
            agree += int(np.sum(np.isnan(t) == np.isnan(exact_t)))
            total += t.size
        sim.close()
    print(f"  validity agreement {preset}: {agree}/{total}")
    return {m: {k: np.asarray(v) for k, v in s.items()} for m, s in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=200)
    parser.add_argument("--presets", default="realistic,paper")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"settings: {PhysicsSettings()}")
    header = f"{'preset':10} {'mode':13} {'TCP max':>9} {'TCP med':>9} {'gauge max':>10} " \
             f"{'gauge med':>10} {'n gauge':>8} {'rot max':>9} {'loop max':>9} {'steps':>14}"
    rows = []
    for preset in args.presets.split(","):
        for mode, s in measure(preset, args.machines, args.seed).items():
            tcp = 1e3 * s["tcp"]
            rows.append(
                f"{preset:10} {mode:13} {tcp.max():9.2e} {np.median(tcp):9.2e}"
                f" {1e3 * s['gauge'].max():10.2e} {1e3 * np.median(s['gauge']):10.2e}"
                f" {s['gauge'].size:8d} {s['rot'].max():9.2e} {1e3 * s['loop'].max():9.2e}"
                f" {np.median(s['steps']):7.0f}/{s['steps'].max():<6.0f}"
            )
    print("errors in µm, rotation in rad")
    print(header)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
