"""``orthoglide compare``: agents x estimators on the same random machines, equal budget."""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from calibrators.agents import available as agents_available
from calibrators.agents import get_agent
from calibrators.cli.common import (
    UsageError,
    add_conditions,
    add_design,
    add_faults,
    add_instruments,
    add_thermometer,
    conditions_of,
    faults_of,
    fit_conditions_of,
    instruments_of,
    machine_design_of,
)
from calibrators.cli.parser import listing
from calibrators.estimators.catalogue import CATALOGUE, exact_estimators, get_estimator
from calibrators.study.compare import CHUNK, Config, Trial, run, study_bound
from calibrators.study.engines import ENGINES, RAY_INSTALL_HINT, ray_available
from calibrators.study.episodes import DEFAULT_BUDGET_S
from calibrators.study.statistics import paired, summary, warning_title
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import DEFAULT_PRESET, PRESETS
from orthoglide_env.scoring import FRAMES
from orthoglide_env.world.conditions import EFFECT_NAMES

if TYPE_CHECKING:
    from calibrators.planning.bound import Bound

TRIALS_FILE = "trials.jsonl"
#: Most processes a run may ask for: beyond the cores they only compete.
MAX_JOBS = 256


class Stopped(BaseException):
    """SIGTERM, what ``kill``, ``timeout`` and a batch scheduler send, received while a
    comparison runs: raised where the run is, as Ctrl-C raises KeyboardInterrupt, so that
    it stops the workers and keeps the finished trials as an interrupt does (not an
    Exception: no ``except Exception`` of the run may take it for a failed fit)."""


def _stop(signum: int, frame: object) -> None:
    raise Stopped


@contextmanager
def _sigterm_stops() -> Iterator[None]:
    """While it lasts, SIGTERM raises :class:`Stopped` instead of ending the process
    where it is, the chunk's workers left running and its finished trials unwritten."""
    previous = signal.signal(signal.SIGTERM, _stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def _signals_held() -> Iterator[None]:
    """While it lasts, SIGINT and SIGTERM wait: each that arrives is raised again as it
    ends, to the handler it would have met."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    held = {s: h for s, h in handlers.items() if callable(h)}
    for s in held:
        signal.signal(s, lambda signum, _frame: arrived.append(signum))
    try:
        yield
    finally:
        for s, handler in held.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(arrived):
            signal.raise_signal(s)


def _names(text: str, option: str) -> tuple[str, ...]:
    names = tuple(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    if not names:
        raise UsageError(f"{option} needs at least one name")
    return names


def _check(args: argparse.Namespace) -> Config:
    agents = _names(args.agents, "--agents")
    for name in agents:
        get_agent(name)  # a ValueError names the known agents, or why a policy cannot run
    estimators = _names(args.estimators, "--estimators")
    for name in estimators:
        get_estimator(name)
    rules = (
        (1 <= args.machines <= 1_000_000, "--machines must be between 1 and 1000000"),
        (0 <= args.seed < 2**32, "--seed must be between 0 and 2**32 - 1"),
        (np.isfinite(args.budget) and 0 < args.budget <= 1e6,
         "--budget must be a number of seconds in (0, 1e6]"),
        (np.isfinite(args.success_mm) and args.success_mm > 0,
         "--success-mm must be a positive number of mm"),
        (1 <= args.jobs <= MAX_JOBS, f"--jobs must be between 1 and {MAX_JOBS}"),
        (1 <= args.chunk <= 1_000_000, "--chunk must be between 1 and 1000000"),
        (0 <= args.verify_pybullet <= 1000, "--verify-pybullet must be between 0 and 1000"),
        (args.engine != "ray" or ray_available(), f"--engine ray needs Ray: {RAY_INSTALL_HINT}"),
        (not args.address or args.engine == "ray", "--address is the Ray cluster of --engine ray"),
        (not args.resume or args.out, "--resume continues the run kept in --out: give --out"),
    )
    for ok, problem in rules:
        if not ok:
            raise UsageError(problem)
    instruments = instruments_of(args, tuple(get_agent(name) for name in agents))
    # The gauge noise was checked with every command's (calibrators.cli.run).
    sigma, resolution = (0.0, 0.0) if args.noise_free else (args.sigma, args.resolution)
    conditions = conditions_of(args)
    return Config(agents, estimators, args.budget, args.errors, sigma, resolution,
                  args.backend, args.seed, args.success_mm,
                  curve_estimator=_curve_estimator(estimators) if args.out else "",
                  design=machine_design_of(args), conditions=conditions,
                  thermometer=args.thermometer, instruments=instruments,
                  faults=faults_of(args),
                  fit_conditions=None if args.fit_conditions is None
                  else fit_conditions_of(args, conditions), world_check=args.check_world,
                  bound=args.bound)


def _curve_estimator(estimators: tuple[str, ...]) -> str:
    """The estimator of the accuracy-versus-time curve: ``extended`` reads every agent's
    instruments, so it draws every curve; otherwise the first one."""
    return "extended" if "extended" in estimators else estimators[0]


def _prepare_out(args: argparse.Namespace, config: Config) -> tuple[Path | None, list[Trial]]:
    """The output folder, checked before any work, and the trials a resumed run has."""
    if not args.out:
        return None, []
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} exists and is not a folder")
    trials_path = out / TRIALS_FILE
    config_path = out / "config.json"
    if args.resume:
        if not trials_path.exists():
            raise UsageError(f"nothing to resume: {trials_path} does not exist")
        saved = json.loads(config_path.read_text()) if config_path.exists() else None
        if saved is not None:  # a run kept before conditions existed ran in the ideal world
            saved.setdefault("conditions", "ideal")
            saved.setdefault("effects", [])
            saved.setdefault("indicator", "dial")
        if saved is not None and "thermometer" not in saved:
            # A run kept before the thermometer existed had none, and its error, which
            # draws nothing without one, was not yet among a condition's effects.
            saved["thermometer"] = False
            if saved["effects"] == [e for e in EFFECT_NAMES if e != "thermometer"]:
                saved["effects"] = list(EFFECT_NAMES)
        if saved != _config_dict(config, args.machines):
            raise UsageError(f"--resume needs the options of the run in {out} "
                             f"({config_path}): they differ")
        done, lines = [], trials_path.read_text().splitlines()
        for n, line in enumerate(lines, start=1):
            try:
                done.append(Trial.from_json(line))
            except (ValueError, TypeError) as exc:
                # The last line of an interrupted run may be cut short: drop it.
                if n < len(lines):
                    raise UsageError(f"{trials_path}:{n}: not a trial ({exc})") from None
        return out, done
    if trials_path.exists():
        raise UsageError(f"{out} already holds a run: use --resume, or another --out")
    out.mkdir(parents=True, exist_ok=True)
    config_path.write_text(json.dumps(_config_dict(config, args.machines)) + "\n")
    return out, []


def _config_dict(config: Config, machines: int) -> dict:
    data = dict(vars(config))
    data.update(agents=list(config.agents), estimators=list(config.estimators),
                machines=machines)
    # The prototype is left out, so that the runs kept before designs existed resume.
    design = data.pop("design")
    if design != PROTOTYPE:
        data["design"] = design.to_dict()
    if not data["instruments"]:
        del data["instruments"]  # today's lab: runs kept before instruments resume
    else:
        data["instruments"] = list(data["instruments"])
    faults = data.pop("faults")
    if faults.active:  # a run without faults keeps the config a run before them kept
        data["faults"] = list(faults.kinds)
    conditions = data.pop("conditions")
    data.update(conditions=conditions.name, effects=list(conditions.effects),
                indicator=conditions.indicator)
    if conditions.drives != "screw":
        data["drives"] = conditions.drives
    # Left out when off, so that the runs kept before they existed resume.
    told = data.pop("fit_conditions")
    if told is not None:
        data["fit_conditions"] = getattr(told, "label", told)
    if data.pop("world_check"):
        data["world_check"] = True
    if data.pop("bound"):
        data["bound"] = True
    return data


def run_command(args: argparse.Namespace) -> None:
    config = _check(args)
    out, done = _prepare_out(args, config)
    handle = (out / TRIALS_FILE).open("a") if out else None
    collected: list[Trial] = list(done)

    def keep(trial: Trial) -> None:
        # A stop between the list and the file would say one trial more or fewer than
        # the file keeps: the signals wait until both hold it.
        with _signals_held():
            collected.append(trial)
            if handle:
                handle.write(trial.to_json() + "\n")
                handle.flush()

    bar = None
    if not (args.quiet or args.json):
        from tqdm import tqdm  # imported for a bar that is shown only

        bar = tqdm(total=args.machines, initial=len({t.machine for t in done}),
                   desc="machines", unit="machine", file=sys.stderr)
    start = time.perf_counter()
    try:
        with _sigterm_stops():
            trials = run(config, args.machines, args.jobs, done, on_trial=keep,
                         progress=None if bar is None else bar.update, engine=args.engine,
                         address=args.address, chunk=args.chunk)
    except KeyboardInterrupt:
        trials, stopped_by = None, signal.SIGINT
    except Stopped:
        trials, stopped_by = None, signal.SIGTERM
    finally:
        if bar is not None:
            bar.close()
        if handle:
            handle.close()
    if trials is None:
        said = "interrupted" if stopped_by == signal.SIGINT else "stopped by SIGTERM"
        print(f"orthoglide compare: {said} after {len(collected)} trials"
              + (f"; kept in {out / TRIALS_FILE}, continue with --resume" if out else ""),
              file=sys.stderr)
        # The table so far at once: the bound's minute or two is not what a stop asks for.
        _print(collected, dataclasses.replace(config, bound=False),
               len({t.machine for t in collected}), time.perf_counter() - start, args.json)
        # The shell's status for a process the signal ended: 130 for SIGINT, 143 for SIGTERM.
        raise SystemExit(128 + stopped_by)
    rows = _print(trials, config, args.machines, time.perf_counter() - start, args.json)
    if args.verify_pybullet:
        from calibrators.study.crosscheck import verify_pybullet

        gaps = verify_pybullet(config, min(args.verify_pybullet, args.machines))
        print(f"PyBullet check of {min(args.verify_pybullet, args.machines)} machine(s), "
              f"every agent, {gaps['steps']} steps with ideal gauges: largest reading "
              f"difference {1e3 * gaps['reading_mm']:.3g} µm, TCP {1e3 * gaps['tcp_mm']:.3g} µm",
              file=sys.stderr if args.json else sys.stdout)
    if out:
        for path in _write(trials, rows, out, config):
            print(f"wrote {path}", file=sys.stderr if args.json else sys.stdout)


def _print(trials: list[Trial], config: Config, machines: int, seconds: float,
           as_json: bool) -> list[dict]:
    """Print the summary of ``trials`` (and the paired comparisons of its agents) as text,
    or as JSON holding the same text's table and warning lines beside the numbers; return
    its rows."""
    rows, pairs = summary(trials, config.target_mm, config.faults.active), paired(trials)
    bound = study_bound(config) if config.bound else None
    for row in rows if bound else ():
        row["bound_mm"] = bound.bound_mm
    table, warnings, pair_lines = _lines(rows, pairs, config, machines, seconds)
    if bound:
        table += _bound_lines(rows, bound)
    if as_json:
        print(json.dumps({"config": _config_dict(config, machines), "world": config.world,
                          "rows": rows, "paired": pairs,
                          **({"bound": bound.to_dict()} if bound else {}),
                          "table": table, "warnings": warnings, "paired_table": pair_lines},
                         allow_nan=False))
        return rows
    print("\n".join(table + warnings + pair_lines))
    return rows


def _lines(rows: list[dict], pairs: list[dict], config: Config, machines: int,
           seconds: float) -> tuple[list[str], list[str], list[str]]:
    """The text of the summary: the table (its heading, header and one line per row), the
    warnings (failed fits, each kind of warning with an example, a hint), and the paired
    comparisons."""
    table = [
        f"{machines} machines ({config.world}), {seconds:.1f} s. TCP error "
        "RMS over the workspace after calibration (mm), median over machines with its "
        "95 % interval; rigid = after the best-fit rigid motion (the headline), raw = "
        "world frame; a failed trial counts as its uncalibrated machine; success: rigid "
        f"error against the truth <= {config.target_mm:g} mm (predicted: by the estimate "
        "itself)"]
    # Wide enough for the longest agent name (a policy file's, AGENT+reference).
    width = max([10, *(len(r["agent"]) + 1 for r in rows)])
    table.append(f"{'agent':{width}}{'estimator':15}{'TCP after (rigid) med':>22}"
                 f"{'95 % interval':>18}{'p95':>9}{'(raw) med':>11}{'time s med':>11}"
                 f"{'z-RMS':>8}{'chi2 rej':>9}{'success':>9}{'predicted':>10}{'failed':>8}")
    for r in rows:
        rigid, raw = r["tcp_after_mm"]["rigid"], r["tcp_after_mm"]["raw"]
        interval = (f"[{rigid['ci95'][0]:.4f}, {rigid['ci95'][1]:.4f}]" if rigid["ci95"]
                    else "-")
        table.append(
            f"{r['agent']:{width}}{r['estimator']:15}{_show(rigid['median'], 22, 4)}"
            f"{interval:>18}{_show(rigid['p95'], 9, 4)}{_show(raw['median'], 11, 3)}"
            f"{r['time_s']['median']:11.0f}{_show(r['z_rms'], 8, 2)}"
            f"{_show(r['chi2_rejected'], 9, 2)}{r['success_rate']:9.0%}"
            f"{r['predicted_success_rate']:10.0%}{r['failed']:8d}")
    warnings = []
    for r in rows:
        if r["failed"]:
            warnings.append(f"{r['agent']} x {r['estimator']}: {r['failed']} of "
                            f"{r['machines']} failed ({r['failure']}), counted as uncalibrated")
        if "faults_detected" in r:
            detected = r["faults_detected"]
            warnings.append(f"{r['agent']} x {r['estimator']}: faults named in "
                            + ("no trial with a fault" if detected is None
                               else f"{detected:.0%} of the trials with one")
                            + "; silent failures (off by > 3 sigma, no warning) "
                            f"{r['silent_failures']:.1%}")
        for kind, seen in r["warnings"].items():
            example = seen["example"].split(":", 1)[-1].strip()
            example = example if len(example) <= 110 else example[:107] + "..."
            warnings.append(f"{r['agent']} x {r['estimator']}: {seen['trials']} of "
                            f"{r['machines']} fits warn: {warning_title(kind)} "
                            f"(e.g. {example})")
    exact = exact_estimators()
    if any(r["failed"] and r["estimator"] not in exact for r in rows):
        warnings.append(f"the exact-model estimators read any agent's readings: --estimators "
                        f"{','.join(exact)}")
    pair_lines = []
    if pairs:
        pair_lines.append("paired on the same machines: median ratio of the TCP errors after "
                          "rigid motion (agent / against; below 1 the agent is better) with "
                          "its 95 % interval, and the agent's win rate")
        for pair in pairs:
            interval = (f"[{pair['ratio_ci95'][0]:.3f}, {pair['ratio_ci95'][1]:.3f}]"
                        if pair["ratio_ci95"] else "-")
            pair_lines.append(
                f"  {pair['estimator']:15}{pair['agent']:>10} / {pair['against']:10}"
                f"{pair['ratio_median']:8.3f} {interval:>16}  wins {pair['win_rate']:4.0%} "
                f"of {pair['machines']}" + (
                    f" ({pair['failed']} with a failed fit, counted uncalibrated)"
                    if pair["failed"] else ""))
    return table, warnings, pair_lines


def _bound_lines(rows: list[dict], bound: Bound) -> list[str]:
    """The bound (mm) beside the table, and each row's median against it."""
    drives = ", ".join("xyz"[d] for d in bound.drives) or "none"
    lines = [f"bound (any plan of these instruments and budget, linearised; docs/compare.md): "
             f"{bound.bound_mm:.4f} mm (best continuous design {bound.design_mm:.4f} mm; "
             f"laser set up on: {drives})"]
    for r in rows:
        median = r["tcp_after_mm"]["rigid"]["median"]
        if median is not None and bound.bound_mm > 0:
            lines.append(f"  {r['agent']} x {r['estimator']}: {median / bound.bound_mm:.2f} x "
                         "the bound")
    return lines


def _show(value: float | None, width: int, digits: int) -> str:
    return f"{value:{width}.{digits}f}" if value is not None else f"{'-':>{width}}"


def _write(trials: list[Trial], rows: list[dict], out: Path, config: Config) -> list[Path]:
    summary_csv = out / "summary.csv"
    # A run with faults has their columns last; one without, the columns it always had.
    faults = ("faults_detected", "silent_failures") if config.faults.active else ()
    with summary_csv.open("w", newline="") as handle:
        writer = csv.writer(handle)
        bound = ("bound_mm",) if config.bound else ()
        writer.writerow(["world", "agent", "estimator", "machines", "failed", "time_s_median",
                         *(f"tcp_after_{f}_median_mm" for f in FRAMES),
                         "tcp_after_rigid_ci95_low_mm", "tcp_after_rigid_ci95_high_mm",
                         "tcp_after_rigid_p95_mm", "z_rms", "chi2_rejected", "success_rate",
                         "predicted_success_rate", *faults, *bound])
        for r in rows:
            writer.writerow([config.world, r["agent"], r["estimator"], r["machines"], r["failed"],
                             r["time_s"]["median"],
                             *(r["tcp_after_mm"][f]["median"] for f in FRAMES),
                             *(r["tcp_after_mm"]["rigid"]["ci95"] or (None, None)),
                             r["tcp_after_mm"]["rigid"]["p95"], r["z_rms"],
                             r["chi2_rejected"], r["success_rate"],
                             r["predicted_success_rate"], *(r[k] for k in faults),
                             *(r[k] for k in bound)])
    from calibrators.cli.plots import accuracy_vs_time, boxes

    return [out / TRIALS_FILE, summary_csv, accuracy_vs_time(trials, config, out),
            boxes(trials, config, out)]


def add(p: argparse.ArgumentParser) -> None:
    listing(p.add_argument("--agents", default="paper,random,tracker",
                           help="comma list of agents (%(listed)s, or policy:FILE, a learned "
                                "policy) (default: %(default)s)"),
            agents_available)
    p.add_argument("--estimators", default="paper,extended",
                   help=f"comma list of estimators ({', '.join(CATALOGUE)}) "
                        "(default: %(default)s)")
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S,
                   help="lab time budget of every agent (s, default %(default)s)")
    p.add_argument("--machines", type=int, default=20,
                   help="random machines (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the run (default %(default)s)")
    p.add_argument("--errors", choices=sorted(PRESETS), default=DEFAULT_PRESET,
                   help="error preset of the machines and gauge stands (default %(default)s)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--sigma", type=float, default=DEFAULT_SIGMA,
                       help="gauge repeatability (mm, default %(default)s)")
    group.add_argument("--noise-free", action="store_true", help="ideal gauges")
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION,
                   help="gauge display resolution (mm, default %(default)s)")
    add_design(p)
    add_conditions(p, told=True)
    p.add_argument("--check-world", action="store_true",
                   help="the exact-model fits test whether the readings show a world worse "
                   "than the one they are told, and warn (warning 'world') with the effects "
                   "that show it, or with those of the default lab it leaves out and cannot "
                   "see (docs/world.md)")
    add_thermometer(p)
    add_instruments(p)
    add_faults(p)
    p.add_argument("--backend", choices=["exact", "pybullet"], default="exact",
                   help="simulator (default %(default)s)")
    p.add_argument("--success-mm", "--target", dest="success_mm", type=float, default=0.01,
                   help="success: the TCP error after rigid motion, against the truth, at "
                        "most this (mm; --target is its older name; default %(default)s)")
    p.add_argument("--jobs", type=int, default=1,
                   help="worker processes; with --engine ray and no cluster address, the "
                        "CPUs of the local Ray instance (default %(default)s)")
    p.add_argument("--chunk", type=int, default=CHUNK, metavar="N",
                   help="machines per task: their episodes run in one vector env and a "
                        "fixed design's fits in one batched solve; fewer lose less work to "
                        "an interrupt and update the progress bar more often, the results "
                        "are the same (default %(default)s)")
    p.add_argument("--engine", choices=ENGINES, default=ENGINES[0],
                   help="where the workers run: local processes, or Ray tasks (extra "
                        "'ray') on a cluster (default %(default)s)")
    p.add_argument("--address", default=None,
                   help="Ray cluster of --engine ray: host:port, ray://host:port or auto "
                        "(default: $RAY_ADDRESS, else a local instance of --jobs CPUs)")
    p.add_argument("--out", default=None,
                   help="folder: every trial as it ends (trials.jsonl), summary.csv, plots")
    p.add_argument("--resume", action="store_true",
                   help="continue the interrupted run kept in --out")
    p.add_argument("--verify-pybullet", type=int, default=0, metavar="K",
                   help="re-run the first K machines on PyBullet in lockstep with the exact "
                        "model and report the largest reading and TCP differences")
    p.add_argument("--bound", action="store_true",
                   help="each row gets bound_mm, the least TCP error after rigid motion any "
                   "plan of the lab's dials and interferometer can reach in the budget "
                   "(linearised, a convex relaxation; a minute or two; docs/compare.md)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: the config, its world, one row per agent x "
                   "estimator, the paired comparisons, and the text's table, warning and "
                   "paired lines (table, warnings, paired_table)")
    p.set_defaults(func=run_command)
