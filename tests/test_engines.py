"""Engines of the comparison: a Ray cluster computes what the local pool computes."""

from __future__ import annotations

import gc
import signal
import subprocess
import sys

import pytest

from calibrators.cli import main
from calibrators.study.compare import Config, run
from calibrators.study.engines import YOUNG_THRESHOLD, imports_kept


def test_ray_engine_gives_the_local_engines_trials(monkeypatch) -> None:
    """Four machines in two chunks as Ray tasks on the local Ray instance a run starts
    when given no cluster (two CPUs, shut down at the end): the same trials, bit for bit,
    as the default engine (here in this process, one chunk), each streamed once as it
    ends, with progress over every machine."""
    ray = pytest.importorskip("ray")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    config = Config(("paper",), ("paper",), budget_s=900.0, seed=5)
    local = run(config, 4)
    streamed, progress = [], []
    remote = run(config, 4, jobs=2, engine="ray", on_trial=streamed.append,
                 progress=progress.append)
    assert not ray.is_initialized()
    # JSON lines, as a run keeps them: NaN (a fixed parameter's std) equals itself there.
    assert [t.to_json() for t in remote] == [t.to_json() for t in local]
    assert sorted(t.machine for t in streamed) == [0, 1, 2, 3]
    assert progress == [2, 2]
    assert not any(t.failed for t in local)


def test_ray_engine_without_ray_is_one_line_and_status_2(monkeypatch, capsys) -> None:
    # A None entry in sys.modules is how Python marks a module as not importable.
    monkeypatch.setitem(sys.modules, "ray", None)
    assert main(["compare", "--machines", "1", "--engine", "ray"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("orthoglide compare: error: --engine ray needs Ray: install the extra: "
                   "pip install '.[ray]'")


def _thread_settings(_: int) -> tuple[str | None, ...]:
    """What a worker sees of the numerical libraries' thread variables."""
    import os

    from calibrators.study.engines import _THREAD_VARIABLES

    return tuple(os.environ.get(key) for key in _THREAD_VARIABLES)


def test_the_collector_is_as_it_was_after_a_command() -> None:
    # While a command runs, what was imported is frozen and the young passes are rarer;
    # after it, the caller's collector is as it was (its own thresholds, nothing frozen).
    before, frozen = gc.get_threshold(), gc.get_freeze_count()
    with imports_kept():
        assert gc.get_threshold()[0] == max(YOUNG_THRESHOLD, before[0])
        assert gc.get_threshold()[1:] == before[1:]
        assert gc.get_freeze_count() > frozen
    assert gc.get_threshold() == before and gc.get_freeze_count() == frozen


@pytest.mark.slow
def test_local_workers_start_single_threaded(monkeypatch) -> None:
    """Spawned workers get one thread per numerical library (or the user's setting): two
    workers with a multi-threaded BLAS each on two cores spin against each other (a
    comparison ran 2.5x slower).  The pool spawns its workers when the first result is
    asked for, so this checks the environment there, not where the generator was made."""
    from calibrators.study.engines import _THREAD_VARIABLES, results

    for key in _THREAD_VARIABLES:
        monkeypatch.delenv(key, raising=False)
    seen = [value for _, value in results(_thread_settings, [0, 1, 2, 3], jobs=2)]
    assert seen == [("1",) * len(_THREAD_VARIABLES)] * 4
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    seen = [value for _, value in results(_thread_settings, [0, 1], jobs=2)]
    assert all(value[_THREAD_VARIABLES.index("OPENBLAS_NUM_THREADS")] == "3" for value in seen)


def _fail_on_two(item: int) -> int:
    if item == 2:
        raise ValueError(f"item {item} is refused")
    return item


def test_a_worker_error_reaches_the_caller_with_its_traceback() -> None:
    """The worker's exception is raised in the parent, of its own type, and the worker's
    traceback goes with it as its cause."""
    from calibrators.study.engines import RemoteTraceback, results

    with pytest.raises(ValueError, match="item 2 is refused") as caught:
        list(results(_fail_on_two, [0, 1, 2, 3], jobs=2))
    assert isinstance(caught.value.__cause__, RemoteTraceback)
    assert "_fail_on_two" in str(caught.value.__cause__)


_INTERRUPTED_RUN = """
import time
from contextlib import closing
from calibrators.study.engines import results

def answer(item):
    # The second worker answers with 200 MB, far more than a pipe holds: it is still
    # sending when the run is interrupted.
    if item:
        time.sleep(0.3)
        return bytes(200_000_000)
    return b""

if __name__ == "__main__":
    with closing(results(answer, [0, 1], jobs=2)) as stream:
        for item, _ in stream:
            time.sleep(1.0)
            raise KeyboardInterrupt
"""


def test_an_interrupt_while_a_worker_sends_its_answer_ends_the_program(tmp_path) -> None:
    """Stopping a run while a worker is halfway through sending a large answer ends the
    program at once: nothing waits for the rest of the answer of a worker that was
    stopped.  (Behind a pool with threads of its own, a comparison interrupted this way
    once hung at exit.)  60 s is ten times what the run takes on two busy cores."""
    script = tmp_path / "interrupted.py"
    script.write_text(_INTERRUPTED_RUN)
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=60)
    # An uncaught KeyboardInterrupt ends Python by the signal itself.
    assert run.returncode == -signal.SIGINT and "KeyboardInterrupt" in run.stderr


def _pid() -> int:
    import os

    return os.getpid()


def _with_prepared(prepared: int, item: int) -> tuple[int, int]:
    import os

    return prepared, os.getpid()


def _refuse() -> None:
    raise ValueError("nothing to prepare")


def test_a_prepared_value_is_made_once_on_a_worker_that_then_takes_items() -> None:
    """``prepare`` runs once, on a spawned worker (not in the caller, whose BLAS may run
    threads of its own), and its value reaches every item's call; the worker that made it
    takes items as the others do, none spawned only to make it.  An error in it reaches
    the caller as an item's does."""
    import os

    from calibrators.study.engines import RemoteTraceback, results

    got = [value for _, value in results(_with_prepared, [0, 1, 2, 3], jobs=2, prepare=_pid)]
    made = {prepared for prepared, _ in got}
    assert len(made) == 1 and os.getpid() not in made
    assert made <= {pid for _, pid in got} and len({pid for _, pid in got}) == 2
    with pytest.raises(ValueError, match="nothing to prepare") as caught:
        list(results(_with_prepared, [0, 1], jobs=2, prepare=_refuse))
    assert isinstance(caught.value.__cause__, RemoteTraceback)
    # With one job, made here and handed to each item alike.
    assert [v for _, v in results(_with_prepared, [0, 1], prepare=_pid)] == [
        (os.getpid(), os.getpid())] * 2


def test_a_resumed_runs_progress_counts_each_machine_once() -> None:
    """A bar that starts at the machines ``done`` holds trials of (the command line's
    ``initial``) ends at the run's machines: progress counts only the others, though the
    resumed machine's chunk is handed out again; and the resumed run's trials are the
    whole run's."""
    config = Config(("paper",), ("paper",), budget_s=900.0, seed=5)
    whole = run(config, 3, chunk=1)
    progress: list[int] = []
    resumed = run(config, 3, done=[t for t in whole if t.machine == 0], chunk=1,
                  progress=progress.append)
    assert progress == [0, 1, 1]
    assert [t.to_json() for t in resumed] == [t.to_json() for t in whole]
