"""The verification a technician runs, played on virtual machines: each machine's
experiment fitted told a world, then played again through the compensated controller in
the true world and verified told that world (``benchmarks/verify_world.py``)."""

from __future__ import annotations

from contextlib import closing

import gymnasium as gym

from calibrators.agents import get_agent
from calibrators.estimators.catalogue import for_study
from calibrators.measurements import Measurements
from calibrators.study.compare import Config
from calibrators.study.episodes import machine_seed, run_episode
from calibrators.study.labs import lab_id
from calibrators.workflow.verify import CompensatedAgent, Verification, verify, world_test
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import machine_dict

#: The verification's reset seeds are the calibration's plus this: the same machine and
#: world (given as the reset's machine), another noise stream.
VERIFICATION_STREAM: int = 500_000

Verified = tuple[Verification, str, Measurements]


def verifications(stated: str, agent: str, episodes: list, config: Config
                  ) -> list[Verified | Exception]:
    """Each machine of ``episodes`` (``agent``'s experiments in ``config``'s world) fitted
    by ``full`` told ``stated``, its experiment played again through the estimate's
    compensated controller (:class:`~calibrators.workflow.verify.CompensatedAgent`) in
    ``config``'s world, and verified told ``stated``: the verification, the world test's
    words ("" when the readings show no worse world) and the readings; an exception where
    the fit or the verification failed (kept, never dropped)."""
    told = Conditions(stated)
    estimates = for_study("full", episodes[0].run.sigma, told, "realistic").fit_many(
        [e.run.measurements for e in episodes])
    kwargs = config.lab_kwargs(get_agent(agent))
    out: list[Verified | Exception] = []
    with closing(gym.make(lab_id(kwargs), **kwargs)) as lab:
        for e, est in zip(episodes, estimates, strict=True):
            if isinstance(est, Exception):
                out.append(est)
                continue
            player = CompensatedAgent(get_agent(agent), est)
            played = run_episode(lab, player, machine_seed(config.seed, e.machine)
                                 + VERIFICATION_STREAM,
                                 {"machine": machine_dict(e.run.truth, e.run.world)})
            readings = player.readings(played)
            try:
                out.append((verify(est, readings, told), world_test(est, readings, told),
                            readings))
            except ValueError as exc:
                out.append(exc)
    return out
