"""Whether this tree's commands print and write the same bytes as an earlier revision's.

    python benchmarks/outputs_against_revision.py --rev REV [--keep DIR] [--only NAME,...]

A refactor must not change a result.  Each case below runs in both trees, each from an
empty folder of its own with its own code first on ``PYTHONPATH`` (the same interpreter
and packages); its standard output and every file it writes are compared byte for byte,
after masking what depends on the run and not on the results (wall seconds, the
interpreter's path).  ``REV`` is checked out into a temporary git worktree.  The exit
status is the number of cases that differ; ``--keep`` leaves both trees' outputs in DIR to
read with ``diff -r``.

The cases cover the commands a user runs: ``compare`` with every agent and estimator on
two machines under ideal and lab conditions, ``calibrate --json`` on both backends,
``fit`` with ``--holdout`` and ``--save-estimate``, ``plan``, ``plan --verify``,
``session`` through a pipe, ``compensate``, ``verify``, and ``examples/end_to_end.py``.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CLI = "{python} -m calibrators.cli"
AGENTS = "paper,paper-once,random,tracker,optimal,optimal-d,optimal-stay,active"
ESTIMATORS = "paper,paper6,extended,extended-base,extended-world,full"

#: The session's other side: a lab of the true machine (as calibrate builds it) answers
#: every reading the session asks for, stepped with each action it announces.
SESSION = """
import json, subprocess, sys
import gymnasium as gym, numpy as np
import orthoglide_env
from calibrators.experiment import machine_seed
env = gym.make(orthoglide_env.LAB_ENV_ID, errors="realistic", gauge_sigma=0.02,
               gauge_resolution=0.01, backend="exact", budget_s=600.0, conditions="ideal")
observation, _ = env.reset(seed=machine_seed(2, 0))
proc = subprocess.Popen([sys.executable, "-m", "calibrators.cli", "session", "--agent",
                        "active", "--budget", "600", "--seed", "2", "--conditions", "ideal",
                        "--out", "session",
                        "--json"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
for line in proc.stdout:
    print(line, end="")
    item = json.loads(line)
    if "action" in item:
        a = item["action"]
        observation, *_ = env.step({"op": int(a["op"]), "rho": np.array(a["rho"]),
                                    "stand": int(a["stand"]), "slot": int(a["slot"])})
    elif "ask" in item:
        k = item["ask"]["stand"] - 1
        value = float(observation["gauges"][k]) if observation["valid"][k] else None
        proc.stdin.write(json.dumps({"reading_mm": value}) + "\\n")
        proc.stdin.flush()
sys.exit(proc.wait())
"""

#: name -> shell lines, run in order in the case's own empty folder.
CASES: dict[str, list[str]] = {
    "compare-ideal": [f"{CLI} compare --agents {AGENTS} --estimators {ESTIMATORS} "
                      "--machines 2 --seed 1 --conditions ideal --jobs 1 --out out"],
    "compare-lab": [f"{CLI} compare --agents {AGENTS} --estimators {ESTIMATORS} "
                    "--machines 2 --seed 1 --conditions lab --jobs 1 --out out"],
    "calibrate": [f"{CLI} calibrate --seed 5 --backend exact --conditions ideal --json",
                  f"{CLI} calibrate --seed 5 --backend pybullet --conditions ideal --json",
                  f"{CLI} calibrate --seed 5 --conditions lab --agent active --params full "
                  "--json"],
    "fit": [f"{CLI} calibrate --seed 6 --conditions lab --agent optimal --params full "
            "--save-measurements readings.csv --save-truth truth.json",
            f"{CLI} fit readings.csv --conditions lab --holdout 0.2 --save-estimate est.json",
            f"{CLI} fit readings.csv --conditions lab --params extended --json",
            f"{CLI} plan --agent paper --conditions ideal --out plan",
            f"{CLI} plan --agent optimal --conditions lab --budget 1200 --out plan-lab",
            f"{CLI} plan --agent paper --verify est.json --conditions lab --out verify",
            "printf 'x,y,z\\n0,0,0\\n10,-20,5\\n-30,25,-15\\n' > targets.csv",
            f"{CLI} compensate est.json --targets targets.csv --out controller",
            f"{CLI} compensate est.json --targets targets.csv --out controller-json --json"],
    "session": ["{python} session.py"],
    "end-to-end": ["{python} {tree}/examples/end_to_end.py --out e2e"],
}
#: What depends on the run and not on its results.
MASKS = [(re.compile(rb"\b\d+(\.\d+)? ?s\b(?=[ .,)\]]|$)"), b"<s>"),
         (re.compile(rb'"(seconds|wall_s|elapsed_s)": [0-9.e+-]+'), rb'"\1": <s>')]


def _mask(data: bytes, tree: Path) -> bytes:
    data = data.replace(str(tree).encode(), b"<tree>")
    for pattern, replacement in MASKS:
        data = pattern.sub(replacement, data)
    return data


def run_case(name: str, tree: Path, folder: Path) -> None:
    """Run case ``name`` with ``tree``'s code in the empty ``folder``; its standard output
    goes to ``folder/stdout`` (every line's, in order), its standard error to ``stderr``."""
    folder.mkdir(parents=True)
    (folder / "session.py").write_text(SESSION)
    env = {**os.environ, "PYTHONPATH": str(tree), "CI": "true"}
    out = bytearray()
    for line in CASES[name]:
        command = line.format(python=sys.executable, tree=tree)
        done = subprocess.run(command, shell=True, cwd=folder, env=env, capture_output=True)
        out += f"$ {line}\n[{done.returncode}]\n".encode() + done.stdout
        (folder / "stderr").open("ab").write(done.stderr)
    (folder / "stdout").write_bytes(bytes(out))
    for path in folder.rglob("*"):
        if path.is_file():
            path.write_bytes(_mask(path.read_bytes(), tree))
    (folder / "stderr").unlink(missing_ok=True)


def _differences(a: Path, b: Path) -> list[str]:
    found = []
    files = {p.relative_to(a) for p in a.rglob("*") if p.is_file()}
    files |= {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    for rel in sorted(files):
        if not (a / rel).exists() or not (b / rel).exists():
            found.append(f"{rel}: only in {'this tree' if (a / rel).exists() else 'REV'}")
        elif not filecmp.cmp(a / rel, b / rel, shallow=False):
            found.append(f"{rel}: differs")
    return found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", required=True, help="the revision to compare against")
    parser.add_argument("--only", help=f"comma list of cases (default all: {','.join(CASES)})")
    parser.add_argument("--keep", type=Path, help="leave both trees' outputs in this folder")
    args = parser.parse_args()
    names = args.only.split(",") if args.only else list(CASES)
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}; the cases are {', '.join(CASES)}")
    scratch = Path(tempfile.mkdtemp(prefix="outputs-"))
    base = args.keep or scratch / "out"
    if args.keep and args.keep.exists():
        parser.error(f"--keep {args.keep} exists; give a new folder")
    old = scratch / "rev"
    subprocess.run(["git", "worktree", "add", "--detach", str(old), args.rev], cwd=ROOT,
                   check=True, capture_output=True)
    failed = 0
    try:
        for name in names:
            for label, tree in (("this", ROOT), ("rev", old)):
                print(f"{name}: {label} tree ...", file=sys.stderr, flush=True)
                run_case(name, tree, base / label / name)
            found = _differences(base / "this" / name, base / "rev" / name)
            failed += bool(found)
            print(f"{name:14s} {'same bytes' if not found else 'DIFFERS'}")
            for line in found:
                print(f"    {line}")
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT,
                       capture_output=True)
        if not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)
    return failed


if __name__ == "__main__":
    sys.exit(main())
