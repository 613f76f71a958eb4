"""Throughput of the calibration env against an earlier revision of the project, in one run.

    python benchmarks/against_revision.py --rev REV [--envs 1,500] [--rounds 5]
        [--seconds 2.0]

Both trees are timed by the same probe in fresh processes, taken in turns (this tree,
then ``REV``, round after round), so a change of load on the machine hits both alike; the
table gives each tree's median steps/s (machine-steps: a vector step of N envs counts N)
and the ratio of this tree's median to ``REV``'s.  ``REV`` is checked out into a
temporary git worktree and imported ahead of the installed package (``PYTHONPATH``); the
probe prints the file it imported, so a run that timed the wrong tree says so.

The probe uses only what every revision since the conditions (``6a01dcd``) offers:
``gym.make(ENV_ID, backend="exact", conditions="ideal")`` for N = 1 (the textbook world,
the default before issue 37), the native vector entry point otherwise,
small random moves around Zero as in a calibration (``bench_vector.py``), autoresets
included.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import json, sys, time
import gymnasium as gym
import numpy as np
import orthoglide_env
n, seconds = int(sys.argv[1]), float(sys.argv[2])
if n == 1:
    env = gym.make(orthoglide_env.ENV_ID, backend="exact", conditions="ideal")
    env.reset(seed=0)

    def step(a):
        if any(env.step(a[0])[2:4]):
            env.reset()
else:
    env = gym.make_vec(orthoglide_env.ENV_ID, num_envs=n,
                       vectorization_mode="vector_entry_point", backend="exact",
                       conditions="ideal")
    env.reset(seed=0)
    step = env.step
rng = np.random.default_rng(0)
actions = rng.uniform(-8, 8, (64, n, 3))
for a in actions[:4]:
    step(a)
steps, start = 0, time.perf_counter()
while time.perf_counter() - start < seconds:
    step(actions[steps % len(actions)])
    steps += 1
rate = steps * n / (time.perf_counter() - start)
print(json.dumps({"file": orthoglide_env.__file__, "rate": rate}))
"""


def probe(tree: Path, n: int, seconds: float) -> float:
    """Steps/s of ``n`` calibration envs imported from ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", PROBE, str(n), str(seconds)], env=env,
                         check=True, capture_output=True, text=True, cwd=tree)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    imported = Path(result["file"]).resolve()
    if tree.resolve() not in imported.parents:
        raise RuntimeError(f"the probe of {tree} imported {imported}")
    return float(result["rate"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", required=True, help="the earlier revision (git)")
    parser.add_argument("--envs", default="1,500",
                        help="comma-separated numbers of envs (1: the single env)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds per tree (>= 1)")
    parser.add_argument("--seconds", type=float, default=2.0,
                        help="timed seconds per probe (> 0)")
    args = parser.parse_args()
    sizes = [int(s) for s in args.envs.split(",")]
    if args.rounds < 1 or args.seconds <= 0 or min(sizes) < 1:
        parser.error("--rounds and every --envs entry must be >= 1, --seconds > 0")
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "rev"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "--quiet",
                        str(old), args.rev], check=True)
        try:
            rates: dict[tuple[str, int], list[float]] = {}
            for r in range(args.rounds):
                for n in sizes:
                    for name, tree in (("this tree", ROOT), (args.rev, old)):
                        rates.setdefault((name, n), []).append(probe(tree, n, args.seconds))
                print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(old)], check=True)
    print(f"load average {os.getloadavg()[0]:.1f}, {args.rounds} rounds of "
          f"{args.seconds:g} s, median steps/s")
    print(f"{'envs':>6}{'this tree':>12}{args.rev[:10]:>12}{'ratio':>8}")
    for n in sizes:
        new, was = (float(np.median(rates[(k, n)])) for k in ("this tree", args.rev))
        print(f"{n:6d}{new:12.0f}{was:12.0f}{new / was:8.2f}")


if __name__ == "__main__":
    main()
