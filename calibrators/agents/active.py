"""``active``: sequential Bayesian design, one operation at a time.

The agent keeps the linearised extended estimator as a filter (:class:`calibrators.planning.search.
Planner` with :meth:`~calibrators.planning.belief.Belief.observe`): the 27 machine errors and each
mounting's stand and zero, with the estimators' priors, updated in closed form after every
reading.  Before each move it prices every candidate move by the expected fall of the predicted TCP
error after the best-fit rigid motion per second, and takes the best.  Its stands move
when and where the ``optimal`` plan moves them: which slot is worth a stand is a
property of the design, the same on every machine to first order, and weighing every
re-mount against staying is the costly part of planning (seconds per decision).

What its feedback buys: from its estimate it predicts every gauge's next reading to
microns where a fixed plan knows it only to about a millimetre a priori, so it lets a
plunger down wherever the tip stays three of *its* standard deviations inside the
travel: more postures read each gauge, and more gauges read each posture.

Every :data:`REFIT_S` seconds of lab time the full (non-linear) extended estimator refits
the whole notebook (``full`` told the lab's conditions, when the notebook holds ballbar
readings under a world's drives) and its estimate replaces the filter's mean: a poor
early estimate (the first readings pin down little, and the filter is linearised at the
nominal machine) is corrected from all the data, so it cannot lock the design.  It stops when
the predicted error reaches :attr:`ActiveAgent.target_mm` or the budget is spent.

Under ``lab`` or ``workshop`` conditions its filter also holds the world's drift,
backlash and warm-up, carries the indicators' curves as consider terms, and stops when
more time does not pay (:mod:`calibrators.planning.world_terms`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import Any

import gymnasium as gym
import numpy as np

from calibrators.agents.base import Agent, action, register
from calibrators.agents.optimal import (
    fixed_plan,
    lab_setup,
    leaves_laser_unread,
    move_dwell_s,
    owned_instruments,
)
from calibrators.estimators.base import Estimator
from calibrators.estimators.catalogue import for_study
from calibrators.planning.belief import (
    N_MACHINE,
    N_STAND,
    ZERO_SCALE,
    PlannedOperation,
    observe_many,
)
from calibrators.planning.instruments import (
    Bundle,
    conditions_or_default,
    operation_keys,
    planned_bundles,
)
from calibrators.planning.pricing import PricedMoves
from calibrators.planning.rounding import plan_bundles
from calibrators.planning.search import Planner, best_moves, take
from calibrators.planning.search import observe as observe_bundle
from orthoglide_env.instruments.ballbar import BallbarSpec
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.instruments.stands import stand_names
from orthoglide_env.instruments.step_gauge import StepGaugeSpec
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.errors import ERROR_NAMES
from orthoglide_env.reading_model import ParameterSpace, default_scales
from orthoglide_env.world.conditions import Conditions

#: Seconds of lab time between two full refits of the notebook.
REFIT_S: float = 600.0


def refit_world(conditions: Conditions | None, records: Sequence[Any]) -> Conditions | None:
    """The world ``active``'s refits tell their fit of the notebook ``records`` (the lab's
    records): the lab's ``conditions`` when they are active and a record is the ballbar's,
    the interferometer's or the step gauge's, else None (the extended fit, told an ideal
    world)."""
    # The bar, the laser and the step gauge's probe read to 0.1-0.35 um, where the drives'
    # lead, lost motion and warm-up move the TCP by microns: a fit without their terms
    # misfits those readings by several sigma and leaves them out one refit at a time, up
    # to its outlier cap.  The dials' 20 um hide those terms, so their refits stay the
    # extended fit.
    world = conditions_or_default(conditions)
    drives = (BallbarSpec, InterferometerAxis, StepGaugeSpec)
    return world if world.active and any(isinstance(r.spec, drives) for r in records) else None


@lru_cache(maxsize=8)
def _refitter(sigma: float, conditions: Conditions | None = None) -> Estimator:
    """The estimator of the refits, for readings of weighting ``sigma`` (mm), made once:
    the extended estimator, or with ``conditions`` ``full`` told them (a notebook that
    holds readings of the drives under an active world: :func:`refit_world`).  Only its
    estimate is read, so its error bars' curvature and the words on the faults it finds
    are left out."""
    estimator = (for_study("extended", sigma) if conditions is None
                 else for_study("full", sigma, conditions))
    return estimator.clone(curvature=False, fault_words=False)


@register
class ActiveAgent(Agent):
    name = "active"
    criterion = "I"
    shares_a_plan = True
    #: Stop once the predicted TCP error after rigid motion is at most this (mm); 0: use
    #: the whole budget.
    target_mm: float = 0.0
    #: Whether the instruments the lab owns beyond its dials are among the options (a
    #: reference procedure that plays its instrument first leaves the rest to the dials).
    plans_instruments: bool = True
    #: Whether its moves read a laser that is set up at every move, also in a lab that lets
    #: a move leave it unread (``OrthoglideLab-v4``).  Its refits use those readings (the
    #: drift, the drive's sections its runs leave, the scale) though its planner prices
    #: them at nothing: leaving them unread made its fits worse per machine, 1.26 [1.05,
    #: 1.39] with the three instruments at one hour under ``lab`` (docs/instruments.md, "A
    #: move that does not wait for the laser").
    laser_at_every_move: bool = True

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        super().reset(env, observation, rng)
        setup = lab_setup(self.env, observation, self.reserved_s)
        slots, engaged, sigma, budget, design, conditions = setup
        owned = owned_instruments(self.env) if self.plans_instruments else ()
        asked = leaves_laser_unread(self)
        dwell_s, start = move_dwell_s(observation, asked), float(observation["time"][0])
        self.planner = Planner(list(slots), list(engaged), sigma, budget + start,
                               criterion=self.criterion, design=design, conditions=conditions,
                               instruments=owned, dwell_s=dwell_s, laser_asked=asked)
        steps, _ = fixed_plan(*setup, criterion=self.criterion, instruments=owned,
                              dwell_s=dwell_s, laser_asked=asked)
        # The fixed plan's clock starts at 0 where the lab's reads ``start``: after a
        # reference procedure's programme, its re-mounts and bundles are due that much later.
        self.remounts = [s._replace(time_s=start + s.time_s) for s in steps
                         if s.op == Op.REMOUNT]
        # The instruments' bundles, taken when and as the fixed plan takes them (as its
        # re-mounts are); the operations of the one under way left, and its first record.
        relaxed = plan_bundles(slots, sigma, budget, design, conditions, owned, asked)
        self.bundles = [(start + t, b) for t, b in planned_bundles(steps, design, owned, tuple(
            b for group in relaxed for b in group))] if owned else []
        self.bundle: Bundle | None = None
        self.bundle_left, self.bundle_first = 0, 0
        self.readings: dict[int, list[tuple[int, float]]] = {k: [] for k in range(len(slots))}
        self.queue: list[PlannedOperation] = []
        self.last: PlannedOperation | None = None
        self.fitted = start
        # Imported here: the experiment module imports the agents package.
        from calibrators.study.episodes import NotebookReadings
        self.notebook = NotebookReadings(design)  # what the refits read, kept converted
        self._observe(observation, {})

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        return self.act_all([self], [observation], [info])[0]

    @classmethod
    def act_all(cls, agents: list[Agent], observations: list[dict[str, np.ndarray]],
                infos: list[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """Each agent takes in its lab's observation and readies its next operation; those
        that choose a move now choose together (:func:`~calibrators.planning.search.
        best_moves`, their beliefs' prices stacked over the chunk's machines), each the
        move it would choose alone; their filters take in their dials' readings together
        too (:func:`~calibrators.planning.belief.observe_many`)."""
        seen = []
        for agent, observation, info in zip(agents, observations, infos, strict=True):
            if agent.bundle_left:
                agent.bundle_left -= 1
                if not agent.bundle_left:
                    agent._observe_bundle(observation)
            elif agent.last is not None and not info.get("refused"):
                read = agent._seen(observation, info)
                if read is not None:
                    seen.append((agent, *read))
        observe_many([a.planner for a, _, _ in seen], [s for _, s, _ in seen],
                     [v for _, _, v in seen])
        for agent, stands, values in seen:
            agent._note(stands, values)
        steps: list[PlannedOperation | None] = [
            agent._ready(float(observation["time"][0]))
            for agent, observation in zip(agents, observations, strict=True)]
        choosing = [i for i, step in enumerate(steps) if step is None]
        choices = best_moves([agents[i].planner for i in choosing])
        for i, choice in zip(choosing, choices, strict=True):
            steps[i] = agents[i]._moved(choice)
        out = []
        for agent, step in zip(agents, steps, strict=True):
            agent.last = step
            out.append(action(step.op, step.rho, step.stand, step.slot, **operation_keys(step)))
        return out

    # -- what was seen -------------------------------------------------------------------
    def _observe(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        """Take in the readings of the last move or re-mount (or of the reset)."""
        read = self._seen(observation, info)
        if read is not None:
            self.planner.observe(*read)
            self._note(*read)

    def _seen(self, observation: dict[str, np.ndarray], info: Mapping[str, Any]
              ) -> tuple[list[int], list[float]] | None:
        """The stands and readings of the last move or re-mount (or of the reset) for the
        filter to take in (None: nothing to take in), its clock and stands brought up to
        date."""
        planner = self.planner
        planner.time_s = float(observation["time"][0])
        for text in info.get("overtravel", []):
            # A stand pushed past its travel reads nothing until it is re-mounted.
            planner.retire(int(text.split()[1]))
        if self.last is not None and self.last.op not in (Op.MOVE, Op.REMOUNT):
            return None
        if self.last is not None and self.last.op == Op.REMOUNT:
            self.readings[self.last.stand] = []
        stands = [k for k in range(len(planner.slots))
                  if observation["valid"][k] and planner.slots[k] >= 0]
        return stands, [float(observation["gauges"][k]) for k in stands]

    def _note(self, stands: list[int], values: list[float]) -> None:
        """Keep the readings the filter took in, for the refits' zeros."""
        for k, value in zip(stands, values, strict=True):
            self.readings[k].append((self.planner.here, value))

    def _observe_bundle(self, observation: dict[str, np.ndarray]) -> None:
        """Take in the readings of the instrument's bundle just played (the notebook's
        records of its set-up)."""
        planner, bundle = self.planner, self.bundle
        planner.time_s = float(observation["time"][0])
        kind = InterferometerAxis if bundle.instrument == "interferometer" else BallbarSpec
        records = [r for r in self.env.records[self.bundle_first:] if isinstance(r.spec, kind)]
        if records:
            last = records[-1].mounting
            records = [r for r in records if r.mounting == last]
        observe_bundle(planner, bundle, np.array([r.rho for r in records]).reshape(-1, 3),
                       np.array([r.reading for r in records]))

    # -- what to do next -------------------------------------------------------------------
    def _ready(self, now: float) -> PlannedOperation | None:
        """The next operation, or None when it is a move the planner is to choose
        (:meth:`_moved` then takes it)."""
        planner = self.planner
        if self.queue:
            return self.queue.pop(0)
        if now - self.fitted >= REFIT_S:
            self._refit()
            self.fitted = now
        if self.target_mm > 0 and planner.predicted_rigid_mm() <= self.target_mm:
            return PlannedOperation(Op.STOP)
        # The fixed plan's bundles and re-mounts are replayed when the lab's clock reaches
        # the plan's time for them, after a move of this agent's own that may pass that
        # time (and an overtravel's re-install may add minutes): one that would then end
        # past the budget is dropped, and the planner chooses moves for the time left.
        start = len(planner.steps)
        if self.bundles and self.bundles[0][0] <= now:
            if not self._bundle_fits():
                self.bundles.pop(0)
                return None
            self._take_bundle()
        elif self.remounts and self.remounts[0].time_s <= now:
            remount = self.remounts.pop(0)
            if now + planner.remount_seconds() > planner.budget_s:
                return None
            planner.remount(remount.stand, remount.slot)
        else:
            return None
        return self._queued(start)

    def _moved(self, choice: tuple[int, PricedMoves] | None) -> PlannedOperation:
        """The next operation after the planner's choice of move (:meth:`~calibrators.
        planning.search.Planner.best_move`'s): that move, else the plan's next bundle
        early (the dials pay no more), else stop."""
        start = len(self.planner.steps)
        if choice is None and not self._bundle_fits():
            return PlannedOperation(Op.STOP)
        if choice is None:
            self._take_bundle()
        else:
            self.planner.move(*choice)
        return self._queued(start)

    def _queued(self, start: int) -> PlannedOperation:
        """The first of the planner's operations from ``start`` on, the rest queued."""
        self.queue = list(self.planner.steps[start:])
        return self.queue.pop(0)

    def _take_bundle(self) -> None:
        """Start the fixed plan's next instrument bundle (its operations in the steps)."""
        _, self.bundle = self.bundles.pop(0)
        self.bundle_first = len(self.env.records)
        self.bundle_left = len(take(self.planner, self.bundle))

    def _bundle_fits(self) -> bool:
        """Whether the fixed plan's next bundle fits in the budget left."""
        if not self.bundles:
            return False
        trial = self.planner.fork()
        take(trial, self.bundles[0][1])
        return trial.time_s <= trial.budget_s

    def _refit(self) -> None:
        """Replace the filter's mean by the extended estimator's fit of the notebook."""
        records = self.env.records
        planner = self.planner
        told = refit_world(planner.conditions, records)
        try:
            est = _refitter(planner.sigma, told).fit(self.notebook.of(records))
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            return  # the filter goes on alone; the next refit has more data
        theta = dict(zip(est.space, est.theta, strict=True))
        mean = planner.mean.copy()
        mean[:N_MACHINE] = est.theta[:N_MACHINE] / default_scales(ParameterSpace())
        for k, slot in enumerate(planner.slots):
            mounting = self._mounting(k)
            if slot < 0 or mounting is None:
                continue
            names = stand_names(mounting, self.env.slots[slot])
            space = ParameterSpace((mounting,), (self.env.slots[slot],))
            cols = N_MACHINE + N_STAND * k + np.arange(4)
            mean[cols] = [theta.get(n, 0.0) for n in names] / default_scales(space)[
                len(ERROR_NAMES):]
            # The zero that makes the stand's readings agree with the new mean on average.
            mean[cols[-1] + 1] = 0.0
            if self.readings[k]:
                postures = [p for p, _ in self.readings[k]]
                values = np.array([v for _, v in self.readings[k]])
                nominal = planner.table.reading[slot, postures]
                residual = values - nominal - planner.rows_at(postures, [k])[:, 0] @ mean
                mean[cols[-1] + 1] = np.mean(residual) / ZERO_SCALE
        planner.mean = mean

    def _mounting(self, stand: int) -> str | None:
        """The name the notebook gives the stand's present mounting (its latest record at
        the stand's slot)."""
        spec = self.env.slots[self.planner.slots[stand]]
        return next((r.mounting for r in reversed(self.env.records) if r.spec == spec), None)
