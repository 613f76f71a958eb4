"""The bound at the machines calibrated: each machine's own bound beside the nominal one.

    python benchmarks/machine_bound.py [--conditions lab] [--budget 3600]
                                       [--instruments dial] [--machines 50] [--seed 1]
                                       [--errors realistic] [--out RUN] [--estimators full]
                                       [--plans [--robust K]]

The bound ``compare --bound`` carries (:func:`~calibrators.study.compare.study_bound`)
linearises at the nominal machine.  A fit linearises at the machine it reads, so each
machine has its own bound (:func:`~calibrators.planning.bound.machine_bound_model`: the
dials' rows and the TCP weight at its 27 errors and its stands' installations), and the
RMS over machines of those bounds is a yardstick no plan, fixed or adaptive, beats on
the linearised model.  It reads the truth: a yardstick, never an agent's input.

For machines 0 to ``--machines`` - 1 of a comparison seeded ``--seed`` (drawn as the lab
draws them at reset), this prints each bound's RMS over the machines with a bootstrap
95 % interval, against the nominal bound; with ``--out`` (a ``compare --out`` folder of
that lab, its ``trials.jsonl``), each agent's realised TCP error after rigid motion
(each of ``--estimators``' fits; a failed fit counts its machine uncalibrated, as ``compare``
scores it) over both bounds: the RMS over machines over the bound's RMS (the per-machine
bounds' interval paired by machine), and the median over machines of realised over
that machine's bound, with its distribution-free interval.  Dial sigma 0.02 mm and
resolution 0.01 mm on the prototype with screw drives: a run of other dials, another
design or scales is refused (exit 2).  The ballbar is no candidate of a machine's
bound.  With ``--plans``, each machine's row of the nominal bound's design
and of ``optimal``'s kept plan (made as ``compare`` makes it, at machine 0's reset) on
that machine's model: what a design or plan made at the nominal machine is worth at the
machines; with ``--robust K``, beside them the phased plan rounded from a design made on
the mean over ``K`` machines drawn from the error preset's prior with a seed of its own
(:func:`robust_plan`: never the comparison's machines, never the truth).  Seconds per
machine.
"""

from __future__ import annotations

import argparse
import json
from contextlib import closing
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
from scipy.sparse import csr_matrix

from calibrators.agents import get_agent
from calibrators.planning.belief import PlannedOperation
from calibrators.planning.bound import (
    BoundModel,
    at_contact_model,
    best_design,
    dial_grid,
    held_design,
    lab_model,
    plan_counts,
)
from calibrators.planning.instruments import step_actions
from calibrators.planning.phased import PASSES, overhead_s, phase_visits, plan_phases, rounded_plan
from calibrators.planning.search import Planner, greedy_plan
from calibrators.study.compare import Config, shared_start, study_bound
from calibrators.study.episodes import machine_seed
from calibrators.study.labs import lab_id
from calibrators.study.statistics import median_interval
from orthoglide_env.instruments.stands import ideal_rays, stand_errors
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, slot_catalogue, slot_index
from orthoglide_env.model.errors import PRESETS, MachineParams, get_preset
from orthoglide_env.world.conditions import CONDITION_NAMES, Conditions

UM = 1e3  # per mm
#: Resamples of the machines for the bootstrap intervals of RMS values.
RESAMPLES: int = 10_000
#: The seed of :func:`robust_plan`'s machines drawn from the prior (not a comparison's:
#: those are drawn from ``machine_seed(seed, i)``).
PRIOR_SEED: int = 2026
#: Multiplicative steps of :func:`mean_design`: a design to round, not an optimum (under
#: ``lab``, one hour, 8 machines, the best visit's gain was within 2 % of the mean gain
#: after 80).
MEAN_STEPS: int = 120
#: The share of :func:`mean_design`'s start spread evenly over every visit, so that it can
#: read where the nominal design does not.
SPREAD: float = 0.01
#: Readings of a candidate below this are dropped before rounding: whole visits are
#: apportioned one each to the largest shares where the support outnumbers them.
READ_FLOOR: float = 0.25


def drawn(config: Config, index: int) -> tuple[MachineParams, np.ndarray]:
    """Machine ``index`` of ``config``'s comparison and its stands' installations per slot
    of the catalogue ((S, 4), zero where no stand starts): the truth of ``optimal``'s lab
    reset with that machine's seed, as ``compare`` resets it (the lab's own draws, so
    whatever it draws before the stands, a tracker station's frame among them, is
    drawn)."""
    kwargs = config.lab_kwargs(get_agent("optimal"))
    with closing(gym.make(lab_id(kwargs), **kwargs)) as env:
        env.reset(seed=machine_seed(config.seed, index))
        lab = env.unwrapped
        machine, gauges = lab.true_machine, lab.true_gauges
    catalogue = slot_catalogue(config.design)
    start = [slot_index(g.spec, design=config.design) for g in gauges]
    specs = [catalogue[s] for s in start]
    origins, directions = ideal_rays(specs, machine)
    installed = np.zeros((len(catalogue), 4))
    installed[start] = stand_errors(specs, np.array([g.origin for g in gauges]),
                                    np.array([g.direction for g in gauges]), origins,
                                    directions)
    return machine, installed


def rms_interval(values: np.ndarray, over: np.ndarray | None = None
                 ) -> tuple[float, float, float]:
    """The RMS of ``values`` (or its ratio to ``over``'s RMS, machine by machine paired)
    and its bootstrap 95 % interval over the machines."""
    draws = np.random.default_rng(0).integers(0, len(values), (RESAMPLES, len(values)))

    def rms(x: np.ndarray, axis: int | None = None) -> np.ndarray:
        return np.sqrt(np.mean(x**2, axis=axis))

    value = rms(values) / (1.0 if over is None else rms(over))
    sampled = rms(values[draws], 1) / (1.0 if over is None else rms(over[draws], 1))
    low, high = np.quantile(sampled, [0.025, 0.975])
    return float(value), float(low), float(high)


def realised(run: Path, config: Config, estimators: tuple[str, ...], machines: int
             ) -> dict[tuple[str, str], tuple[np.ndarray, int]]:
    """Each agent's TCP error after rigid motion (mm) with each of ``estimators``' fits on
    machines 0 to ``machines`` - 1 of the comparison in ``run`` and how many of those fits
    failed (``ValueError``: not ``config``'s lab, or machines missing)."""
    told = json.loads((run / "config.json").read_text())
    # A run of other dials or of another design has another bound: refused, not compared.
    expected = {"conditions": config.conditions.name, "budget_s": config.budget_s,
                "instruments": list(config.instruments), "seed": config.seed,
                "errors": config.errors, "effects": list(config.conditions.effects),
                "sigma": config.sigma, "resolution": config.resolution,
                "indicator": config.conditions.indicator, "design": None, "drives": None}
    differ = {k: told.get(k) for k, v in expected.items() if told.get(k) != v}
    if differ:
        raise ValueError(f"{run} is another lab: {differ} (this one: "
                         f"{ {k: expected[k] for k in differ} })")
    errors: dict[tuple[str, str], dict[int, float]] = {}
    failed: dict[tuple[str, str], int] = {}
    for line in (run / "trials.jsonl").read_text().splitlines():
        trial = json.loads(line)
        row = trial["agent"], trial["estimator"]
        if row[1] in estimators and trial["machine"] < machines:
            errors.setdefault(row, {})[trial["machine"]] = trial["tcp_after"]["rigid"]
            failed[row] = failed.get(row, 0) + bool(trial["failed"])
    if not errors:
        raise ValueError(f"{run} has no trials of estimators {list(estimators)}")
    out = {}
    for row, by_machine in errors.items():
        missing = sorted(set(range(machines)) - set(by_machine))
        if missing:
            raise ValueError(f"{run}: {row} has no trial on machines {missing[:5]}")
        out[row] = np.array([by_machine[i] for i in range(machines)]), failed[row]
    return out


def mean_design(judged: list[BoundModel], visits: csr_matrix, start: np.ndarray,
                count: float) -> np.ndarray:
    """The readings (N,) of ``count`` visits, each reading the candidates of its row of
    ``visits`` (V, N; sparse, 0 or 1), shared to least the mean over ``judged`` of their ``f``:
    :data:`MEAN_STEPS` multiplicative steps from the shares ``start`` (V,) with
    :data:`SPREAD` spread evenly (every visit costs one settle, so the step is each
    visit's gain over the mean gain)."""
    share = (1 - SPREAD) * start / start.sum() + SPREAD / len(start)
    for _ in range(MEAN_STEPS):
        counts = count * (visits.T @ share)
        gain = np.zeros(len(share))
        for model in judged:
            gain += visits @ model.value_and_fall(counts)[1]
        share = share * gain / (share @ gain)
    return count * (visits.T @ share)


def robust_plan(opened: Planner, greedy: tuple[PlannedOperation, ...],
                judged: list[BoundModel]) -> tuple[tuple[PlannedOperation, ...], float]:
    """:func:`~calibrators.planning.phased.phased_plan` from the fresh planner ``opened``
    and its ``greedy`` plan, its design made on the mean of ``judged`` (models counted at
    a-priori contact) by :func:`mean_design` over the visits of every posture in each
    phase, started from the nominal design's visits: the steps and the planner's
    predicted error (mm)."""
    slots = tuple(int(s) for s in opened.slots)
    phases, remounts = plan_phases(slots, greedy)
    added = tuple(sorted({s for phase in phases for s in phase} - set(slots)))
    grid = dial_grid(judged[0])
    atoms = [(posture, j) for j in range(len(phases)) for posture in range(len(grid))
             if (grid[posture, list(phases[j])] >= 0).any()]
    read = [grid[posture, list(phases[j])] for posture, j in atoms]
    read = [r[r >= 0] for r in read]
    visits = csr_matrix((np.ones(sum(r.size for r in read)), np.concatenate(read),
                         np.r_[0, np.cumsum([r.size for r in read])]),
                        shape=(len(atoms), judged[0].rows.shape[0]))
    steps, planner = greedy, opened
    for _ in range(PASSES):
        left = opened.budget_s - overhead_s(steps)
        design = held_design(opened.design, opened.conditions, opened.sigma, left, ("dial",),
                             added, len(remounts), len(slots), phases=phases,
                             at_contact=True)
        readings = np.where(grid >= 0, design.counts[np.maximum(grid, 0)], 0.0)
        start = phase_visits(readings, phases)[tuple(np.array(atoms).T)].astype(float)
        counts = mean_design(judged, visits, start,
                             (left - len(remounts) * TIME.remount_s) / TIME.settle_and_read_s)
        readings = np.where(grid >= 0, counts[np.maximum(grid, 0)], 0.0)
        planner = opened.fork()
        steps = tuple(rounded_plan(planner, phase_visits(
            np.where(readings >= READ_FLOOR, readings, 0.0), phases), remounts))
    return steps, planner.predicted_rigid_mm()


def plans_at_machines(config: Config, machines: int, robust: int = 0) -> None:
    """Print, per machine and as RMS over them, its bound, the nominal bound's design and
    ``optimal``'s kept plan on its model (µm), beside their values on the nominal one;
    with ``robust`` machines, the plan of :func:`robust_plan` on them too."""
    plans = shared_start(replace(config, agents=("optimal",)), 0, 1).plans
    (slots, engaged, sigma, *_), (steps, kept) = next(iter(plans.items()))
    owned, stands = config.instruments, len(PAPER_SLOTS)
    nominal = best_design(config.design, config.conditions, sigma, config.budget_s, owned)
    model = lab_model(config.design, config.conditions, sigma, config.budget_s, owned, stands)
    held = [steps]
    if robust:
        planner = Planner(list(slots), list(engaged), sigma, config.budget_s,
                          design=config.design, conditions=config.conditions)
        planner.expect_readings()
        preset = get_preset(config.errors)
        judged = [at_contact_model(lab_model(
            config.design, config.conditions, sigma, config.budget_s, owned, stands,
            preset.sample(np.random.default_rng([PRIOR_SEED, k]), config.design)),
            config.design) for k in range(robust)]
        made, predicted = robust_plan(planner.fork(), tuple(greedy_plan(planner)), judged)
        held.append(made)
        print(f"the planner's criterion: `optimal`'s plan {UM * kept:.3f} µm, the plan on "
              f"{robust} drawn machines {UM * predicted:.3f} µm\n")
    actions = [step_actions(s) for s in held]
    counts = [plan_counts(model, config.design, slots, engaged, a) for a in actions]
    print("| machine | its bound | its best design | the nominal design there | "
          "`optimal`'s plan there | plan over its bound |"
          + (f" the plan on {robust} drawn machines there |" if robust else ""))
    print("|---|---|---|---|---|---|" + ("---|" if robust else ""))
    rows = []
    for i in range(-1, machines):
        if i >= 0:
            machine, installed = drawn(config, i)
            found = best_design(config.design, config.conditions, sigma, config.budget_s,
                                owned, stands, True, machine, installed)
            model = lab_model(config.design, config.conditions, sigma, config.budget_s,
                              owned, stands, machine, installed)
            counts = [plan_counts(model, config.design, slots, engaged, a) for a in actions]
        else:
            found = nominal
        row = UM * np.array([found.bound.bound_mm, found.bound.design_mm,
                             np.sqrt(model.value(nominal.counts)),
                             *(np.sqrt(model.value(c)) for c in counts)])
        rows += [row] if i >= 0 else []
        print(f"| {i if i >= 0 else 'nominal'} | " + " | ".join(f"{v:.3f}" for v in row[:4])
              + f" | {row[3] / row[0]:.3f} |" + "".join(f" {v:.3f} |" for v in row[4:]))
    rms = np.sqrt(np.mean(np.array(rows) ** 2, axis=0))
    print("| RMS | " + " | ".join(f"{v:.3f}" for v in rms[:4]) + f" | {rms[3] / rms[0]:.3f} |"
          + "".join(f" {v:.3f} |" for v in rms[4:]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--conditions", default="lab", choices=CONDITION_NAMES)
    parser.add_argument("--budget", type=float, default=3600.0, help="lab seconds")
    parser.add_argument("--instruments", default="dial",
                        help="what the lab owns, comma-separated (dial, interferometer)")
    parser.add_argument("--machines", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--errors", default="realistic", choices=sorted(PRESETS))
    parser.add_argument("--out", type=Path, help="a compare --out folder of this lab")
    parser.add_argument("--estimators", default="full",
                        help="whose fits --out's rows are, comma-separated")
    parser.add_argument("--plans", action="store_true",
                        help="the nominal design and optimal's plan at each machine")
    parser.add_argument("--robust", type=int, default=0, metavar="K",
                        help="with --plans: the phased plan designed on K machines drawn "
                             "from the prior too")
    args = parser.parse_args()
    owned = tuple(args.instruments.split(","))
    if "dial" not in owned or set(owned) - {"dial", "interferometer"}:
        parser.error(f"--instruments must name dial and maybe interferometer (no ballbar "
                     f"at a machine), got {args.instruments!r}")
    if not (np.isfinite(args.budget) and args.budget > 0):
        parser.error(f"--budget must be a positive number of seconds, got {args.budget}")
    if args.machines < 6:
        parser.error(f"--machines must be at least 6 (a median's interval), got {args.machines}")
    config = Config(agents=(), estimators=(), budget_s=args.budget, errors=args.errors,
                    seed=args.seed, conditions=Conditions(args.conditions),
                    instruments=owned)
    if args.robust < 0 or (args.robust and not args.plans):
        parser.error(f"--robust takes a count of machines >= 0 with --plans, got {args.robust}")
    if args.plans:
        plans_at_machines(config, args.machines, args.robust)
        return
    agents: dict[tuple[str, str], tuple[np.ndarray, int]] = {}
    if args.out is not None:
        try:
            agents = realised(args.out, config, tuple(args.estimators.split(",")),
                              args.machines)
        except (OSError, ValueError, KeyError) as error:
            parser.error(str(error))
    nominal = study_bound(config).bound_mm
    bounds = np.array([study_bound(config, *drawn(config, i)).bound_mm
                       for i in range(args.machines)])
    rms, low, high = rms_interval(bounds)
    print(f"{args.conditions}, {args.budget:g} s, {'+'.join(owned)}, machines 0-"
          f"{args.machines - 1} of seed {args.seed}, {args.errors}: nominal bound "
          f"{UM * nominal:.3f} µm; at the machines RMS {UM * rms:.3f} [{UM * low:.3f}, "
          f"{UM * high:.3f}] µm ({rms / nominal:.4f}x), median {UM * np.median(bounds):.3f}, "
          f"range {UM * bounds.min():.3f}-{UM * bounds.max():.3f}")
    if not agents:
        return
    print()
    print("| agent, estimator | failed | realised RMS µm | RMS / nominal bound "
          "| RMS / machines' bound RMS | median per machine / nominal "
          "| median per machine / its bound |")
    print("|---|---|---|---|---|---|---|")
    for (agent, estimator), (errors, failures) in sorted(agents.items()):
        mine, lo, hi = rms_interval(errors)
        paired = rms_interval(errors, bounds)
        over = errors / nominal
        each = errors / bounds
        a, b = median_interval(over)
        c, d = median_interval(each)
        print(f"| {agent}, {estimator} | {failures} | "
              f"{UM * mine:.2f} [{UM * lo:.2f}, {UM * hi:.2f}] | "
              f"{mine / nominal:.3f} [{lo / nominal:.3f}, {hi / nominal:.3f}] | "
              f"{paired[0]:.3f} [{paired[1]:.3f}, {paired[2]:.3f}] | "
              f"{np.median(over):.3f} [{a:.3f}, {b:.3f}] | "
              f"{np.median(each):.3f} [{c:.3f}, {d:.3f}] |")


if __name__ == "__main__":
    main()
