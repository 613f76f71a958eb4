"""The paper's third experiment: readings taken through the compensated controller, held
against what the estimate predicts for them.

:class:`VerificationPlan` (``orthoglide plan --verify EST``) plans the experiment with
each posture's command compensated (:func:`compensated_procedure`); :class:`Verify`
(:func:`verify`) holds its filled sheet against the estimate.  The
leg-parallelism deviations are each mounting's readings minus its first one (the
compensated Zero).  *Before* is what the estimated machine shows at the uncompensated
commands; *after* is what the readings show.  The test is a chi-square of the readings
against the estimate's prediction, with the mountings' zeros eliminated.  Its covariance
holds:

* the estimate's own error (its covariance of estimate minus truth, through the exact
  model's Jacobian);
* the new stands' installation errors, at the realistic preset's tolerances;
* the conditions' effects the model leaves out (the consider terms of
  :mod:`calibrators.estimators.consider`, at their full a-priori size: conservative
  where the fit already took out a part, such as the lead error of a pitch table);
* the gauges' noise.

It passes at the fit's own :data:`~calibrators.estimators.exact_fit.CHI2_LEVEL`.

The readings may be any instrument's (each row's ``instrument``): a tracker's frame and a
ballbar set-up's pivot are unknowns, projected out with the zeros, as the fit takes them
(:data:`NUISANCE_GROUPS`), and each reading is weighted by its instrument's noise.  An
instrument finer than a dial gauge sees the world's effects above its noise: its
readings are also tested along the directions where those effects dominate
(:data:`FOCUS_RATIO`), the level shared between the two tests.
:class:`BallbarCircles` is such a verification: ISO 230-4's circles with a ballbar.

The same instruments that calibrated a machine verify it through the same blind spots: an
estimate whose error bars are too narrow because its world was understated reads, through
the compensated controller, as it predicts.  What the verification's readings can show is
the world itself: ``check_world`` (``verify --check-world``) fits them with ``full`` told
the stated world and tests whether they show a worse one
(:mod:`calibrators.estimators.world_sizes`); the verification then fails when they do.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import linalg

from calibrators.agents.ballbar import circle_steps
from calibrators.agents.base import PlannedAgent, action
from calibrators.estimators.base import Estimate
from calibrators.estimators.catalogue import for_study
from calibrators.estimators.consider import consider_terms, tracker_sigma
from calibrators.estimators.exact_fit import CHI2_LEVEL, world_columns
from calibrators.estimators.gauss_newton import align_tracker, tracker_reach
from calibrators.estimators.world_sizes import BLIND_SPOT
from calibrators.measurements import Measurement, Measurements, rho_label
from calibrators.study.episodes import Episode
from calibrators.workflow.compensate import compensated_commands
from calibrators.workflow.plan import Plan, Procedure, rho_words
from orthoglide_env.instruments import ballbar, interferometer
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA, weighting_sigma
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.instruments.slots import GaugeSpec
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S, TRACKER_SIGMA, Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import DEFAULT_PRESET, ERROR_NAMES, PRESETS, MachineParams
from orthoglide_env.model.kinematics import PAPER_POSTURES, direct, paper_posture
from orthoglide_env.reading_model import (
    ReadingLayout,
    TrackerAxis,
    default_scales,
    jacobian,
    predict,
    preset_sigmas,
)
from orthoglide_env.scoring import commands
from orthoglide_env.world.conditions import Conditions

#: The posture label of a compensated command: the nominal posture's, with this suffix.
COMPENSATED: str = "-compensated"
#: How far at a time (mm) the verification pulls a command at a control limit inside when
#: its compensated command lies beyond the limit (:func:`compensated_procedure`): small
#: next to the stroke (160 mm on the prototype), so that the posture verified stays the
#: calibration's to a few hundredths of the workspace; an assumption, no standard sets it.
INWARD_STEP_MM: float = 0.5


class VerificationPlan:
    """The plan of the verification of the estimate ``estimate``, configured: agent
    ``agent``'s experiment (within ``budget_s`` s, under ``conditions``, read with gauges
    of repeatability ``sigma`` and display ``resolution`` mm, a random agent's choices
    from ``seed``) on a machine of the estimate's design, every command compensated as
    the compensated controller drives it.  ``ValueError`` at construction as
    :class:`~calibrators.workflow.plan.Plan`'s; :meth:`run` makes the procedure."""

    def __init__(self, estimate: Estimate, *, agent: str = "paper",
                 conditions: Conditions | None = None, budget_s: float = DEFAULT_BUDGET_S,
                 seed: int = 0, sigma: float = DEFAULT_SIGMA,
                 resolution: float = DEFAULT_RESOLUTION) -> None:
        self.estimate = estimate
        # The estimate holds the design it calibrated: its verification is planned for it.
        self.plan = Plan(estimate.readings.design, agent=agent, conditions=conditions,
                         budget_s=budget_s, seed=seed, sigma=sigma, resolution=resolution)

    def run(self) -> Procedure:
        """:func:`compensated_procedure` of the plan's procedure."""
        return compensated_procedure(self.plan.run(), self.estimate)


def compensated_procedure(procedure: Procedure, est: Estimate) -> Procedure:
    """``procedure`` with every drive command replaced by the one that puts the tool of
    the machine ``est`` estimates where the nominal machine's tool is at that command (the
    compensated controller's), its readings' postures labelled with :data:`COMPENSATED`.

    A command at a control limit (the paper's postures sit there) whose compensated one
    lies beyond it is pulled inside, by :data:`INWARD_STEP_MM` at a time on its axes at a
    limit, until the compensated command can be made: the verification reads every
    posture of the calibration it verifies, that one a little inside, its reading
    labelled with the command it was made from (``rho(...)``) and said in the notes.  One
    that cannot be brought within the design's ``drho`` validity range of its place is
    left out with its readings, and said too.  The steps' seconds stay the lab's for the
    nominal commands: the commands differ by a few tenths of a mm, a few ms of driving."""
    design = est.readings.design
    nominal = MachineParams(design=design)
    wanted = sorted({tuple(s.rho) for s in procedure.steps if s.rho is not None}
                    | {tuple(m.rho) for m in procedure.sheet})
    made, found = _inside(est, nominal, np.array(wanted, dtype=float))
    table = {rho: [float(v) for v in c] for rho, c in zip(wanted, found, strict=True)
             if np.isfinite(c).all()}
    moved = {rho: tuple(float(v) for v in m) for rho, m in zip(wanted, made, strict=True)
             if rho in table and tuple(m) != rho}
    steps, notes, number = [], list(procedure.notes), {}
    for step in procedure.steps:
        if step.rho is not None:
            rho = table.get(tuple(step.rho))
            if rho is None:
                notes.append(f"step {step.number} of the plan (drive to "
                             f"{', '.join(f'{v:g}' for v in step.rho)}) is left out: its "
                             "compensated command lies beyond the control limits")
                continue
            text = step.text.replace(f"({rho_words(step.rho)})", f"({rho_words(rho)})", 1)
            if tuple(step.rho) in moved:
                notes.append(f"step {step.number} of the plan (drive to "
                             f"{', '.join(f'{v:g}' for v in step.rho)}) is verified at "
                             f"{', '.join(f'{v:g}' for v in moved[tuple(step.rho)])}: its "
                             "compensated command lies beyond the control limits there")
            step = replace(step, rho=rho, text=text)
        number[step.number] = len(steps) + 1
        steps.append(step)
    sheet = [type(m)(m.gauge, (rho_label(moved[tuple(m.rho)]) if tuple(m.rho) in moved
                               else m.posture) + COMPENSATED, m.repetition, 0.0,
                     tuple(table[tuple(m.rho)]), m.mounting, time_s=m.time_s,
                     step=number[m.step], design=est.readings.design)
             for m in procedure.sheet if m.step in number]
    rows: dict[int, list[int]] = {}
    for k, m in enumerate(sheet, start=1):
        rows.setdefault(m.step, []).append(k)
    steps = [replace(s, number=number[s.number], rows=rows.get(number[s.number], []))
             for s in steps]
    return replace(procedure, steps=steps, sheet=sheet, notes=notes)


#: The operations whose command the compensated controller drives to: a move, and a
#: ballbar's set-up, which drives the tool to the pivot's centre (so that the circles,
#: compensated, run about their pivot).
_DRIVEN: tuple[int, ...] = (int(Op.MOVE), int(Op.PIVOT))


class BallbarCircles(PlannedAgent):
    """ISO 230-4's circles with the ballbar alone (the ``ballbar`` agent's programme,
    :func:`~calibrators.agents.ballbar.circle_steps`, without the gauges' experiment
    after it): a verification that reads the tool's path through another instrument than
    the dial gauges that calibrated it.  Not a registered agent: it calibrates nothing."""

    name = "ballbar"
    needs_instruments = ("ballbar",)

    def make_plan(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        return [*circle_steps(len(observation["slot"]), self.env.design), action(Op.STOP)]


class CompensatedAgent(PlannedAgent):
    """The planned agent ``agent``'s experiment through the compensated controller of
    the estimate ``estimate``, in a virtual lab: what a technician does by the procedure
    of :func:`compensated_procedure`, each drive command (a move's, a ballbar set-up's)
    the compensated one (pulled inside at a control limit in the same way), a drive with
    none left out.
    :meth:`readings` labels the episode's readings as that procedure's sheet does, for
    :func:`verify`."""

    def __init__(self, agent: PlannedAgent, estimate: Estimate) -> None:
        if not isinstance(agent, PlannedAgent):
            raise ValueError(f"agent '{agent.name}' chooses each move from the last reading: "
                             "its verification cannot be planned")
        self.agent, self.estimate = agent, estimate
        self.name = agent.name
        self.needs_tracker, self.needs_reference = agent.needs_tracker, agent.needs_reference
        self.needs_instruments = agent.needs_instruments
        self.made: dict[tuple[float, ...], tuple[float, ...]] = {}

    def make_plan(self, observation: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        self.agent.reset(self.env, observation, self.rng)
        plan = list(self.agent.plan)
        moves = [a for a in plan if int(a["op"]) in _DRIVEN]
        design = self.estimate.readings.design
        made, found = _inside(self.estimate, MachineParams(design=design),
                              np.array([a["rho"] for a in moves], dtype=float).reshape(-1, 3))
        commands = iter(zip(made, found, strict=True))
        out = []
        for a in plan:
            if int(a["op"]) in _DRIVEN:
                m, c = next(commands)
                if not np.isfinite(c).all():
                    continue
                self.made[tuple(float(v) for v in c)] = tuple(float(v) for v in m)
                a = {**a, "rho": c}
            out.append(a)
        return out

    def readings(self, episode: Episode) -> Measurements:
        """The episode's readings, each at a compensated command labelled with the
        command it was made from and :data:`COMPENSATED` (the set-up's, read before the
        first drive, keep theirs)."""
        data = episode.measurements
        return Measurements([replace(m, posture=rho_label(self.made[tuple(m.rho)])
                                     + COMPENSATED, design=data.design)
                             if tuple(m.rho) in self.made else m for m in data.items],
                            data.experiment_time_s, data.design)


def _inside(est: Estimate, nominal: MachineParams, rho: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The commands (n, 3) the verification makes of the nominal commands ``rho`` (n, 3)
    (each itself, or pulled inside on its axes at a control limit, see
    :func:`compensated_procedure`) and their compensated commands (NaN rows: none)."""
    design = nominal.design
    made = rho.copy()
    found = compensated_commands(est, direct(nominal, made))
    at_max, at_min = rho >= design.rho_max, rho <= design.rho_min
    reach = design.validity_range["drho"][0]
    for step in range(1, int(reach / INWARD_STEP_MM) + 1):
        missing = ~np.isfinite(found).all(axis=-1) & (at_max | at_min).any(axis=-1)
        if not missing.any():
            break
        inward = step * INWARD_STEP_MM
        made[missing] = np.where(at_max[missing], rho[missing] - inward,
                                 np.where(at_min[missing], rho[missing] + inward,
                                          rho[missing]))
        found[missing] = compensated_commands(est, direct(nominal, made[missing]))
    return made, found


def _nominal_command(m: Measurement, design: MachineDesign) -> np.ndarray:
    """The uncompensated command a verification reading's was made from, by its label (a
    paper posture's name, or the rho of :func:`~calibrators.measurements.rho_label`, then
    :data:`COMPENSATED`); NaN when the label does not say."""
    base = m.posture.removesuffix(COMPENSATED)
    if base != m.posture:
        if base in PAPER_POSTURES:
            return paper_posture(base, design)
        found = re.fullmatch(r"rho\(([^,]+),([^,]+),([^,]+)\)", base)
        if found:
            return np.array([float(v) for v in found.groups()])
    return np.full(3, np.nan)


@dataclass(frozen=True)
class Verification:
    """The verification's outcome: pass or fail with the reason, the chi-square, and per
    reading the deviations before and after compensation, the predicted ones and the
    residual (mm)."""

    passed: bool
    reason: str
    chi2: float
    dof: int
    rows: list[dict[str, Any]]
    residual_rms_mm: float
    predicted_rms_mm: float
    #: The world test's words when it was asked for (``check_world``): the readings'
    #: fit's warning of kind ``world``, or "" when they show no worse world than stated.
    world: str | None = None
    #: The chi-square and its degrees of freedom along the directions where the stated
    #: world's effects dominate the rest, for readings of an instrument finer than a dial
    #: gauge (None: not taken, or no such direction).
    focused: tuple[float, int] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The outcome as JSON (``verify --json``'s object; ``world`` only when the
        world was tested, ``focused_chi2`` and ``focused_dof`` only when that test was
        taken)."""
        return {"passed": self.passed, "reason": self.reason, "chi2": self.chi2,
                "dof": self.dof, "residual_rms_mm": self.residual_rms_mm,
                "predicted_rms_mm": self.predicted_rms_mm,
                **({} if self.world is None else {"world": self.world}),
                **({} if self.focused is None else {"focused_chi2": self.focused[0],
                                                    "focused_dof": self.focused[1]}),
                "deviations_before": [r["before_mm"] for r in self.rows],
                "deviations_after": [r["after_mm"] for r in self.rows], "readings": self.rows}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Verification:
        """The outcome :meth:`to_dict` wrote (``ValueError`` if it is not one)."""
        try:
            world = data.get("world")
            focused = (None if "focused_chi2" not in data
                       else (float(data["focused_chi2"]), int(data["focused_dof"])))
            return cls(bool(data["passed"]), str(data["reason"]), float(data["chi2"]),
                       int(data["dof"]), [dict(r) for r in data["readings"]],
                       float(data["residual_rms_mm"]), float(data["predicted_rms_mm"]),
                       None if world is None else str(world), focused)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a verification's outcome: {exc}") from None

    def write(self, folder: str | Path) -> list[Path]:
        """Write :data:`VERIFICATION_FILE` (:meth:`to_dict`) into ``folder`` (made if
        missing); the paths written."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / VERIFICATION_FILE
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n", encoding="utf-8")
        return [path]


#: The file :meth:`Verification.write` writes.
VERIFICATION_FILE = "verification.json"


class Verify:
    """The verification, configured: the readings ``readings`` taken through the
    compensated controller (the filled sheet of a :class:`VerificationPlan`, or any
    instrument's readings, such as a ballbar's circles: :class:`BallbarCircles`), under
    ``conditions`` (default the estimate's), against the estimate ``estimate``.
    ``ValueError`` at construction for readings of another design than the estimate's;
    :meth:`run` makes the :class:`Verification`."""

    def __init__(self, estimate: Estimate, readings: Measurements,
                 conditions: Conditions | None = None, *, check_world: bool = False) -> None:
        _check_design(estimate, readings)
        self.estimate, self.readings, self.conditions = estimate, readings, conditions
        self.check_world = check_world

    def run(self) -> Verification:
        """:func:`verify` of the readings."""
        return verify(self.estimate, self.readings, self.conditions,
                      check_world=self.check_world)


def _check_design(est: Estimate, data: Measurements) -> None:
    if data.design != est.readings.design:
        raise ValueError("the readings are of another design than the estimate's machine")


def verify(est: Estimate, data: Measurements, conditions: Conditions | None = None, *,
           check_world: bool = False) -> Verification:
    """Hold the verification readings ``data`` (taken under ``conditions``, default the
    estimate's; any instrument's, see the module docstring) against the estimate
    ``est``'s prediction; ``check_world``: and test whether they show a world worse than
    ``conditions`` (:func:`world_test`).  ``ValueError`` when they are of another design,
    or too few to test."""
    _check_design(est, data)
    if conditions is None:
        conditions = Conditions.from_dict(est.conditions) if est.conditions else (
            Conditions("ideal"))
    items = data.items
    design = ReadingLayout.of([m.mounting for m in items], [m.gauge for m in items],
                       np.array([m.rho for m in items], dtype=float), data.design)
    values = align_tracker(design, np.array([m.reading for m in items], dtype=float))
    space = design.space
    if list(est.space[:len(ERROR_NAMES)]) != list(ERROR_NAMES):
        raise ValueError("the estimate holds no machine errors to verify")
    theta = np.zeros(len(space.names))
    theta[:len(ERROR_NAMES)] = est.theta[:len(ERROR_NAMES)]
    predicted = predict(theta, design)
    # What the estimated machine shows at the commands the compensation replaced.
    machine = est.machine
    before_rho = np.array([_nominal_command(m, data.design) for m in items])
    guessed = ~np.isfinite(before_rho).all(axis=1)
    if guessed.any():
        before_rho[guessed] = commands(MachineParams(design=data.design),
                                       direct(machine, design.rho[guessed]))
    if not np.isfinite(before_rho).all():
        k = int(np.flatnonzero(~np.isfinite(before_rho).all(axis=1))[0])
        raise ValueError(f"reading {k + 1} ({items[k].posture}): no uncompensated command "
                         "within the control limits puts the tool where this one does")
    before = predict(theta, ReadingLayout(design.mountings, design.specs, design.mounting,
                                   before_rho, design.machine_design))
    scale = default_scales(space)
    jac = jacobian(theta, design, np.ones(len(theta), bool), scale)  # (N, P) per scale
    prior = (preset_sigmas(PRESETS[DEFAULT_PRESET], space) / scale) ** 2
    sigma_scaled = np.diag(prior)
    n = len(ERROR_NAMES)
    sigma_scaled[:n, :n] = est.error_covariance[:n, :n] / np.outer(scale[:n], scale[:n])
    noise = _noise(est, design, data, conditions)
    cov = jac @ sigma_scaled @ jac.T + np.diag(noise**2)
    times = [m.time_s for m in items]
    timed = None if any(t is None for t in times) else np.array(times, dtype=float)[None]
    columns = world_columns(design, consider_terms(design, values[None], timed, conditions))[0]
    effects = columns @ columns.T
    cov += effects
    # Each mounting's zero is unknown, and so are a tracker's frame and a ballbar's pivot
    # (as the fit takes them): project them out.
    onehot = np.eye(len(design.mountings))[design.mounting]
    nuisance = np.isin(space.groups, NUISANCE_GROUPS)
    unknown = np.hstack([onehot, jac[:, nuisance]]) if nuisance.any() else onehot
    centre = np.eye(len(values)) - unknown @ np.linalg.pinv(unknown)
    residual = centre @ (values - predicted)
    dof = len(values) - int(np.linalg.matrix_rank(unknown))
    if dof < 1:
        raise ValueError("every mounting needs more readings than its unknowns to verify "
                         "(a gauge's zero: two; a ballbar set-up's zero and pivot: five)")
    lam, vec = np.linalg.eigh(centre @ cov @ centre)
    keep = lam > lam.max() * 1e-12
    lam, vec = lam[keep], vec[:, keep]
    terms = (vec.T @ residual) ** 2 / lam
    chi2 = float(np.sum(terms))
    focused = None
    if not all(isinstance(s, GaugeSpec) for s in design.specs):
        # In the readings left once the unknowns are out (``vec``'s span): the directions
        # where the world's effects are FOCUS_RATIO times the rest of the covariance, and
        # each one's whole variance, 1 + that ratio, in the rest's units.
        world = vec.T @ effects @ vec
        ratio, turn = linalg.eigh(world, np.diag(lam) - world)
        along = ratio > FOCUS_RATIO
        if along.any():
            focused = (float(np.sum((turn[:, along].T @ vec.T @ residual) ** 2
                                    / (1 + ratio[along]))), int(along.sum()))
    # Imported here: planning a verification (``orthoglide plan``, which imports this
    # module) needs none of SciPy's distributions, a CPU-second to import.
    from scipy import stats

    # Two tests share the level where there are two (Bonferroni).
    level = CHI2_LEVEL if focused is None else CHI2_LEVEL / 2
    limit = float(stats.chi2.ppf(1 - level, dof))
    passed = chi2 <= limit
    if focused is not None:
        focus_limit = float(stats.chi2.ppf(1 - level, focused[1]))
        passed = passed and focused[0] <= focus_limit
    rms = float(np.sqrt(np.mean(residual**2)))
    expected = float(np.sqrt(np.trace(centre @ cov @ centre) / len(values)))
    along = "" if focused is None else (
        f", and {focused[0] / focused[1]:.2f} along the {focused[1]} directions where the "
        f"stated world's effects dominate the estimate's error bars and the readings' "
        f"noise (limit {focus_limit / focused[1]:.2f})")
    verdict = (f"chi2/dof = {chi2 / dof:.2f} over {dof} degrees of freedom{along}, "
               f"{'within' if passed else 'beyond'} the chi-square test at {level:g} "
               f"(limit {limit / dof:.2f}); readings off the prediction by {rms:.4f} mm RMS "
               f"against {expected:.4f} mm expected from the estimate's error bars")
    reason = (f"the compensated machine reads as the estimate predicts ({verdict})"
              if passed else f"the machine does not read as the estimate predicts "
              f"({verdict}); re-calibrate, or look for a stand that moved")
    world = world_test(est, data, conditions) if check_world else None
    if world:
        reason = (f"{reason}; but the readings show a world worse than the stated one, "
                  f"so the estimate's error bars are too narrow: {world}"
                  if passed else f"{reason}; {world}")
        passed = False
    first = {}
    for k, m in enumerate(design.mounting):
        first.setdefault(int(m), k)
    rows = []
    for k, m in enumerate(items):
        ref = first[int(design.mounting[k])]
        rows.append({"mounting": m.mounting, "posture": m.posture, "rho": list(m.rho),
                     "before_mm": float(before[k] - before[ref]),
                     "after_mm": float(values[k] - values[ref]),
                     "predicted_mm": float(predicted[k] - predicted[ref]),
                     "residual_mm": float(residual[k])})
    return Verification(passed, reason, chi2, dof, rows, rms, expected, world, focused)


#: Readings of an instrument finer than a dial gauge are also tested along the directions
#: where the stated world's effects are at least this many times the rest of the
#: predicted covariance (the estimate's error bars and the noise): there an understated
#: world shows plainly, where the one chi-square over every direction dilutes it among
#: the noise's many, and the estimate's error bars, as wide in any world, do not blur
#: it.  The directions are chosen before the residual is looked at, so any ratio keeps
#: the test's level; 10 is an assumption.  On a ballbar's circles after the paper's
#: calibration (12 machines in the workshop, told the lab) it took 13 directions of 146
#: and rejected on all 12 at 5e-4, where the directions that dominate the noise alone
#: (the error bars' with the world's, 22) let 3 of the 12 pass.
FOCUS_RATIO: float = 10.0
#: The parameter groups a verification takes as unknown, beside each mounting's zero: a
#: tracker station's rotation, a ballbar set-up's pivot.
NUISANCE_GROUPS: tuple[str, ...] = ("tracker_rotation", "ballbar_centre")


def _noise(est: Estimate, design: ReadingLayout, data: Measurements,
           conditions: Conditions) -> np.ndarray:
    """Each reading's noise (mm, a standard deviation), as the fit weights it: a dial
    gauge's, the estimate's; a tracker's, its MPE's under ``conditions`` with one (at the
    reach of its points), else the lab's default; an interferometer's and a ballbar's,
    their scatter under ``conditions``."""
    def of(spec: object) -> float:
        if isinstance(spec, TrackerAxis):
            return (tracker_sigma(conditions, tracker_reach(design, data))
                    if "tracker" in conditions else TRACKER_SIGMA)
        if isinstance(spec, InterferometerAxis):
            return interferometer.sigma(conditions)
        if isinstance(spec, ballbar.BallbarSpec):
            return ballbar.sigma(conditions)
        return est.sigma

    return weighting_sigma(np.array([of(s) for s in design.specs])[design.mounting])


def world_test(est: Estimate, data: Measurements, conditions: Conditions) -> str:
    """The words of the test that the verification readings ``data`` show a world worse
    than ``conditions`` (the warning of kind ``world`` of their ``full`` fit told them, at
    the estimate's noise), or "" when they do not.  ``ValueError`` when that fit fails."""
    [fitted] = for_study("full", est.sigma, conditions, world_check=True).fit_many([data])
    if isinstance(fitted, Exception):
        raise ValueError(f"the verification's readings could not be fitted to test the "
                         f"world: {fitted}")
    # A blind spot says what the readings cannot show: no verdict on the world.
    return next((w for w in fitted.warnings
                 if w.startswith("world:") and not w.startswith(BLIND_SPOT)), "")
