"""Wall times of this tree against an earlier revision, in one run, with the outputs held
identical: the batched comparison, the command line's start-up, the ``active`` sweep and
the test suite.

    python benchmarks/speed_against_revision.py [--rev 02c124b] [--rounds 3]
        [--items compare,startup,active,suite] [--active-machines 100] [--same-as REV]

Each item times whole commands in fresh processes, this tree and ``REV`` taken in turns,
round after round, so a change of load hits both alike; the table gives each tree's median
wall time and the median of the rounds' ratios with their range, then the same of their CPU
seconds (user and system, of the command and every process it starts), which other work on
a loaded machine stretches far less than the wall time.  ``REV`` is checked out
into a temporary git worktree; both trees run from their own folder with their own code
first on ``PYTHONPATH`` (the same interpreter and packages), each compiled to bytecode
first as an installed package is, so the comparison is of the code alone.

=========  ============================================================================
item       what is timed, and what must come out the same
=========  ============================================================================
compare    ``orthoglide compare --agents paper --estimators paper6 --machines 1000
           --seed 1 --jobs 1 --conditions ideal --quiet``; its printed table, the run's
           seconds masked, must be the same bytes
startup    ``orthoglide --version``, beside ``python -c "import numpy"`` (the target is
           at most 2x numpy's)
active     ``benchmarks/bench_active.py``'s sweep (``active`` x ``extended``, lab, one
           hour, ``--jobs 2``); every trial (its readings, time and errors) must be the
           same bytes: the plans are identical
suite      ``CI=true make test`` in a fresh clone of each (HEAD and ``REV``): the wall
           time, the venv's build included, and the number of tests that passed; beside
           them the venv's wall time and the tests' CPU seconds
=========  ============================================================================

``REV``'s outputs may differ for reasons of their own (a warning's wording changed since):
``--same-as`` names a revision whose outputs must be this tree's to the byte (the one a
speed-up started from), run once per item beside the timed rounds.  The suite item clones
the committed HEAD, not the working tree, and takes minutes per round; it runs one round
whatever ``--rounds`` says.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
ITEMS = ("compare", "startup", "active", "suite")
COMPARE = ["compare", "--agents", "paper", "--estimators", "paper6", "--machines", "1000",
           "--seed", "1", "--jobs", "1", "--conditions", "ideal", "--quiet"]
#: What of the comparison's output depends on the run and not on the results: its seconds.
RUN_SECONDS = re.compile(r", [0-9.]+ s\. ")

#: The sweep of ``bench_active.py`` through ``calibrators.compare.run``, an interface both
#: trees have; prints a digest of every trial's JSON line.
ACTIVE = """
import hashlib, sys
from calibrators.compare import Config, run
from orthoglide_env.world.conditions import Conditions
machines = int(sys.argv[1])
config = Config(("active",), ("extended",), seed=1, conditions=Conditions("lab"))
trials = run(config, machines, jobs=2)
digest = hashlib.sha256("\\n".join(t.to_json() for t in trials).encode()).hexdigest()
print(digest)
"""


class Seconds(NamedTuple):
    """What a command took: wall seconds and CPU seconds (user and system, its own and its
    children's)."""

    wall: float
    cpu: float


def _env(tree: Path) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(tree))


def _timed(command: list[str], tree: Path, env: dict[str, str] | None = None
           ) -> tuple[Seconds, str]:
    """The seconds of ``command`` run in ``tree`` and what it printed."""
    start, cpu = time.perf_counter(), _children_cpu()
    out = subprocess.run(command, cwd=tree, env=env or _env(tree), check=True,
                         capture_output=True, text=True)
    return Seconds(time.perf_counter() - start, _children_cpu() - cpu), out.stdout


def compare(tree: Path, _: argparse.Namespace) -> tuple[Seconds, str]:
    seconds, out = _timed([sys.executable, "-m", "calibrators.cli", *COMPARE], tree)
    return seconds, RUN_SECONDS.sub(", (seconds) s. ", out)


def startup(tree: Path, _: argparse.Namespace) -> tuple[Seconds, str]:
    return _timed([sys.executable, "-m", "calibrators.cli", "--version"], tree)


def active(tree: Path, args: argparse.Namespace) -> tuple[Seconds, str]:
    return _timed([sys.executable, "-c", ACTIVE, str(args.active_machines)], tree)


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's ended children so far."""
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    return used.ru_utime + used.ru_stime


def suite(tree: Path, _: argparse.Namespace) -> tuple[Seconds, str]:
    """``CI=true make test`` in a fresh clone of ``tree``'s checked-out commit, its venv
    built first by make (the build's wall seconds apart: its share of the total); prints
    the number of tests that passed and the CPU seconds of the tests' part (lint, compile,
    pytest and its workers and the commands they start), which a loaded machine's wall
    time hides."""
    with tempfile.TemporaryDirectory() as tmp:
        clone = Path(tmp) / "clone"
        subprocess.run(["git", "-c", "advice.detachedHead=false", "clone", "--quiet", str(tree),
                        str(clone)], check=True)
        env = dict({k: v for k, v in os.environ.items()
                    if k not in ("PYTHONPATH", "VIRTUAL_ENV")}, CI="true")
        venv, _ = _timed(["make", ".venv/.installed"], clone, env)
        tests, out = _timed(["make", "test"], clone, env)
    passed = re.findall(r"(\d+) passed", out)
    return Seconds(venv.wall + tests.wall, venv.cpu + tests.cpu), (
        f"{passed[-1] if passed else '?'} passed (venv {venv.wall:.0f} s, tests "
        f"{tests.wall:.0f} s and {tests.cpu:.0f} CPU-s)")


RUNNERS: dict[str, Callable[[Path, argparse.Namespace], tuple[Seconds, str]]] = {
    "compare": compare, "startup": startup, "active": active, "suite": suite}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="02c124b", help="the earlier revision (git)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds per tree (>= 1)")
    parser.add_argument("--items", default=",".join(ITEMS),
                        help=f"comma list of {', '.join(ITEMS)} (default: all)")
    parser.add_argument("--active-machines", type=int, default=100,
                        help="machines of the active sweep (default %(default)s)")
    parser.add_argument("--same-as", default="",
                        help="a revision whose compare and active outputs must be this "
                             "tree's (default: none)")
    args = parser.parse_args()
    items = [i.strip() for i in args.items.split(",") if i.strip()]
    unknown = sorted(set(items) - set(ITEMS))
    if unknown or not items:
        parser.error(f"--items: unknown {unknown}; choose from {', '.join(ITEMS)}")
    if args.rounds < 1 or args.active_machines < 1:
        parser.error("--rounds and --active-machines must be >= 1")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        old, same = Path(tmp) / "rev", Path(tmp) / "same"
        trees = [(old, args.rev)] + ([(same, args.same_as)] if args.same_as else [])
        for tree, rev in trees:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "--quiet",
                            str(tree), rev], check=True)
        for tree in (ROOT, *(tree for tree, _ in trees)):
            _compiled(tree)
        try:
            for item in items:
                rows.append(_measure(item, old, 1 if item == "suite" else args.rounds, args,
                                     same if args.same_as else None))
        finally:
            for tree, _ in trees:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                str(tree)], check=True)
    print(f"load average {os.getloadavg()[0]:.1f}, {args.rounds} rounds; median wall and CPU "
          "seconds of each tree and the median of the rounds' ratios [their range]")
    print(f"{'item':<10}{'this tree':>11}{args.rev[:10]:>12}{'ratio':>8}  {'range':<14}"
          f"{'CPU this':>10}{'CPU ' + args.rev[:8]:>13}{'ratio':>8}  {'range':<14}check")
    for item, times, same in rows:
        cells = []
        for kind in Seconds._fields:
            new, was = (float(np.median([getattr(t, kind) for t in times[k]]))
                        for k in ("new", "old"))
            ratios = [getattr(a, kind) / getattr(b, kind)
                      for a, b in zip(times["new"], times["old"], strict=True)]
            spread = f"[{min(ratios):.2f}, {max(ratios):.2f}]"
            width = (11, 12) if kind == "wall" else (10, 13)
            cells.append(f"{new:{width[0]}.3f}{was:{width[1]}.3f}"
                         f"{float(np.median(ratios)):8.2f}  {spread:<14}")
        print(f"{item:<10}{''.join(cells)}{same}")


def _compiled(tree: Path) -> None:
    """``tree``'s packages compiled to bytecode, as an installed package's are: where
    ``PYTHONDONTWRITEBYTECODE`` is set (container images) every command timed would compile
    its tree's modules again, some 0.2 CPU-s of each start in both trees alike."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", "orthoglide_env", "calibrators"],
                   cwd=tree, check=True, stdout=subprocess.DEVNULL)


def _measure(item: str, old: Path, rounds: int, args: argparse.Namespace,
             same: Path | None = None) -> tuple[str, dict[str, list[Seconds]], str]:
    """``item`` timed in both trees in turns, ``rounds`` rounds: the seconds of each round
    in each tree (``new``: this one, ``old``) and what was checked.  The start-up's
    rounds also time ``python -c "import numpy"`` in turn, which its check compares with;
    ``same``: a tree whose outputs of compare and active must be this tree's."""
    times: dict[str, list[Seconds]] = {"new": [], "old": [], "numpy": []}
    outputs: dict[str, set[str]] = {"new": set(), "old": set()}
    for r in range(rounds):
        for name, tree in (("new", ROOT), ("old", old)):
            seconds, out = RUNNERS[item](tree, args)
            times[name].append(seconds)
            outputs[name].add(out)
        if item == "startup":
            times["numpy"].append(_timed([sys.executable, "-c", "import numpy"], ROOT)[0])
        print(f"{item}: round {r + 1}/{rounds} done", file=sys.stderr, flush=True)
    if item == "startup":
        numpy = [a.wall / b.wall for a, b in zip(times["new"], times["numpy"], strict=True)]
        check = (f"import numpy {float(np.median([t.wall for t in times['numpy']])):.3f} s: "
                 f"{float(np.median(numpy)):.2f}x it [{min(numpy):.2f}, {max(numpy):.2f}]")
    elif item == "suite":
        check = f"tests: {outputs['new'].pop()} / {outputs['old'].pop()}"
    else:
        mine = outputs["new"].pop() if len(outputs["new"]) == 1 else None
        digest = hashlib.sha256(str(mine).encode()).hexdigest()[:12]
        checks = [f"outputs {'the same' if mine is not None else 'DIFFER'} round to round "
                  f"(sha256 {digest})",
                  f"{'identical to' if outputs['old'] == {mine} else 'differ from'} "
                  f"{args.rev}'s"]
        if same is not None:
            agree = RUNNERS[item](same, args)[1] == mine
            checks.append(f"{'identical to' if agree else 'DIFFER FROM'} {args.same_as}'s")
        check = "; ".join(checks)
    return item, times, check


if __name__ == "__main__":
    main()
