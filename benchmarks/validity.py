"""How large may a machine's errors be before the PyBullet machine and the exact model part?

For each parameter group and each error size, builds machines whose every error of that
group sits at +-size (random signs: the corners of the box, where the disagreement is
largest), the other groups zero, and compares the simulator with the exact model at random
postures across the joint cube and near Zero, and at the cube's corners: TCP, gauge
status (valid, no contact, overtravel, missed) and the readings (differences from Zero)
where both call them valid.  With ``--all`` every group sits at its size from ``--sizes``
at once (the corners of a candidate validity box).  The prototype's validity range
(``orthoglide_env/model/prototype.json``) was chosen from this output.

    python benchmarks/validity.py [--machines 10] [--groups drho,dL] [--sizes 1,5,10]
    python benchmarks/validity.py --all --sizes drho=15,dL=15,axis_tilt=0.02,...
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from orthoglide_env.instruments.dial import Status, status_of
from orthoglide_env.instruments.rays import exact_ray_distances
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import UnreachableError, direct
from orthoglide_env.sim.pybullet import OrthoglideMachine

#: Sizes tried per group when none are given (mm; rad for the tilts).
DEFAULT_SIZES: dict[str, tuple[float, ...]] = {
    "drho": (2, 5, 10, 20, 30, 50),
    "dL": (2, 5, 10, 20, 30, 50),
    "axis_tilt": (0.002, 0.005, 0.01, 0.02, 0.05, 0.1),
    "axis_offset": (0.5, 2, 5, 10, 20, 30),
    "attach": (0.3, 1, 2, 5, 10, 20),
}
SHAPES = {k: np.shape(v) for k, v in MachineParams().to_dict().items()}


#: The corners of the joint cube, reported apart: (60, 60, 60) lies near a singularity of
#: the machine, where the PyBullet machine sags under gravity while the exact model is rigid.
CORNERS = np.array(list(itertools.product((PROTOTYPE.rho_min, PROTOTYPE.rho_max), repeat=3)),
                   dtype=float)


def postures(rng: np.random.Generator, n_random: int) -> np.ndarray:
    """Random postures across the joint cube and near Zero (where the gauges read)."""
    return np.vstack([rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (n_random, 3)),
                      rng.uniform(-8, 8, (n_random, 3))])


def corner_machine(sizes: dict[str, float], rng: np.random.Generator) -> MachineParams:
    """A machine whose every error of the given groups is +-size (random signs)."""
    return MachineParams(**{k: v * rng.choice([-1.0, 1.0], SHAPES[k]) for k, v in sizes.items()})


def compare(machine: MachineParams, rhos: np.ndarray) -> dict[str, float]:
    """Worst TCP disagreement (mm) at ``rhos`` and at the cube's corners, worst
    gauge-difference disagreement (mm) and the count of failures."""
    gauges = install(PAPER_LAYOUT, machine)
    out = {"tcp": 0.0, "corner": 0.0, "gauge": 0.0, "validity": 0, "unreachable": 0,
           "build": 0}
    try:
        sim = OrthoglideMachine(machine, gauges)
    except (ValueError, RuntimeError):
        out["build"] = 1
        return out
    try:
        t0_sim = sim.gauge_distances()
        t0_exact = exact_ray_distances(machine, gauges, np.zeros(3))
        for k, rho in enumerate(np.vstack([rhos, CORNERS])):
            try:
                tcp = direct(machine, rho)
                t_exact = exact_ray_distances(machine, gauges, rho) - t0_exact
            except UnreachableError:
                out["unreachable"] += 1
                continue
            sim.move(rho)
            where = "tcp" if k < len(rhos) else "corner"
            out[where] = max(out[where], float(np.max(np.abs(sim.tcp() - tcp))))
            t_sim = sim.gauge_distances()
            status_sim = status_of(gauges, t_sim)
            status_exact = status_of(gauges, t_exact + t0_exact)
            out["validity"] += int(np.sum(status_sim != status_exact))
            # Readings, as the env reports them: where both sides call the gauge valid.
            ok = (status_sim == Status.VALID) & (status_exact == Status.VALID)
            if ok.any():
                gap = np.abs(t_sim - t0_sim - t_exact)[ok]
                out["gauge"] = max(out["gauge"], float(np.max(gap)))
    finally:
        sim.close()
    return out


def report(label: str, sizes: dict[str, float], machines: int, seed: int,
           n_random: int) -> None:
    rng = np.random.default_rng(seed)
    rows = [compare(corner_machine(sizes, rng), postures(rng, n_random))
            for _ in range(machines)]
    print(f"{label:44} TCP max {1e3 * max(r['tcp'] for r in rows):9.2e} µm  "
          f"at corners {1e3 * max(r['corner'] for r in rows):9.2e} µm  "
          f"gauge max {1e3 * max(r['gauge'] for r in rows):9.2e} µm  "
          f"status disagreements {sum(r['validity'] for r in rows):3d}  "
          f"unreachable {sum(r['unreachable'] for r in rows):3d}  "
          f"not built {sum(r['build'] for r in rows):2d}", flush=True)


def parse_sizes(text: str) -> dict[str, float]:
    pairs = (item.split("=") for item in text.split(","))
    return {key: float(value) for key, value in pairs}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=10)
    parser.add_argument("--random", type=int, default=8, help="random postures per machine "
                        "(and as many near Zero), besides the 8 corners of the joint cube")
    parser.add_argument("--groups", default=",".join(DEFAULT_SIZES))
    parser.add_argument("--sizes", default=None, help="comma-separated sizes for every "
                        "group, or with --all key=size pairs")
    parser.add_argument("--all", action="store_true", help="all groups at once")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.all:
        sizes = parse_sizes(args.sizes)
        report("all groups " + ", ".join(f"{k}={v:g}" for k, v in sizes.items()), sizes,
               args.machines, args.seed, args.random)
        return
    for group in args.groups.split(","):
        values = (DEFAULT_SIZES[group] if args.sizes is None
                  else tuple(float(s) for s in args.sizes.split(",")))
        for size in values:
            report(f"{group} = +-{size:g}", {group: size}, args.machines, args.seed,
                   args.random)


if __name__ == "__main__":
    main()
