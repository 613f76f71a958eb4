"""``active``'s filter beside the design view (:mod:`calibrators.planning.active_expert`):
its expert is ``active``, and a policy of its view plays in the lab as it did in training."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import pytest
from conftest import assert_view_plays_as_lab, tiny_maskable_policy
from gymnasium.utils.env_checker import check_env

import orthoglide_env
from calibrators.agents.names import get_agent
from calibrators.agents.policy import DesignPolicyAgent, read_spec
from calibrators.planning.active_expert import FilteredDesignLab, filtered_design_lab_env
from calibrators.planning.design_expert import PlanExpert
from calibrators.study import compare
from calibrators.study.episodes import machine_seed, run_episode
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.wrappers import design_lab_env

BUDGET_S = 330.0
LAB = {"conditions": "lab", "gauge_sigma": 0.02, "budget_s": BUDGET_S}


def played_alone(env: gym.Env, seed: int) -> list:
    """The notebook of the view's expert playing a whole episode of ``env`` reset with
    ``seed``."""
    env.reset(seed=seed)
    expert = env.expert if isinstance(env, FilteredDesignLab) else PlanExpert(env.unwrapped,
                                                                             env.belief)
    done = False
    while not done:
        chosen = expert.choose(env.belief)
        _, _, terminated, truncated, _ = env.step(chosen)
        expert.follow(chosen, env.belief)
        done = terminated or truncated
    return env.unwrapped.records


@pytest.mark.slow
def test_the_active_expert_played_alone_reads_what_active_reads() -> None:
    """On the comparison's machines, the filtered view's expert takes ``active``'s
    operations: the same postures, plungers and readings, value for value, until the last
    move.  The last seconds may differ: the view opens a move when the lab's drive fits the
    budget, ``active``'s planner when its priced move (the world's dwell included) does.
    And it reads more than the fixed plan's flicks let ``optimal``'s expert read."""
    config = compare.Config(("active",), ("full",), budget_s=BUDGET_S, errors=DEFAULT_PRESET,
                            sigma=0.02, seed=1, conditions=Conditions("lab"))
    kwargs = config.lab_kwargs(get_agent("active"))
    machines = [0, 1, 2]
    filtered_readings = prior_readings = 0
    for machine, episode in zip(machines, compare.agent_episodes(config, "active", machines),
                                strict=True):
        seed = machine_seed(1, machine)
        records = played_alone(filtered_design_lab_env(version=1, **kwargs), seed)
        early = [(r.spec, r.mounting, r.rho, r.reading, r.time_s) for r in records
                 if r.time_s < BUDGET_S - 5.0]
        theirs = [(r.spec, r.mounting, r.rho, r.reading, r.time_s) for r in episode.run.records
                  if r.time_s < BUDGET_S - 5.0]
        assert early == theirs
        # Not vacuous: most of the episode is compared.
        assert len(early) >= 0.9 * len(episode.run.records)
        filtered_readings += len(records)
        prior_readings += len(played_alone(design_lab_env(version=1, **kwargs), seed))
    # About 3.0 readings a posture against 2.7 (benchmarks/episode_habits.py on 10 machines:
    # medians 111 and 95 readings); summed over three machines the margin is far above
    # one machine's spread.
    assert filtered_readings > 1.05 * prior_readings


@pytest.mark.parametrize("reach", [False, True], ids=["flicks", "reach"])
def test_check_env_of_the_filtered_view(reach: bool) -> None:
    """The filtered view passes Gymnasium's check (random actions, re-mounts onto held
    slots and onto a stand's own among them); with ``reach`` its observation has one more
    entry per candidate posture, each in [0, 1]."""
    env = filtered_design_lab_env(version=1, reach=reach, conditions="lab", gauge_sigma=0.02,
                                  budget_s=120.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    # The one warning left says the env is a wrapper, which it is by design.
    messages = [str(w.message) for w in caught]
    assert all("different from the unwrapped version" in m for m in messages), messages
    assert env.observation_space.shape == (272 + reach * env.belief.n_postures,)


@pytest.fixture(scope="module", params=[False, True], ids=["flicks", "reach"])
def filtered_policy(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest
                    ) -> Path:
    """A tiny MaskablePPO policy of the filtered view (v1; its observation with the
    filter's reach or not), played by its argmax."""
    pytest.importorskip("sb3_contrib")
    env = filtered_design_lab_env(version=1, reach=request.param, **LAB)
    return tiny_maskable_policy(env, LAB, tmp_path_factory.mktemp("policy") / "filtered.zip")


def test_a_filtered_policy_plays_in_the_lab_as_in_its_view(filtered_policy: Path) -> None:
    """``policy:FILE`` of a policy trained in the filtered view keeps ``active``'s filter
    beside its belief: its episode in the lab is the one the view plays with the same
    network's most likely open operation, reading for reading; the file says how its
    plungers go down and what its network sees."""
    spec = read_spec(filtered_policy)
    assert spec.flicks == "filter"
    agent = get_agent(f"policy:{filtered_policy}")
    assert isinstance(agent, DesignPolicyAgent)
    episode = run_episode(gym.make(orthoglide_env.LAB_ENV_ID, **LAB), agent, seed=4)
    view = filtered_design_lab_env(version=1, reach=spec.reach, **LAB)
    assert view.observation_space.shape[0] == 272 + spec.reach * view.belief.n_postures
    assert_view_plays_as_lab(view, agent, episode, 4)
