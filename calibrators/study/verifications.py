"""The verification a technician runs, played on virtual machines: each machine's
experiment fitted told a world, then a verification played through the compensated
controller in the true world (the calibration's own experiment again, or ISO 230-4's
circles with a ballbar) and verified told that world (``benchmarks/verify_world.py``)."""

from __future__ import annotations

from contextlib import closing
from dataclasses import replace

import gymnasium as gym

from calibrators.agents import get_agent
from calibrators.agents.base import PlannedAgent
from calibrators.estimators.catalogue import for_study
from calibrators.measurements import Measurements
from calibrators.study.compare import Config
from calibrators.study.episodes import machine_seed, run_episode
from calibrators.study.labs import lab_id
from calibrators.workflow.verify import (
    BallbarCircles,
    CompensatedAgent,
    Verification,
    verify,
    world_test,
)
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import machine_dict

#: The verification's reset seeds are the calibration's plus this: the same machine and
#: world (given as the reset's machine), another noise stream.
VERIFICATION_STREAM: int = 500_000

Verified = tuple[Verification, str | None, Measurements]

#: What a verification reads with: ``same``, the calibration's own experiment again
#: (its agent, its instruments); ``ballbar``, ISO 230-4's circles with a ballbar
#: (:class:`~calibrators.workflow.verify.BallbarCircles`), in a lab that owns one.
VERIFIERS: tuple[str, ...] = ("same", "ballbar")


def verifications(stated: str, agent: str, episodes: list, config: Config,
                  instrument: str = "same") -> list[Verified | Exception]:
    """Each machine of ``episodes`` (``agent``'s experiments in ``config``'s world) fitted
    by ``full`` told ``stated``, a verification played through the estimate's
    compensated controller (:class:`~calibrators.workflow.verify.CompensatedAgent`) in
    ``config``'s world by ``instrument`` (:data:`VERIFIERS`), and verified told
    ``stated``: the verification, the world test's words ("" when the readings show no
    worse world; None for a ballbar's: the fit's world test does not take the families of
    a ballbar's terms, its scale error and the drives' give, yet) and the readings; an
    exception where the fit or the verification failed (kept, never dropped).
    ``ValueError`` for an unknown ``instrument``."""
    if instrument not in VERIFIERS:
        raise ValueError(f"unknown verification instrument '{instrument}'; one of "
                         f"{', '.join(VERIFIERS)}")
    told = Conditions(stated)
    estimates = for_study("full", episodes[0].run.sigma, told, "realistic").fit_many(
        [e.run.measurements for e in episodes])
    ballbar = instrument == "ballbar"

    def verifier() -> PlannedAgent:
        return BallbarCircles() if ballbar else get_agent(agent)

    kwargs = (replace(config, instruments=("dial", "ballbar")) if ballbar
              else config).lab_kwargs(verifier())
    out: list[Verified | Exception] = []
    with closing(gym.make(lab_id(kwargs), **kwargs)) as lab:
        for e, est in zip(episodes, estimates, strict=True):
            if isinstance(est, Exception):
                out.append(est)
                continue
            player = CompensatedAgent(verifier(), est)
            run = run_episode(lab, player, machine_seed(config.seed, e.machine)
                              + VERIFICATION_STREAM,
                              {"machine": machine_dict(e.run.truth, e.run.world)})
            readings = player.readings(run)
            try:
                world = None if ballbar else world_test(est, readings, told)
                out.append((verify(est, readings, told), world, readings))
            except ValueError as exc:
                out.append(exc)
    return out
