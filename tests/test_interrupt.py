"""Ctrl-C at any moment of a command: one line on stderr, the shell's status for SIGINT
(130), no traceback, and every trial finished so far kept; and a comparison's SIGTERM
likewise, with status 143.

The moments are chosen by events, not by waiting: an import hook sends the interrupt
when a given module starts loading (the command line's own first module, the
comparison's numerical libraries), and a comparison with two busy workers is
interrupted once its first trial is on disk.  Ctrl-C goes to the whole process group, as
a terminal sends it; SIGTERM to the command alone, as ``kill`` sends it."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import as_a_terminal_job, command_here

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


def _orthoglide(*argv: str) -> list[str]:
    return [sys.executable, "-m", "calibrators.cli", *argv]


def _wait_for_a_trial(proc: subprocess.Popen, trials: Path, stderr: Callable[[], str]
                      ) -> None:
    """Wait for the readiness marker, a finished trial on disk, while the run goes on (its
    ``stderr`` said if it ended first)."""
    while not (trials.exists() and trials.read_text().count("\n") >= 1):
        assert proc.poll() is None, stderr()
        try:
            proc.wait(0.05)
        except subprocess.TimeoutExpired:
            pass


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
        _orthoglide(*COMPARE, "--machines", "400", "--jobs", "2", "--chunk", "1", "--out",
                    str(out)),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_environment(),
        start_new_session=True, preexec_fn=as_a_terminal_job)
    try:
        # The workers are then on the next machines, of 400.
        _wait_for_a_trial(proc, trials, lambda: proc.communicate()[1])
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


#: Six machines of the ideal lab, each a chunk of its own and half a CPU-second of work
#: (the default agents and estimators, ten minutes of lab time: ``random`` plays to the
#: budget, the others stop before it): a stop sent once the first trial is written lands
#: while four or five machines are left.
SMALL = ["compare", "--conditions", "ideal", "--machines", "6", "--chunk", "1", "--seed",
         "2", "--budget", "600", "--quiet"]


def _workers_of_group(group: int) -> list[int]:
    """The process ids of the spawned workers of process group ``group`` that still run
    (not zombies): the group's resource tracker, which ends once its parent has, is none."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            # After the command's name in parentheses: state, parent, group.
            state, _, pgrp = stat.read_text().rsplit(")", 1)[1].split()[:3]
            command = (stat.parent / "cmdline").read_bytes()
        except OSError:  # ended meanwhile
            continue
        if int(pgrp) == group and state != "Z" and b"spawn_main" in command:
            found.append(int(stat.parent.name))
    return found


@pytest.fixture(scope="session")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The trials file of :data:`SMALL` run to its end in one job, in this process (the
    stopped runs are the commands' processes)."""
    out = tmp_path_factory.mktemp("uninterrupted") / "run"
    run = command_here([*SMALL, "--jobs", "1", "--out", str(out)])
    assert run.returncode == 0, run.stderr
    return (out / "trials.jsonl").read_bytes()


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the processes in /proc")
@pytest.mark.parametrize("jobs", [1, 2])
def test_sigterm_keeps_the_finished_trials_stops_the_workers_and_resumes(
        tmp_path: Path, jobs: int, uninterrupted: bytes) -> None:
    """SIGTERM to the command alone, as ``kill``, ``timeout`` and a batch scheduler send
    it, once its first trial is on disk: one line says how many trials it keeps and how to
    resume, the status is 143 (128 + 15), and no worker of the run still runs (stopped,
    not orphaned: ``kill`` reaches the command alone).  ``--resume`` then writes the trials of an
    uninterrupted run to the bit: the same bytes in one process; with two workers, which
    write their machines as they end, the same lines in some order."""
    out = tmp_path / "run"
    trials = out / "trials.jsonl"
    command = _orthoglide(*SMALL, "--jobs", str(jobs), "--out", str(out))
    # Files, not pipes: the workers would hold a pipe open, and its end wait for theirs.
    said_out, said_err = tmp_path / "stdout", tmp_path / "stderr"
    with said_out.open("w") as stdout_file, said_err.open("w") as stderr_file:
        proc = subprocess.Popen(command, stdout=stdout_file, stderr=stderr_file,
                                env=_environment(), start_new_session=True)
    try:
        _wait_for_a_trial(proc, trials, said_err.read_text)
        proc.send_signal(signal.SIGTERM)
        proc.wait(GUARD_S)
        left = _workers_of_group(proc.pid)  # as the command ends
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    stdout, stderr = said_out.read_text(), said_err.read_text()
    assert proc.returncode == 143, stderr
    assert not left, f"workers {left} outlived the stopped run"
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    said = re.fullmatch(r"orthoglide compare: stopped by SIGTERM after (\d+) trials; kept in "
                        r"(.+), continue with --resume", lines[0])
    assert said and Path(said[2]) == trials, stderr
    kept = [Trial.from_json(line) for line in trials.read_text().splitlines()]
    assert len(kept) == int(said[1]) >= 1
    assert stdout.strip()  # the partial table
    resumed = subprocess.run([*command, "--resume"], capture_output=True, text=True,
                             timeout=GUARD_S, env=_environment())
    assert resumed.returncode == 0, resumed.stderr
    if jobs == 1:
        assert trials.read_bytes() == uninterrupted
    else:
        assert sorted(trials.read_bytes().splitlines()) == sorted(uninterrupted.splitlines())


@pytest.mark.parametrize("signum, raised", [(signal.SIGTERM, "Stopped"),
                                             (signal.SIGINT, "KeyboardInterrupt")])
def test_a_stop_waits_until_the_trial_is_kept_in_memory_and_on_disk(
        signum: int, raised: str) -> None:
    """A signal that arrives while a trial is being kept (in the list the stop line counts
    and in the trials file) raises only once both hold it: raised between the two, the
    stop line counted one trial more than the file kept.  The signal is raised in this
    thread inside the held block (``raise_signal``: a signal sent to the process may be
    taken by another of its threads, such as a test worker's, and reach the handlers only
    after the block, which then held nothing); the statements after it must run, and the
    stop must come as the block ends, to the handler the run had installed.  SIGINT's is
    Python's own, as a command started from a terminal has it: a suite started as a
    background job inherits SIGINT ignored, and Python then installs none."""
    from calibrators.cli import compare

    kept: list[str] = []
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with compare._sigterm_stops():
            with pytest.raises(BaseException) as stop:
                with compare._signals_held():
                    signal.raise_signal(signum)
                    kept.append("in memory")
                    kept.append("on disk")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert type(stop.value).__name__ == raised
    assert kept == ["in memory", "on disk"]
