"""Ctrl-C at any moment of a command: one line on stderr, the shell's status for SIGINT
(130), no traceback, and every trial finished so far kept.

The moments are chosen by events, not by waiting: an import hook sends the interrupt
when a given module starts loading (the command line's own first module, the
comparison's numerical libraries), and a comparison with two busy workers is
interrupted once its first trial is on disk.  The signal goes to the whole process group,
as a terminal sends it."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import as_a_terminal_job

from calibrators.study.trials import Trial

#: A hang guard only (the run is interrupted long before): never a timing assertion.
GUARD_S: float = 600.0

#: Runs the command line as ``python -m calibrators.cli`` does, with an import hook that
#: interrupts this process when module ``sys.argv[1]`` starts loading.
_HOOKED = textwrap.dedent("""
    import importlib.abc, os, runpy, signal, sys

    target = sys.argv[1]

    class Interrupt(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target_=None):
            if name == target:
                sys.meta_path.remove(self)
                os.kill(os.getpid(), signal.SIGINT)
            return None

    sys.meta_path.insert(0, Interrupt())
    sys.argv = ["orthoglide", *sys.argv[2:]]
    runpy.run_module("calibrators.cli", run_name="__main__", alter_sys=True)
""")

COMPARE = ["compare", "--agents", "paper", "--estimators", "paper6", "--quiet"]


def _environment() -> dict[str, str]:
    root = str(Path(__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}


@pytest.mark.parametrize("module", ["calibrators.cli.parser", "calibrators.cli.compare",
                                    "scipy", "gymnasium", "orthoglide_env.envs.vector"])
def test_ctrl_c_while_the_command_loads_is_one_line_and_130(module: str) -> None:
    """From the command line's first module to the comparison's libraries, and the lab's
    vector env, the last module a comparison loads: its first machines are being built."""
    run = subprocess.run([sys.executable, "-c", _HOOKED, module, *COMPARE,
                          "--machines", "5"], capture_output=True, text=True,
                         timeout=GUARD_S, env=_environment(), preexec_fn=as_a_terminal_job)
    assert run.returncode == 130, run.stderr
    assert "Traceback" not in run.stderr
    lines = run.stderr.strip().splitlines()
    # Before the command is known "orthoglide: interrupted"; once the run started
    # "orthoglide compare: interrupted after N trials", its own handler's line.
    assert len(lines) == 1, run.stderr
    assert re.fullmatch(r"orthoglide( compare)?: interrupted( after \d+ trials?)?", lines[0]), \
        run.stderr


def test_ctrl_c_with_busy_workers_keeps_the_finished_trials(tmp_path) -> None:
    """Two workers each on a machine of their own (one machine a chunk), the first
    trial written: the interrupt stops both, says how many trials it keeps in one line,
    and those are on disk, each whole, and ``--resume`` takes them up."""
    out = tmp_path / "run"
    trials = out / "trials.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "calibrators.cli", *COMPARE, "--machines", "400",
         "--jobs", "2", "--chunk", "1", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_environment(),
        start_new_session=True, preexec_fn=as_a_terminal_job)
    try:
        # The readiness marker: a finished trial on disk (the workers are then on the
        # next machines, of 400).
        while not (trials.exists() and trials.read_text().count("\n") >= 1):
            assert proc.poll() is None, proc.communicate()[1]
            try:
                proc.wait(0.05)
            except subprocess.TimeoutExpired:
                pass
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=GUARD_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("orthoglide compare: interrupted after"), stderr
    kept = [Trial.from_json(line) for line in trials.read_text().splitlines()]
    said = int(lines[0].split("after ")[1].split()[0])
    assert len(kept) == said >= 1
    # Fewer than all: the interrupt stopped the run, and the partial table was printed.
    assert len({t.machine for t in kept}) < 400 and stdout.strip()
    saved = json.loads((out / "config.json").read_text())
    assert saved["machines"] == 400
