"""Faults in the lab: they draw from a stream of their own, so a lab with faults reads as
one without until the first one acts, and each acts as its kind says on the readings the
agent sees and the notebook holds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.study.episodes import run_episode
from orthoglide_env.world.faults import (
    FAULT_KINDS,
    Faults,
    as_faults,
    fault_stream,
    happened,
    schedule,
)

#: Seed 1's fault stream (:func:`fault_stream` of ``default_rng(1)``) schedules the first
#: fault of every kind list below at 183 s of a 20-minute budget.
SEED, BUDGET, FIRST_S = 1, 1200.0, 183.0


def episode(faults: str | None, seed: int = SEED, agent: str = "optimal",
            budget: float = BUDGET):
    """One episode of ``agent`` under ``lab`` conditions (explicit: the default changes)."""
    kwargs = {"faults": faults} if faults else {}
    env = gym.make(orthoglide_env.LAB_ENV_ID, conditions="lab", errors="realistic",
                   gauge_sigma=0.02, budget_s=budget, **kwargs)
    return run_episode(env, get_agent(agent), seed)


@pytest.fixture(scope="session")
def clean():
    """The episode without faults, which every fault's is held against (read only)."""
    return episode(None)


@pytest.fixture(scope="session")
def pair(clean):
    """The same machine and seed without faults and with every kind of fault."""
    return clean, episode(",".join(FAULT_KINDS))


def test_a_seed_schedules_its_faults_before_the_episode_draws() -> None:
    for kinds in (FAULT_KINDS, ("knock",), ("sign",)):
        events = schedule(Faults(kinds), fault_stream(np.random.default_rng(SEED)), "lab",
                          BUDGET)
        assert round(events[0][0]) == FIRST_S


@pytest.mark.slow
def test_until_the_first_fault_the_readings_are_those_of_a_lab_without(pair) -> None:
    clean, faulted = pair
    # It acts at the first look at the machine from its time on.
    assert faulted.faults and faulted.faults[0]["time_s"] >= FIRST_S
    first = faulted.faults[0]["step"]
    before = [(r.mounting, r.rho, r.reading) for r in clean.records if r.step < first]
    assert before == [(r.mounting, r.rho, r.reading) for r in faulted.records if r.step < first]
    assert clean.truth.to_vector().tolist() == faulted.truth.to_vector().tolist()


@pytest.mark.slow
def test_a_knock_moves_its_mounting_readings_by_its_size_and_nothing_else(clean) -> None:
    knocked = episode("knock")
    events = [e for e in knocked.faults if e["stand"] >= 0]
    assert events, "no knock acted on this seed"
    event = events[0]
    later = [e["step"] for e in knocked.faults[1:]] or [10**9]

    def values(book, mounting):
        return {(r.step, r.rho): r.reading for r in book.records if r.mounting == mounting
                and event["step"] <= r.step < later[0]}

    a, b = values(clean, event["mounting"]), values(knocked, event["mounting"])
    assert a.keys() == b.keys() and a
    # The noise draws are the same (the fault stream is another): the difference is the
    # knock exactly, to float rounding of a sum of a few mm.
    assert np.allclose([b[k] - a[k] for k in a], event["size"], atol=1e-12)
    others = [(r.mounting, r.step, r.reading) for r in clean.records
              if r.mounting != event["mounting"] and r.step < later[0]]
    assert others == [(r.mounting, r.step, r.reading) for r in knocked.records
                      if r.mounting != event["mounting"] and r.step < later[0]]


def test_a_sign_slip_negates_one_written_reading(clean) -> None:
    slipped = episode("sign")
    events = [e for e in slipped.faults if e["stand"] >= 0]
    assert events, "no sign slip acted on this seed"
    a = [(r.mounting, r.step, r.reading) for r in clean.records]
    b = [(r.mounting, r.step, r.reading) for r in slipped.records]
    changed = [(x, y) for x, y in zip(a, b, strict=True) if x != y]
    # A slip of a reading of 0 (a dial at Zero) writes the same number.
    assert 1 <= len(changed) <= len(events)
    for (_, _, value), (_, _, written) in changed:
        assert written == -value


def test_faults_are_named_by_kind_and_refused_otherwise() -> None:
    assert as_faults("lost-steps, knock").kinds == ("knock", "lost-steps")
    assert as_faults(None) == Faults() and not Faults().active
    with pytest.raises(ValueError, match="unknown fault kind 'bump'; kinds are knock"):
        as_faults("knock,bump")
    with pytest.raises(ValueError, match="faults must be a list of fault kinds"):
        as_faults(3)
    assert happened([{"kind": "knock", "stand": -1}, {"kind": "lost-steps", "stand": -1},
                     {"kind": "sign", "stand": 2}]) == ["sign", "lost-steps"]


def test_a_fit_without_the_words_on_faults_gives_the_same_estimate(monkeypatch) -> None:
    """``fault_words=False`` (the ``active`` agent's refits read only the estimate) looks
    for faults only as far as a repair can change the estimate: the same estimate to the
    bit as with the words, on a clean notebook and on one whose stands were knocked (both
    refitted with the knocked stands' new mountings), and the drives' test, which repairs
    nothing, left out where no stand steps."""
    from calibrators.estimators import gauss_newton
    from calibrators.estimators.catalogue import for_study

    made = []
    sensitivities = gauss_newton.drive_sensitivities
    monkeypatch.setattr(gauss_newton, "drive_sensitivities",
                        lambda *args: made.append(1) or sensitivities(*args))
    named = for_study("extended", 0.02)
    quiet = named.clone(fault_words=False)
    for kinds, knocked in ((None, False), ("knock", True)):
        data = episode(kinds).measurements
        with_words = named.fit(data)
        made.clear()
        without = quiet.fit(data)
        assert np.array_equal(without.theta, with_words.theta)
        knocks = [w for w in with_words.warnings if w.startswith("fault knock")]
        assert bool(knocks) == knocked
        assert [w for w in without.warnings if w.startswith("fault knock")] == knocks
        assert bool(made) == knocked
