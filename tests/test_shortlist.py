"""``active``'s short list as a policy's actions (:mod:`calibrators.planning.shortlist`): the
mask opens ``active``'s choice and its next best moves only, the view plays ``active``'s
episode when the policy takes the choice, and ``policy:FILE`` plays as its view did."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_view_plays_as_lab, tiny_maskable_policy
from gymnasium.utils.env_checker import check_env

import orthoglide_env
from calibrators.agents.names import get_agent
from calibrators.agents.policy import DesignPolicyAgent, read_spec
from calibrators.planning.active_expert import filtered_design_lab_env
from calibrators.planning.shortlist import (
    RANK_FEATURES,
    SHORTLIST_MOVES,
    LookaheadExpert,
    RankLabels,
    listed_moves,
    played_out,
    ranked_shortlist_lab_env,
    shortlist_design_lab_env,
    shortlist_mask,
)
from calibrators.study.episodes import run_episode

#: A short episode: some twenty decisions, enough to leave Zero's neighbourhood.
LAB = {"conditions": "lab", "gauge_sigma": 0.02, "budget_s": 120.0}


def test_the_mask_opens_actives_choice_and_its_next_best_moves() -> None:
    """At every state of an episode played at random among the open operations: stop and
    ``active``'s choice are open, at most :data:`SHORTLIST_MOVES` moves are, each one the
    filter opens, and no move the filter opens but the mask shuts has a higher gain per
    second than an open one other than the choice."""
    env = shortlist_design_lab_env(version=1, **LAB)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    n = env.belief.n_postures
    widest, done = 0, False
    while not done:
        mask = env.action_masks()
        chosen = env.expert.choose(env.belief)
        opened = env.expert.action_mask(env.belief)
        assert mask[chosen] and mask[-1]
        assert not np.any(mask & ~opened)
        moves = np.flatnonzero(mask[:n])
        assert len(moves) <= SHORTLIST_MOVES
        widest = max(widest, len(moves))
        rate, _ = env.expert.planner.top_rates(SHORTLIST_MOVES)
        others = [p for p in moves if p != chosen]
        shut = opened[:n] & ~mask[:n]
        if chosen < n:
            shut[chosen] = False
        if others:
            assert np.all(rate[others].min() >= rate[shut])
        _, _, terminated, truncated, _ = env.step(int(rng.choice(np.flatnonzero(mask))))
        done = terminated or truncated
    # Not vacuous: the list was full at some state.
    assert widest == SHORTLIST_MOVES
    with pytest.raises(ValueError, match="at least 1 move"):
        shortlist_mask(env.expert, env.belief, moves=0)


def test_taking_the_choice_plays_the_filtered_views_episode() -> None:
    """The short list's view changes only the mask: taking ``active``'s choice at every
    state reads what the filtered view's expert reads, value for value."""
    played = []
    for make in (shortlist_design_lab_env, filtered_design_lab_env):
        env = make(version=1, **LAB)
        env.reset(seed=5)
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(env.expert.choose(env.belief))
            done = terminated or truncated
        played.append([(r.spec, r.rho, r.reading) for r in env.unwrapped.records])
    assert played[0] == played[1]
    assert len(played[0]) > 12


@pytest.mark.parametrize("make", [shortlist_design_lab_env, ranked_shortlist_lab_env])
def test_check_env_of_the_shortlist_views(make: object) -> None:
    """Gymnasium's check passes (its one warning: the env is a wrapper)."""
    env = make(version=1, **LAB)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    messages = [str(w.message) for w in caught]
    assert all("different from the unwrapped version" in m for m in messages), messages


def test_the_lookahead_takes_the_move_whose_greedy_play_out_ends_lowest() -> None:
    """Along an episode it plays itself: its choice is open in the short list, and the
    greedy play-out after it ends no higher than after ``active``'s choice and below the
    criterion now; a play-out leaves the filter as it was (it plays on a copy).  And it
    departs from ``active`` somewhere."""
    env = shortlist_design_lab_env(version=1, **LAB)
    env.reset(seed=3)
    expert = LookaheadExpert(env.expert)
    n = env.belief.n_postures
    departed, done = 0, False
    while not done:
        chosen, theirs = expert.choose(env.belief), env.expert.choose(env.belief)
        assert env.action_masks()[chosen]
        if theirs < n:
            planner = env.expert.planner
            now = planner._criterion_value(), planner.time_s, list(planner.engaged)
            ends = played_out(planner, chosen), played_out(planner, theirs)
            assert ends[0] <= ends[1] < now[0]
            assert (planner._criterion_value(), planner.time_s, list(planner.engaged)) == now
        departed += chosen != theirs
        _, _, terminated, truncated, _ = env.step(chosen)
        done = terminated or truncated
    assert departed >= 1


@pytest.mark.parametrize(("make_view", "flicks"), [(shortlist_design_lab_env, "shortlist"),
                                                    (ranked_shortlist_lab_env, "ranked")])
def test_a_shortlist_policy_plays_in_the_lab_as_in_its_view(
        make_view, flicks: str, tmp_path: Path) -> None:
    """``policy:FILE`` of a short list's view (the list's mask, or its ranks with the listed
    moves' features after the view's observation) narrows its choice as the view did: its
    episode in the lab is the view's with the same network's most likely open operation."""
    pytest.importorskip("sb3_contrib")
    policy = tiny_maskable_policy(make_view(version=1, **LAB), LAB, tmp_path / f"{flicks}.zip")
    assert read_spec(policy).flicks == flicks
    agent = get_agent(f"policy:{policy}")
    assert isinstance(agent, DesignPolicyAgent)
    episode = run_episode(gym.make(orthoglide_env.LAB_ENV_ID, **LAB), agent, seed=4)
    assert_view_plays_as_lab(make_view(version=1, **LAB), agent, episode, 4)


def test_the_ranked_view_names_the_short_list_and_sees_its_moves() -> None:
    """Along an episode played at random among the listed ranks: rank ``r`` plays the short
    list's ``r``-th operation (the list the short-list view's mask opens), the mask opens
    the ranks the list fills and stop, and each listed move's features are its own: the
    best rate of the list is 1, a stay is flagged where the belief stands, the readings so
    far are the belief's tally there; ranks past the list's end are zeros; a listed move
    leaves the belief at its posture."""
    env = ranked_shortlist_lab_env(version=1, **LAB)
    observation, _ = env.reset(seed=3)
    rng = np.random.default_rng(1)
    n, revisits, done = env.belief.n_postures, 0, False
    while not done:
        listed, _, _ = listed_moves(env.expert, env.belief)
        assert listed == env.listed
        opened = np.flatnonzero(shortlist_mask(env.expert, env.belief))
        assert sorted({*listed, env.belief.n_actions - 1}) == opened.tolist()
        assert env.action_masks().tolist() == [r < len(listed) for r in
                                               range(SHORTLIST_MOVES)] + [True]
        features = observation[-SHORTLIST_MOVES * RANK_FEATURES:].reshape(SHORTLIST_MOVES, -1)
        moves = [r for r, p in enumerate(listed) if p < n]
        if moves:
            assert features[moves, 2].max() == pytest.approx(1.0)
        for r, p in enumerate(listed):
            if p < n:
                assert features[r, 7] == (p == env.belief.here)
                assert features[r, 6] == pytest.approx(env.belief.readings_at[p] / 10.0)
                revisits += env.belief.readings_at[p] > 0
        assert not features[len(listed):].any()
        # A random listed operation (the list holds at least ``active``'s choice; stop only
        # where that is it).
        rank = int(rng.choice(np.flatnonzero(env.action_masks()[:-1])))
        here = listed[rank]
        readings = len(env.unwrapped.records)
        observation, _, terminated, truncated, _ = env.step(rank)
        done = terminated or truncated
        if here < n and not done:
            assert env.belief.here == here and len(env.unwrapped.records) > readings
    # Not vacuous: a posture read before was listed somewhere.
    assert revisits >= 1
    with pytest.raises(ValueError, match="an action is an integer"):
        env.step(SHORTLIST_MOVES + 1)


def test_ranked_labels_name_the_experts_operation() -> None:
    """A view expert's label as a rank (:class:`RankLabels`) names the operation the
    expert chose, along the lookahead's own episode; an operation off the list is refused."""
    env = ranked_shortlist_lab_env(version=1, **LAB)
    env.reset(seed=5)
    lookahead = LookaheadExpert(env.expert)
    labels = RankLabels(lookahead, env)
    ranks, done = [], False
    while not done:
        rank = labels.choose(env.belief)
        chosen = lookahead.choose(env.belief)
        assert [*env.listed, env.belief.n_actions - 1][rank] == chosen
        ranks.append(rank)
        _, _, terminated, truncated, _ = env.step(rank)
        done = terminated or truncated
    # The lookahead departs from ``active``'s choice (rank 0) somewhere.
    assert max(ranks[:-1]) >= 1
    off = next(p for p in range(env.belief.n_postures) if p not in env.listed)
    with pytest.raises(ValueError, match="not on the short list"):
        env.rank_of(off)


def test_ppo_starts_from_the_file_s_actor_and_refuses_another_world(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """``train_masked.py --start FILE``: before any PPO update the model's actor is the
    file's, weight for weight, so it takes the file's operations (its logits, as
    ``policy:FILE`` reads them in NumPy, agree to float32 rounding, 1e-5 at logits of
    order 1); its critic alone is fitted, to that actor's returns, so it moves off the
    file's.  A file of another world is refused, naming what differs."""
    sb3_contrib = pytest.importorskip("sb3_contrib")
    torch = pytest.importorskip("torch")
    monkeypatch.syspath_prepend(str(Path(__file__).parents[1] / "examples"))
    from train_masked import (
        check_start,
        env_kwargs,
        parse,
        point_file,
        recorded,
        start_from,
        view,
    )

    argv = ["--expert", "active-ranked", "--view", "1", "--conditions", "lab", "--sigma",
            "0.02", "--budget", "120", "--steps", "64", "--episodes", "2", "--updates", "50",
            "--envs", "1", "--seed", "7"]
    kwargs = env_kwargs(parse(argv))
    path = tiny_maskable_policy(view(kwargs, "active-ranked"), recorded(kwargs),
                                tmp_path / "start.zip")
    args = parse([*argv, "--start", str(path)])
    model = sb3_contrib.MaskablePPO("MlpPolicy", view(kwargs, "active-ranked"), seed=1,
                                    device="cpu")
    start_from(args, kwargs, model)
    saved = sb3_contrib.MaskablePPO.load(path, device="cpu").policy.state_dict()
    now = model.policy.state_dict()
    actor = [k for k in saved if k.startswith(("mlp_extractor.policy_net", "action_net"))]
    critic = [k for k in saved if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert actor and critic
    assert all(torch.equal(now[k], saved[k]) for k in actor)
    assert not all(torch.equal(now[k], saved[k]) for k in critic)
    agent = get_agent(f"policy:{path}")
    env = view(kwargs, "active-ranked")
    observation, _ = env.reset(seed=11)
    done = False
    while not done:
        with torch.no_grad():
            logits = model.policy.action_net(model.policy.mlp_extractor.forward_actor(
                torch.as_tensor(observation[None])))[0].numpy()
        np.testing.assert_allclose(logits, agent.actor.logits(observation), atol=1e-5)
        mask = env.action_masks()
        rank = int(np.argmax(np.where(mask, logits, -np.inf)))
        observation, _, terminated, truncated, _ = env.step(rank)
        done = terminated or truncated
    check_start(args, kwargs)
    # PPO's curve points are kept and chosen among; a start is not also imitated.
    assert parse([*argv, "--start", str(path), "--select-round"]).select_round
    assert point_file(Path("r/m.zip"), 4096) == Path("r/m.ppo4096.zip")
    with pytest.raises(SystemExit):
        parse([*argv, "--start", str(path), "--imitate", "2"])
    with pytest.raises(ValueError, match="env gauge_sigma"):
        check_start(parse([*argv, "--sigma", "0.03", "--start", str(path)]),
                    env_kwargs(parse([*argv, "--sigma", "0.03"])))
