"""Monte-Carlo comparison of strategies over many random machines.

Every machine is drawn from a seed; each strategy runs its own experiment on a fresh
episode of that machine (same seed, so the same gauge installation and noise stream),
and is scored against the truth.  Work is spread over processes; the results are the
same whatever the number of processes.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, fields
from multiprocessing import get_context
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import orthoglide_env
from orthoglide_env.scoring import FRAMES, ScoreReport, score

from .base import PARAM_NAMES, PARAM_SETS, get_strategy
from .differences import differences
from .measurements import Measurements


@dataclass(frozen=True)
class Trial:
    """One strategy on one machine."""

    strategy: str
    machine: int
    param_error: np.ndarray  # (6,), estimate - truth, mm
    crlb: np.ndarray  # (6,), mm (NaN for fixed parameters)
    std: np.ndarray  # (6,), reported standard deviations, mm
    residual_rms: float
    nominal_residual_rms: float  # RMS of the differences: what the nominal model leaves
    experiment_time_s: float
    # TCP error RMS over the workspace grid (mm), uncompensated and compensated, in the
    # three frames of the scoring; the rigid frame is the headline.
    tcp_before_raw_rms: float
    tcp_before_translation_rms: float
    tcp_before_rigid_rms: float
    tcp_after_raw_rms: float
    tcp_after_translation_rms: float
    tcp_after_rigid_rms: float
    tcp_after_raw_max: float
    tcp_after_rigid_max: float


#: The TCP fields of a :class:`Trial`, in the order of its CSV columns.
TCP_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Trial) if f.name.startswith("tcp_"))


def _tcp_fields(report: ScoreReport) -> dict[str, float]:
    """A score's values for :data:`TCP_FIELDS`."""
    values = {f"tcp_{when}_{frame}_rms": getattr(frames, frame).rms
              for when, frames in (("before", report.tcp_before), ("after", report.tcp_after))
              for frame in FRAMES}
    values.update(tcp_after_raw_max=report.tcp_after.raw.max,
                  tcp_after_rigid_max=report.tcp_after.rigid.max)
    return values


@dataclass(frozen=True)
class Config:
    strategies: tuple[str, ...]
    errors: str
    sigma: float
    resolution: float
    backend: str
    params: str
    seed: int


def _failed(name: str, index: int) -> Trial:
    nan6 = np.full(6, np.nan)
    return Trial(name, index, nan6, nan6, nan6, *(np.nan,) * 3,
                 **dict.fromkeys(TCP_FIELDS, np.nan))


def run_machine(env: gym.Env, config: Config, index: int) -> list[Trial]:
    """Every strategy on machine ``index`` of the run, in ``env``.

    Strategies that share an experiment (``Calibrator.experiment_key``) share one
    measurement of it: the same seed would give them the same readings anyway."""
    seed = config.seed * 1_000_003 + index
    env.reset(seed=seed)
    sigma = env.unwrapped.gauge_noise.effective_sigma
    truth = env.unwrapped.true_machine
    fresh = True  # the episode has not moved yet
    measured: dict[str, Measurements | None] = {}
    trials = []
    for name in config.strategies:
        strategy = get_strategy(name)
        try:
            key = strategy.experiment_key
            if key not in measured:
                if not fresh:
                    env.reset(seed=seed)  # same machine, gauges and noise stream
                fresh = False
                measured[key] = None  # a failed experiment fails every strategy sharing it
                measured[key] = strategy.collect(env)
            data = measured[key]
            if data is None:
                raise RuntimeError("the shared experiment failed")
            est = strategy.estimate(data, config.params, sigma, verify=False)
        except (RuntimeError, ValueError):
            # A failed calibration is a result too: it counts, it does not stop the run.
            trials.append(_failed(name, index))
            continue
        report = score(est.machine, truth)
        free = list(PARAM_SETS[config.params])
        crlb, std = np.full(6, np.nan), np.full(6, np.nan)
        crlb[free] = est.crlb
        std[free] = np.sqrt(np.diag(est.covariance))
        trials.append(Trial(
            name, index, np.concatenate([est.drho - truth.drho, est.dL - truth.dL]),
            crlb, std, est.residual_rms_mm,
            float(np.sqrt(np.mean(differences(data).values ** 2))), est.experiment_time_s,
            **_tcp_fields(report),
        ))
    return trials


def run_chunk(config: Config, indices: range) -> list[Trial]:
    """Machines ``indices`` in one environment (building a PyBullet one costs ~70 ms)."""
    env = gym.make(orthoglide_env.ENV_ID, errors=config.errors, gauge_sigma=config.sigma,
                   gauge_resolution=config.resolution, backend=config.backend)
    try:
        return [t for i in indices for t in run_machine(env, config, i)]
    finally:
        env.close()


#: Thread pools of the numerical libraries, limited to one thread in each worker: a
#: worker already has its core, and the pools' extra threads only spin on the other cores
#: (measured on 2 cores: 100 machines in 9.6 s with them, 4.2 s without).
_THREAD_VARIABLES: tuple[str, ...] = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                      "MKL_NUM_THREADS")


@contextmanager
def _single_threaded() -> Iterator[None]:
    """Environment under which freshly spawned workers start single-threaded pools (the
    pools read it when numpy is first imported); a user's own setting wins."""
    saved = {k: os.environ.get(k) for k in _THREAD_VARIABLES}
    for key in _THREAD_VARIABLES:
        os.environ.setdefault(key, "1")
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


#: Machines per task sent to a worker: large enough to amortise the env, small enough for
#: a live progress bar and an even spread over the workers.
CHUNK: int = 10


def run(config: Config, machines: int, jobs: int | None = None,
        progress: bool = True) -> list[Trial]:
    """Run the comparison; ``jobs`` processes (default: every core).  The trials come in
    machine order, the same whatever ``jobs``."""
    jobs = jobs or os.cpu_count() or 1
    chunks = [range(i, min(i + CHUNK, machines)) for i in range(0, machines, CHUNK)]
    trials: list[Trial] = []
    bar = tqdm(total=machines, desc="machines", disable=not progress, unit="machine")
    if jobs == 1:
        for chunk in chunks:
            trials += run_chunk(config, chunk)
            bar.update(len(chunk))
    else:
        with _single_threaded(), ProcessPoolExecutor(jobs, mp_context=get_context("spawn")
                                                     ) as pool:
            futures = [pool.submit(run_chunk, config, chunk) for chunk in chunks]
            for chunk, future in zip(chunks, futures, strict=True):
                trials += future.result()
                bar.update(len(chunk))
    bar.close()
    return trials


def summary(trials: list[Trial]) -> list[dict[str, float | str]]:
    """Per strategy: median and 95th percentile of |parameter error| (over all freed
    parameters), TCP error RMS before and after calibration (median in every frame, the
    rigid one first, and its 95th percentile after), experiment time, and the ratio of the
    RMS error of each parameter to its Cramér-Rao bound (worst parameter shown)."""
    rows = []
    for name in dict.fromkeys(t.strategy for t in trials):
        everything = [t for t in trials if t.strategy == name]
        mine = [t for t in everything if np.isfinite(t.tcp_after_rigid_rms)]
        err = np.array([t.param_error for t in mine])
        free = ~np.isnan(mine[0].crlb)
        abs_err = np.abs(err[:, free])
        rms = np.sqrt(np.mean(err[:, free] ** 2, axis=0))
        crlb = np.sqrt(np.mean(np.array([t.crlb[free] for t in mine]) ** 2, axis=0))
        after = np.array([t.tcp_after_rigid_rms for t in mine])
        rows.append({
            "strategy": name,
            "machines": len(everything),
            "failed": len(everything) - len(mine),
            "param_err_median_mm": float(np.median(abs_err)),
            "param_err_p95_mm": float(np.percentile(abs_err, 95)),
            **{f"tcp_{when}_{frame}_rms_median_mm":
               float(np.median([getattr(t, f"tcp_{when}_{frame}_rms") for t in mine]))
               for when in ("before", "after") for frame in reversed(FRAMES)},
            "tcp_after_rigid_rms_p95_mm": float(np.percentile(after, 95)),
            "residual_rms_median_mm": float(np.median([t.residual_rms for t in mine])),
            "experiment_time_median_s": float(np.median([t.experiment_time_s for t in mine])),
            "rms_over_crlb_worst": float(np.max(rms / crlb)),
            "rms_over_crlb_best": float(np.min(rms / crlb)),
        })
    return rows


def write_outputs(trials: list[Trial], rows: list[dict], out: Path) -> list[Path]:
    """CSV of every trial and of the summary, and PNG plots, in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    trial_csv = out / "trials.csv"
    with trial_csv.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["strategy", "machine", *(f"err_{n}" for n in PARAM_NAMES),
                         *(f"crlb_{n}" for n in PARAM_NAMES), *TCP_FIELDS, "residual_rms",
                         "nominal_residual_rms", "experiment_time_s"])
        for t in trials:
            writer.writerow([t.strategy, t.machine, *t.param_error, *t.crlb,
                             *(getattr(t, key) for key in TCP_FIELDS), t.residual_rms,
                             t.nominal_residual_rms, t.experiment_time_s])
    summary_csv = out / "summary.csv"
    with summary_csv.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return [trial_csv, summary_csv, *_plots(trials, out)]


def _plots(trials: list[Trial], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    names = list(dict.fromkeys(t.strategy for t in trials))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for name in names:
        mine = [t for t in trials if t.strategy == name and np.isfinite(t.tcp_after_rigid_rms)]
        err = np.array([t.param_error for t in mine])
        axes[0].plot(PARAM_NAMES, np.sqrt(np.nanmean(err**2, axis=0)), "o-", label=f"{name} RMS")
        crlb = np.sqrt(np.mean(np.array([t.crlb for t in mine]) ** 2, axis=0))
        axes[0].plot(PARAM_NAMES, crlb, "x--", label=f"{name} CRLB")
    axes[0].set_ylabel("parameter error (mm)")
    axes[0].set_title("RMS parameter error vs Cramér-Rao bound")
    axes[0].legend(fontsize=8)
    before = [t.tcp_before_rigid_rms for t in trials if t.strategy == names[0]
              and np.isfinite(t.tcp_before_rigid_rms)]
    data = [before] + [[t.tcp_after_rigid_rms for t in trials if t.strategy == n
                        and np.isfinite(t.tcp_after_rigid_rms)] for n in names]
    axes[1].boxplot(data, tick_labels=["uncalibrated", *names])
    axes[1].set_yscale("log")
    axes[1].set_ylabel("TCP error RMS after best-fit rigid motion (mm)")
    axes[1].set_title("Positioning accuracy")
    fig.tight_layout()
    path = out / "compare.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]
