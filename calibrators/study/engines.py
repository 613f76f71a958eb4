"""Where the chunks of a comparison run: in this process, over a local process pool, or
over a Ray cluster (the optional extra ``ray``).

Every engine calls the same function on the same items and yields each item with its
result as soon as it ends, so what a comparison computes never depends on the engine.
An interrupt (Ctrl-C) or an error stops the work still outstanding before it is raised.
"""

from __future__ import annotations

import gc
import os
import signal
import traceback
from collections.abc import Callable, Iterator
from contextlib import closing, contextmanager
from functools import partial
from importlib.util import find_spec
from multiprocessing import get_context
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from typing import Any, TypeVar

#: The engines, the first the default.
ENGINES: tuple[str, ...] = ("local", "ray")

#: What to run where Ray is missing.
RAY_INSTALL_HINT = "install the extra: pip install '.[ray]'"

#: Thread pools of the numerical libraries, limited to one thread in each worker: a
#: worker already has its core, and the pools' extra threads only spin on the other cores.
_THREAD_VARIABLES: tuple[str, ...] = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                      "MKL_NUM_THREADS")

Item = TypeVar("Item")
Result = TypeVar("Result")

#: How long (s) a stopped worker has to end before it is killed: a terminated one ends at
#: once, but one in a C extension that holds off the signal on a loaded machine may not.
STOP_GRACE_S: float = 5.0

#: Marks the end of the items (an item may be None).
_NONE = object()


def ray_available() -> bool:
    """Whether Ray can be imported (without importing it: that takes a second)."""
    return find_spec("ray") is not None


def worker_environment() -> dict[str, str]:
    """The thread settings of every worker: single-threaded pools, unless the user set
    a variable here, whose value then goes to the workers."""
    return {key: os.environ.get(key, "1") for key in _THREAD_VARIABLES}


@contextmanager
def _single_threaded() -> Iterator[None]:
    """Environment under which freshly spawned local workers start with
    :func:`worker_environment`."""
    saved = {k: os.environ.get(k) for k in _THREAD_VARIABLES}
    os.environ.update(worker_environment())
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


#: The youngest generation's threshold of the cyclic collector while :func:`imports_kept`
#: lasts (Python's default is 700 allocations): a chunk's records, readings and estimates,
#: hundreds of thousands of small objects, live until its trials are made, so the young
#: passes over them free nothing.
YOUNG_THRESHOLD: int = 20_000


@contextmanager
def imports_kept() -> Iterator[None]:
    """While it lasts, what the process holds at its start (the modules, their tables and
    caches) is out of the cyclic garbage collector's passes: it outlives the work, and each
    full pass of a long run would walk it again (a third of the collector's CPU in a
    1000-machine comparison, 2 % of the run); and the young passes run every
    :data:`YOUNG_THRESHOLD` allocations, not every 700.  Collects nothing and changes no
    result; after it, the collector sees everything again (a caller's own objects
    included) at its thresholds as they were."""
    thresholds = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(max(YOUNG_THRESHOLD, thresholds[0]), *thresholds[1:])
    try:
        yield
    finally:
        gc.set_threshold(*thresholds)
        gc.unfreeze()


def _ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the main process, which stops them: a terminal sends it to
    every process of the group, and each worker would print its own traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def results(function: Callable[..., Result], items: list[Item], jobs: int = 1,
            engine: str = "local", address: str | None = None,
            prepare: Callable[[], Any] | None = None) -> Iterator[tuple[Item, Result]]:
    """``(item, function(item))`` for every item, in the order they end.

    ``local`` runs them in this process (``jobs`` 1) or over ``jobs`` spawned processes;
    ``ray`` submits them as Ray tasks to the cluster at ``address`` (Ray's conventions:
    ``host:port``, ``ray://host:port``, ``auto`` for the latest cluster started on this
    machine; none given, ``RAY_ADDRESS``), or, with neither, to a local Ray instance of
    ``jobs`` CPUs started for the run.  ``function`` and the items must pickle.

    ``prepare``: what every item's call needs, made once before any of them, then handed
    to each as ``function(prepare(), item)``: in this process with ``jobs`` 1; over
    spawned processes, on the first worker while the others start and import what
    ``function`` needs, which then takes items as they do (no process is spawned and set
    up only to make it); for Ray, in one spawned local process (its workers' thread
    settings, :func:`worker_environment`).
    """
    if engine == "local":
        if jobs == 1:
            return _in_process(function if prepare is None else partial(function, prepare()),
                               items)
        return _pool(function, items, jobs, prepare)
    if engine == "ray":
        if not ray_available():
            raise RuntimeError(f"the ray engine needs Ray: {RAY_INSTALL_HINT}")
        if prepare is not None:
            with closing(_pool(_made, [prepare], 1)) as made:
                function = partial(function, next(made)[1])
        return _ray(function, items, jobs, address or os.environ.get("RAY_ADDRESS"))
    raise ValueError(f"unknown engine '{engine}'; choose from {list(ENGINES)}")


def _made(prepare: Callable[[], Result]) -> Result:
    """``prepare()``, a worker's item (:func:`results`' ``prepare``)."""
    return prepare()


def _in_process(function: Callable[[Item], Result], items: list[Item]
                ) -> Iterator[tuple[Item, Result]]:
    for item in items:
        yield item, function(item)


def _pool(function: Callable[..., Result], items: list[Item], jobs: int,
          prepare: Callable[[], Any] | None = None) -> Iterator[tuple[Item, Result]]:
    """A pool of spawned workers, each with a pipe of its own; ``prepare`` (see
    :func:`results`) made on the first, while the others import what ``function`` needs.

    Not :class:`concurrent.futures.ProcessPoolExecutor`: an interrupted comparison
    sometimes hung at exit in its threads and shared queues.  Here the parent alone
    talks to each worker, so stopping the workers and closing their pipes is the whole
    of the clean-up.
    """
    context = get_context("spawn")
    workers: list[tuple[BaseProcess, Connection]] = []
    todo = iter(items)
    busy: dict[Connection, Item] = {}
    try:
        with _single_threaded():
            for _ in range(min(jobs, len(items))):
                mine, theirs = context.Pipe()
                process = context.Process(target=_serve, args=(function, theirs), daemon=True)
                process.start()
                theirs.close()
                workers.append((process, mine))
        if prepare is not None and workers:
            workers[0][1].send((_PREPARE, prepare))
            prepared = _answer(workers[0][1])
            for _, connection in workers:
                connection.send((_BIND, prepared))
        for _, connection in workers:
            _hand(connection, todo, busy)
        while busy:
            for connection in wait(list(busy)):
                item = busy.pop(connection)
                value = _answer(connection)
                # The worker starts on its next item while this one is consumed.
                _hand(connection, todo, busy)
                yield item, value
    except BaseException:
        # Includes the consumer going away (GeneratorExit): no worker outlives the run.
        for process, _ in workers:
            process.terminate()
        raise
    finally:
        for process, connection in workers:
            connection.close()
            process.join(STOP_GRACE_S)
            if process.is_alive():
                process.kill()
                process.join()


def _answer(connection: Connection) -> Any:
    """The worker's result at ``connection``, or its error raised here."""
    try:
        done, value = connection.recv()
    except EOFError:
        raise RuntimeError("a worker process ended without an answer") from None
    if not done:
        error, remote = value
        raise error from RemoteTraceback(remote)
    return value


def _hand(connection: Connection, todo: Iterator[Item], busy: dict[Connection, Item]
          ) -> None:
    """Send the worker at ``connection`` the next item, if any is left."""
    item = next(todo, _NONE)
    if item is not _NONE:
        connection.send((_ITEM, item))
        busy[connection] = item


#: What a worker is sent: an item, the ``prepare`` of :func:`results` to make, or what
#: it made, to hand to the function before each item.
_ITEM, _PREPARE, _BIND = range(3)


def _serve(function: Callable[..., Result], connection: Connection) -> None:
    """A worker's loop: answer each item (and a ``prepare`` to make) with ``(True,
    result)`` or ``(False, (error, its traceback))`` until the parent closes the pipe."""
    _ignore_interrupts()
    with imports_kept():  # ``function`` came with its modules
        while True:
            try:
                kind, sent = connection.recv()
            except EOFError:
                return
            if kind == _BIND:
                function = partial(function, sent)
                gc.freeze()  # what was made outlives the items, as the function does
                continue
            try:
                answer = (True, sent() if kind == _PREPARE else function(sent))
            except Exception as error:
                # A traceback does not pickle: its text goes along.
                answer = (False, (error, traceback.format_exc()))
            connection.send(answer)


class RemoteTraceback(Exception):
    """The traceback of an error raised in a worker, shown as the cause of the error the
    parent raises again."""

    def __str__(self) -> str:
        return "\n" + self.args[0]


def _ray(function: Callable[[Item], Result], items: list[Item], jobs: int,
         address: str | None) -> Iterator[tuple[Item, Result]]:
    import ray

    # A caller that connected Ray itself keeps its session; otherwise the run opens one
    # and closes it at the end.
    own = not ray.is_initialized()
    # Per task, Ray adds these variables to those of the job's own runtime environment.
    runtime_env = {"env_vars": worker_environment()}
    if own and address:
        ray.init(address=address)
    elif own:
        # "local": a fresh instance sized for this run, never a cluster left running on
        # this machine (that one is --address auto).  Its workers, started with the
        # session, get the tasks' environment at once, instead of being replaced.
        ray.init(address="local", num_cpus=jobs, include_dashboard=False,
                 runtime_env=runtime_env)
    try:
        task = ray.remote(_apply).options(runtime_env=runtime_env)
        # One copy of the function (and all it binds) in the object store, not one a task.
        shared = ray.put(function)
        pending = {task.remote(shared, item): item for item in items}
        try:
            while pending:
                finished, _ = ray.wait(list(pending), num_returns=1)
                for ref in finished:
                    yield pending.pop(ref), ray.get(ref)
        except BaseException:
            # Not forced: a forced cancel racing a task's end aborted the driver (Ray
            # 2.60); an unforced one interrupts the running tasks and drops the queued.
            for ref in pending:
                ray.cancel(ref)
            raise
    finally:
        if own:
            ray.shutdown()


def _apply(function: Callable[[Item], Result], item: Item) -> Result:
    """The body of a Ray task (Ray resolves the shared function before the call)."""
    return function(item)
