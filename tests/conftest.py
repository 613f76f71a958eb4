"""Shared fixtures: seeded machines, the paper's row order of eq. (10) and its
experiment in the lab."""

from __future__ import annotations

import atexit
import contextlib
import functools
import io
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.cli import main
from calibrators.measurements import Measurements
from calibrators.study.episodes import Episode, run_episode
from orthoglide_env.instruments.dial import GaugeNoise, weighting_sigma
from orthoglide_env.model.design import PROTOTYPE


def _bytecode_for_this_run() -> None:
    """Where the environment forbids bytecode (``PYTHONDONTWRITEBYTECODE``, as container
    images set it), the workers and every child a test starts would compile NumPy, SciPy,
    Gymnasium and the package again, about 0.9 CPU-s a child that imports the command
    line: they write it instead to a folder of this run's own (``PYTHONPYCACHEPREFIX``,
    never into a shared environment), removed at its end.  ``make test`` unsets the
    variable and writes bytecode in place, and a run given a folder keeps it."""
    if not sys.flags.dont_write_bytecode or os.environ.get("PYTHONPYCACHEPREFIX"):
        return
    folder = tempfile.mkdtemp(prefix="orthoglide-bytecode-")
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    os.environ["PYTHONPYCACHEPREFIX"] = folder
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)  # absent where -B set the flag
    sys.pycache_prefix, sys.dont_write_bytecode = folder, False


_bytecode_for_this_run()


#: Rows of eq. (10) as (posture, index of the gauge in the paper layout).  The paper's
#: labels of rows 9-12 are misprinted (docs/estimators.md); these are the physical ones.
#: The paper's Table 1: the machine its experiment identified (mm).
TABLE1: dict[str, list[float]] = {"drho": [4.66, -5.36, 1.46], "dL": [5.20, -5.96, 3.16]}

#: The weighting sigma (mm) of the default dials (0.02 mm scatter read to 0.01 mm), as the
#: planners and the bound weigh a reading.
DIAL_SIGMA: float = float(weighting_sigma(GaugeNoise(0.02, 0.01).effective_sigma))

EQ10_ROWS: tuple[tuple[str, int], ...] = (
    ("YMax", 2), ("XMax", 0), ("YMin", 2), ("XMin", 0),
    ("ZMax", 5), ("YMax", 3), ("ZMin", 5), ("YMin", 3),
    ("ZMax", 4), ("XMax", 1), ("ZMin", 4), ("XMin", 1),
)  # fmt: skip


def paper_matrix() -> np.ndarray:
    """Eq. (10)'s 12x6 matrix, written from the paper's a_i, b_i, c_i formulas."""
    coef = []
    for limit in (PROTOTYPE.rho_max, PROTOTYPE.rho_min):
        alpha = np.arcsin(limit / PROTOTYPE.L)
        s, t, c = np.sin(alpha), np.tan(alpha), np.cos(alpha)
        coef.append((s, (0.5 + s) * t, (0.5 + s) / c - 0.5))
    (a1, b1, c1), (a2, b2, c2) = coef
    return np.array(
        [
            [a1, b1, 0, -c1, -b1, 0], [b1, a1, 0, -b1, -c1, 0],
            [a2, b2, 0, -c2, -b2, 0], [b2, a2, 0, -b2, -c2, 0],
            [0, a1, b1, 0, -c1, -b1], [0, b1, a1, 0, -b1, -c1],
            [0, a2, b2, 0, -c2, -b2], [0, b2, a2, 0, -b2, -c2],
            [a1, 0, b1, -c1, 0, -b1], [b1, 0, a1, -b1, 0, -c1],
            [a2, 0, b2, -c2, 0, -b2], [b2, 0, a2, -b2, 0, -c2],
        ]
    )  # fmt: skip


@pytest.fixture(autouse=True, scope="session")
def _learning_logs_under_pytest(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """stable-baselines3's default logger makes an empty ``SB3-<date>`` folder in the
    system's temporary directory at each ``learn``: the tests' go under pytest's own
    temporary directory, which pytest prunes."""
    patch = pytest.MonkeyPatch()
    patch.setenv("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3")))
    yield
    patch.undo()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture
def joint_samples(rng: np.random.Generator) -> np.ndarray:
    """Random control coordinates across the whole joint range."""
    return rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (500, 3))


def paper_experiment(machine: dict | None = None, seed: int = 0, **lab: Any
                     ) -> tuple[Episode, Any]:
    """The ``paper`` agent's episode in an exact-backend lab (``lab``: the lab's other
    arguments) on ``machine`` (a machine-file dict; default: drawn from the seed), and the
    lab it left (for its truth).  The world is the textbook's unless ``lab`` names other
    conditions: the paper's numbers are of that world."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, backend="exact",
                   **{"conditions": "ideal", **lab})
    try:
        episode = run_episode(env, get_agent("paper"), seed,
                              None if machine is None else {"machine": machine})
    finally:
        env.close()
    return episode, env.unwrapped


#: The warnings a child interpreter does not print by default (outside ``__main__``).
_UNSHOWN = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)


def command_here(argv: list[str]) -> subprocess.CompletedProcess:
    """``orthoglide ARGV`` run by ``main`` in this process, with the exit status (argparse's
    exit as its code), stdout and stderr that ``python -m calibrators.cli ARGV`` gives.  A
    warning the command raises is added to that stderr, as a child prints it; an exception
    the command lets through fails the test, where a child printed its traceback.  For a
    test of what a command does or refuses, not of its process: a child costs a CPU-second
    or two to import the command, and each command keeps tests that start one."""
    out, err = io.StringIO(), io.StringIO()
    with (warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out),
          contextlib.redirect_stderr(err)):
        warnings.simplefilter("always")
        try:
            status = main(argv)
        except SystemExit as ended:
            status = ended.code
    shown = "".join(f"{w.category.__name__}: {w.message}\n" for w in caught
                    if not issubclass(w.category, _UNSHOWN))
    return subprocess.CompletedProcess(argv, status, out.getvalue(), err.getvalue() + shown)


def assert_refused_in_one_line(path: Path, words: str, child: bool = True) -> None:
    """A bad reading file: reading it raises ``ValueError`` with ``words`` in one line, and
    ``fit`` ends with that one line on stderr and exit 2 (run as a ``child`` process, or
    in this one: :func:`command_here`)."""
    with pytest.raises(ValueError, match=re.escape(words)) as info:
        Measurements.read(path)
    assert "\n" not in str(info.value)
    done = (subprocess.run([sys.executable, "-m", "calibrators.cli", "fit", str(path)],
                           capture_output=True, text=True, check=False) if child
            else command_here(["fit", str(path)]))
    assert done.returncode == 2
    assert words in done.stderr and len(done.stderr.strip().splitlines()) == 1


ROOT = Path(__file__).resolve().parent.parent


@functools.cache
def script_help(script: str) -> subprocess.CompletedProcess:
    """``python SCRIPT --help`` (``script``: its path from the repository's top), run as a
    user runs it: from the top, the script's folder first on ``sys.path``.  Once per
    process: the scripts' own test and the documents' options ask the same."""
    return subprocess.run([sys.executable, script, "--help"], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)


def as_a_terminal_job() -> None:
    """A child's SIGINT at its default, as a terminal's foreground job has it: a shell
    starts background jobs with SIGINT ignored, and children inherit that (pass as
    ``preexec_fn``), so a Ctrl-C test holds wherever the suite was started."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def assert_batch_reads_as_alone(env_id: str, steps: list[dict[str, Any]], defaults: dict[str,
                                int], keys: tuple[str, ...], **kwargs: Any) -> dict:
    """The native vector env of ``env_id`` over machine seeds 3 and 7, stepped through
    ``steps`` (each with ``defaults`` for the keys it leaves out), observes at every step
    what two separate exact labs observe, key by key of ``keys``: its last observation."""
    seeds = [3, 7]
    envs = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    envs.reset(seed=seeds)
    lone = [gym.make(env_id, backend="exact", **kwargs) for _ in seeds]
    for env, seed in zip(lone, seeds, strict=True):
        env.reset(seed=seed)
    batched: dict = {}
    for step in steps:
        step = {**defaults, **step}
        batched = envs.step({k: np.array([v, v]) for k, v in step.items()})[0]
        alone = [env.step(step)[0] for env in lone]
        for key in keys:
            np.testing.assert_array_equal(batched[key], np.stack([a[key] for a in alone]))
    return batched


def refit_misfit(data: Measurements, kind: type, conditions: Any, name: str
                 ) -> tuple[int, float, bool]:
    """``active``'s refit of ``data`` told ``conditions`` (None: an ideal world): how many
    readings of the instrument ``kind`` (a gauge spec's class) it leaves out, the RMS (um)
    of those it keeps, and whether it warns that the ``name`` readings left out are the
    model's error."""
    from calibrators.agents.active import _refitter
    est = _refitter(0.02, conditions).fit(data)
    mine = np.flatnonzero([isinstance(m.gauge, kind) for m in data.items])
    kept = np.setdiff1d(mine, est.outliers)
    said = any(f"{name} readings left out" in w and "model's error" in w
               for w in est.warnings)
    rms_um = float(np.sqrt(np.mean(np.asarray(est.residuals)[kept] ** 2))) * 1e3
    return len(mine) - len(kept), rms_um, said


def tiny_maskable_policy(env: gym.Env, lab: dict[str, Any], path: Path) -> Path:
    """A MaskablePPO policy of ``env`` after one update of 64 steps, saved at ``path`` with
    the spec of ``lab`` to be played by its argmax: enough to check how a file plays, not
    how well (the caller skips first where sb3-contrib is absent)."""
    import sb3_contrib

    from calibrators.agents.policy import save_policy, spec_of
    model = sb3_contrib.MaskablePPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1,
                                    seed=0, device="cpu")
    model.learn(total_timesteps=64)
    return save_policy(model, path, spec_of(env, "MaskablePPO", lab, play="argmax"))


def assert_view_plays_as_lab(view: gym.Env, agent: Any, episode: Episode, seed: int) -> None:
    """``view``, stepped with ``agent``'s network's most likely open operation from a reset
    at ``seed``, reads what the lab episode ``episode`` of the ``policy:FILE`` agent read,
    reading for reading; more than a dozen of them, so it moved beyond Zero's first
    readings and the check is not vacuous."""
    observation, _ = view.reset(seed=seed)
    assert view.observation_space.contains(observation)
    done = False
    while not done:
        logits = agent.actor.logits(observation)
        chosen = int(np.argmax(np.where(view.action_masks(), logits, -np.inf)))
        observation, _, terminated, truncated, _ = view.step(chosen)
        done = terminated or truncated
    played = [(r.spec, r.rho, r.reading) for r in view.unwrapped.records]
    assert played == [(r.spec, r.rho, r.reading) for r in episode.records]
    assert len(played) > 12


def _module_fixtures(item: pytest.Item) -> set[tuple[str, str]]:
    """The fixtures of ``item``'s own module that outlive a test (scoped to the module or
    to the worker's session), each with its module's name (read from pytest's
    ``_fixtureinfo``: a fixture's scope has no public view on an item)."""
    defs = getattr(item, "_fixtureinfo", None)
    if defs is None:
        return set()
    module = item.nodeid.split("::")[0]
    return {(item.module.__name__, name) for name, chain in defs.name2fixturedefs.items()
            if chain and chain[-1].scope in ("module", "session")
            and chain[-1].baseid == module}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The tests marked ``slow`` run first, each in collection order, and with them the
    tests that share a module's fixture with one: the fixture is built once per worker,
    and scheduled apart a slow test's plan or sheet was built on both workers
    (`tests/test_plan.py`'s `optimal` plan, 20 CPU-s each when it was an hour's).  A
    module's costly fixtures are scoped to the worker's session: a worker that takes
    tests of a module from the other's queue (``--dist worksteal``) runs them apart from
    the module's others, and a module-scoped fixture, ended between, was built again
    (`tests/test_warm_bound.py`'s design, 7.7 CPU-s).
    Spread over workers (``make test``: ``-n auto``), the suite lasts as long as its
    busiest worker: a long test handed out last would keep one worker busy while the
    others idle, whereas started first it overlaps the many short ones.  ``make test``
    lets a worker that runs out take half of another's queue (``--dist worksteal``): the
    default's opening blocks gave every slow test to the first worker.  The order is only
    a schedule: no test depends on another having run."""
    shared = set().union(*(_module_fixtures(item) for item in items
                           if item.get_closest_marker("slow")))
    items.sort(key=lambda item: not (item.get_closest_marker("slow")
                                     or _module_fixtures(item) & shared))
