"""The lab's design view (``OrthoglideLabDesign-v0``): the planner's candidate operations as
masked discrete actions, an observation of what the readings determine, and the fall of
the predicted TCP error as the reward."""

from __future__ import annotations

import dataclasses
import warnings
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import orthoglide_env
from calibrators.agents.base import action
from calibrators.agents.names import get_agent
from calibrators.agents.optimal import fixed_plan
from calibrators.agents.policy import (
    SPEC_ENTRY,
    DesignPolicyAgent,
    read_spec,
    save_policy,
    spec_of,
)
from calibrators.planning.design_expert import PlanExpert
from calibrators.planning.search import Planner
from calibrators.study.episodes import run_episode
from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.lab.design_belief import (
    COUNT_SCALE,
    FALL_FLOOR,
    READ_PROBABILITY,
    DesignBelief,
    observations,
)
from orthoglide_env.lab.operations import Op
from orthoglide_env.lab.rewards import ACCURACY_UNIT_MM
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.wrappers import DesignLab, DesignLabVector, design_lab_env

ID = orthoglide_env.DESIGN_LAB_ENV_ID
ID_V1 = orthoglide_env.DESIGN_LAB_V1_ENV_ID
ID_V2 = orthoglide_env.DESIGN_LAB_V2_ENV_ID
BUDGET_S = 900.0


def design(**kwargs) -> DesignLab:
    kwargs.setdefault("conditions", "ideal")
    kwargs.setdefault("gauge_sigma", 0.02)
    kwargs.setdefault("budget_s", BUDGET_S)
    return design_lab_env(**kwargs)


def candidate_moves(env: DesignLab, rng: np.random.Generator, count: int) -> list[int]:
    """``count`` operations chosen at random among the unmasked moves, stepping ``env``."""
    taken = []
    for _ in range(count):
        mask = env.action_masks()
        action = int(rng.choice(np.flatnonzero(mask[:env.belief.n_postures])))
        env.step(action)
        taken.append(action)
    return taken


def test_the_spaces_and_check_env() -> None:
    env = gym.make(ID, conditions="ideal", budget_s=BUDGET_S)
    belief = env.get_wrapper_attr("belief")
    # Prototype: 1500 candidate postures, 6 stands x 39 slots, stop.
    assert env.action_space == gym.spaces.Discrete(1500 + 6 * 39 + 1)
    assert belief.factor.shape == (27, 12)
    assert env.observation_space.shape == (12 + 1 + 6 * (39 + 3) + 3 + 1,)
    # The raw lab's own check is in test_lab.py.
    _assert_check_env_clean(version=0)


def _assert_check_env_clean(version: int) -> None:
    """Gymnasium's ``check_env`` of the design view ``version`` says nothing but that the
    wrapped env differs from the unwrapped one, which a wrapper is."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(design(version=version), skip_render_check=True)
    messages = [str(w.message) for w in caught]
    assert all("different from the unwrapped version" in m for m in messages), messages


def test_view_1_is_view_0_then_the_readings_here_and_check_env() -> None:
    v0, v1 = gym.make(ID, conditions="lab", budget_s=BUDGET_S), gym.make(ID_V1, conditions="lab",
                                                                          budget_s=BUDGET_S)
    assert v1.observation_space.shape == (v0.observation_space.shape[0] + 3,)
    assert v1.action_space == v0.action_space
    for env in (v0, v1):
        env.reset(seed=5)
    rng = np.random.default_rng(3)
    for _ in range(6):
        mask = v0.get_wrapper_attr("action_masks")()
        np.testing.assert_array_equal(mask, v1.get_wrapper_attr("action_masks")())
        chosen = int(rng.choice(np.flatnonzero(mask[:1500])))
        a, r0, *_ = v0.step(chosen)
        b, r1, *_ = v1.step(chosen)
        np.testing.assert_array_equal(a, b[:-3])
        assert r0 == r1 and v1.observation_space.contains(b)
    _assert_check_env_clean(version=1)


def test_view_1_counts_the_readings_here_and_their_fall() -> None:
    """Re-readings of one posture count up one by one, a move elsewhere starts a new run
    and a return adds to the posture's total; the fall is the reading's relative fall of
    the predicted mean square, as the step's info gives it."""
    env = design(version=1)
    _, info = env.reset(seed=2)
    before = info["predicted_rigid_mm"] ** 2
    # The first candidate move that reads (re-reading Zero alone only pins the dials'
    # zeros), then three re-readings there, a move to Zero and back.
    for here in np.flatnonzero(env.action_masks()[:1500]):
        _, _, _, _, info = env.step(int(here))
        if info["predicted_rigid_mm"] ** 2 < before:
            break
    before = info["predicted_rigid_mm"] ** 2
    counts = []
    zero = env.belief.table.zero
    for chosen in (here, here, here, zero, here):
        observation, _, _, _, info = env.step(int(chosen))
        after = info["predicted_rigid_mm"] ** 2
        counts.append(np.round(observation[-3:-1] * COUNT_SCALE).tolist())
        # float32 observation of a log10: 1e-6 of a decade.
        assert observation[-1] == pytest.approx(np.log10(1 - after / before + FALL_FLOOR),
                                                abs=1e-5)
        # A re-reading where the stands read adds information, if little.
        assert chosen == zero or after < before
        before = after
    # Zero: read at the reset, then once more.
    assert counts == [[2, 2], [3, 3], [4, 4], [1, 2], [1, 5]]


def test_view_2_is_view_1_s_stands_then_the_readings_at_every_posture() -> None:
    """View 2 observes v1's stands, posture, clock and readings here, then the readings
    taken at each posture (its spectrum and fall left out); its actions, masks and rewards
    are v1's, step for step, and ``check_env`` is clean."""
    v1, v2 = (gym.make(i, conditions="lab", budget_s=BUDGET_S) for i in (ID_V1, ID_V2))
    spectrum = v1.get_wrapper_attr("belief").factor.shape[1] + 1
    assert v2.observation_space.shape == (v1.observation_space.shape[0] - spectrum - 1 + 1500,)
    assert v2.action_space == v1.action_space
    for env in (v1, v2):
        env.reset(seed=5)
    rng = np.random.default_rng(3)
    chosen = []
    for _ in range(6):
        mask = v1.get_wrapper_attr("action_masks")()
        np.testing.assert_array_equal(mask, v2.get_wrapper_attr("action_masks")())
        chosen.append(int(rng.choice(np.flatnonzero(mask[:1500]))))
        a, r1, *_ = v1.step(chosen[-1])
        b, r2, *_ = v2.step(chosen[-1])
        np.testing.assert_array_equal(a[spectrum:-1], b[:-1500])
        assert r1 == r2 and v2.observation_space.contains(b)
    # Zero read at the reset, then each chosen posture once per choice.
    expected = np.bincount([v2.get_wrapper_attr("belief").table.zero, *chosen], minlength=1500)
    np.testing.assert_array_equal(np.round(b[-1500:] * COUNT_SCALE), expected)
    _assert_check_env_clean(version=2)


def test_a_belief_of_view_2_may_count_without_the_covariance() -> None:
    """A belief that does not follow the covariance observes view 2 as one that does, and
    refuses to predict an error; the views that observe the spectrum refuse it."""
    env = design(conditions="lab", version=2)
    # The lab's own observations, which an agent's belief follows.
    observation, _ = env.unwrapped.reset(seed=1)
    lean = DesignBelief(env.belief.design, env.belief.n_stands, env.belief.sigma, BUDGET_S, 2,
                        covariance=False)
    for belief in (env.belief, lean):
        belief.start(observation)
    rng = np.random.default_rng(0)
    for _ in range(5):
        operations = env.operations(int(rng.choice(np.flatnonzero(env.action_masks()[:1500]))))
        for operation in operations:
            observation, _, _, _, info = env.unwrapped.step(operation)
            for belief in (env.belief, lean):
                belief.observe(operation, observation, bool(info.get("refused")))
        np.testing.assert_array_equal(lean.observation(), env.belief.observation())
        np.testing.assert_array_equal(lean.action_mask(), env.belief.action_mask())
    assert env.belief.predicted_mse() < np.trace(env.belief.weight)
    np.testing.assert_array_equal(lean.covariance, np.eye(len(lean.covariance)))
    with pytest.raises(ValueError, match="predicts no error"):
        lean.predicted_mse()
    for version in (0, 1):
        with pytest.raises(ValueError, match="observes the covariance"):
            DesignBelief(env.belief.design, 6, 0.02, BUDGET_S, version, covariance=False)


def test_the_observations_of_a_chunk_are_each_belief_s_own() -> None:
    """A policy deciding for a chunk of machines observes them in one batched pass: the
    same floats as each belief's own observation, in every state of either view."""
    rng = np.random.default_rng(4)
    for version in (0, 1, 2):
        envs = [design(conditions="lab", version=version) for _ in range(4)]
        for k, env in enumerate(envs):
            env.reset(seed=k)
            candidate_moves(env, rng, 3 * k)
        beliefs = [env.belief for env in envs]
        for count in (1, 2, 4):
            np.testing.assert_array_equal(observations(beliefs[:count]),
                                          [b.observation() for b in beliefs[:count]])


def test_bad_arguments_are_refused() -> None:
    for kwargs in ({"reward": "accuracy"}, {"per": "hour"}, {"reference": True},
                   {"version": 3}):
        with pytest.raises(ValueError):
            design(**kwargs)
    env = design()
    env.reset(seed=0)
    with pytest.raises(ValueError):
        env.step(env.action_space.n)


def test_the_move_mask_is_the_planners_candidate_moves() -> None:
    """The moves open are those where the experiment planner, in the same state and a
    priori, expects some stand to read more likely than not and which end within the
    budget; the lever flicks of each move are the planner's."""
    env = design(conditions="lab")
    env.reset(seed=2)
    candidate_moves(env, np.random.default_rng(0), 6)
    belief = env.belief
    lab = env.unwrapped
    planner = Planner([int(s) for s in belief.slots], list(belief.engaged),
                      weighting_sigma(float(lab.noise.effective_sigma)), BUDGET_S,
                      design=lab.design)
    planner.rho, planner.here, planner.time_s = belief.rho.copy(), belief.here, belief.time_s
    seconds, after, reads = planner._moves()
    mine = belief.moves()
    np.testing.assert_array_equal(mine[1], after)
    np.testing.assert_array_equal(mine[2], reads)
    np.testing.assert_allclose(mine[0], seconds, rtol=0, atol=1e-12)
    fits = belief.time_s + seconds <= BUDGET_S
    np.testing.assert_array_equal(env.action_masks()[:belief.n_postures],
                                  (reads >= READ_PROBABILITY).any(axis=0) & fits)
    # Some moves the planner would price read less likely than that: they are closed.
    assert np.any(reads.any(axis=0) & ~(reads >= READ_PROBABILITY).any(axis=0))
    assert 0 < env.action_masks()[:belief.n_postures].sum() < belief.n_postures


def test_a_masked_remount_is_one_the_lab_refuses_or_no_candidate() -> None:
    """A re-mount is masked exactly where its slot is held: by another stand the lab
    refuses it, by itself it is a new installation where it stands; an open one the lab
    does."""
    env = design()
    env.reset(seed=1)
    belief = env.belief
    start = belief.n_postures
    masks = env.action_masks()[start:-1].reshape(belief.n_stands, belief.n_slots)
    held = belief.slots[belief.slots >= 0]
    assert np.array_equal(~masks, np.isin(np.arange(belief.n_slots), held)[None].repeat(6, 0))
    for stand in range(belief.n_stands):
        for slot in held:
            twin = design()
            twin.reset(seed=1)
            info = twin.step(start + stand * belief.n_slots + int(slot))[-1]
            assert bool(info["refused"]) == (belief.slots[stand] != slot), (stand, slot)
    free = np.flatnonzero(masks[0])
    twin = design()
    twin.reset(seed=1)
    info = twin.step(start + int(free[0]))[-1]
    assert info["refused"] == "" and twin.belief.slots[0] == free[0]


def test_the_mask_closes_what_the_budget_cannot_pay() -> None:
    env = design(budget_s=60.0)
    env.reset(seed=0)
    mask = env.action_masks()
    belief = env.belief
    # A re-mount takes two minutes: none fits in one.
    assert not mask[belief.n_postures:-1].any() and mask[-1]
    seconds, _, _ = belief.moves()
    assert not mask[:belief.n_postures][seconds > 60.0].any()


def test_the_reward_is_the_fall_of_the_predicted_error_the_lab_computes() -> None:
    """The reward is the fall of the belief's predicted mean square, and that prediction
    is the lab notebook's own (its information summed from the records' Jacobian, an
    independent path): they differ only by the dial zero's prior of 10 mm, which the
    notebook eliminates exactly, a relative difference below (0.02 / 10)^2 per reading."""
    env = design(gauge_resolution=0.0)
    _, info = env.reset(seed=3)
    rng = np.random.default_rng(1)
    before = info["predicted_rigid_mm"] ** 2
    for step in range(8):
        mask = env.action_masks()
        # Two re-mounts among the moves: they reset a stand's unknowns.
        action = (env.belief.n_postures + int(np.flatnonzero(mask[env.belief.n_postures:-1])[0])
                  if step in (3, 6) else int(rng.choice(np.flatnonzero(mask[:1500]))))
        _, reward, terminated, truncated, info = env.step(action)
        after = info["predicted_rigid_mm"] ** 2
        assert reward == pytest.approx((before - after) / ACCURACY_UNIT_MM**2, rel=1e-12)
        notebook = env.unwrapped.predicted_tcp_rigid_mm()
        assert info["predicted_rigid_mm"] == pytest.approx(notebook, rel=1e-4)
        before = after
        assert not (terminated or truncated)


def test_the_log_reward_per_second() -> None:
    env = design(reward="log_mse", per="second")
    _, info = env.reset(seed=3)
    start = env.belief.time_s
    action = int(np.flatnonzero(env.action_masks())[0])
    _, reward, *_, after = env.step(action)
    seconds = env.belief.time_s - start
    expected = 2 * np.log(info["predicted_rigid_mm"] / after["predicted_rigid_mm"]) / seconds
    assert reward == pytest.approx(expected, rel=1e-12) and reward > 0


def test_the_observation_never_depends_on_the_truth() -> None:
    """Two different machines in different worlds (lab conditions), read at the same
    places by the same mountings: different readings, the same observation."""
    one, two = design(conditions="lab"), design(conditions="lab")
    a, _ = one.reset(seed=10)
    b, _ = two.reset(seed=11)
    assert not np.array_equal(one.unwrapped.true_machine.to_vector(),
                              two.unwrapped.true_machine.to_vector())
    np.testing.assert_array_equal(a, b)
    # Moves whose every stand surely reads or surely does not (a priori contact 1 or 0):
    # the same places read on both machines.
    _, _, reads = one.belief.moves()
    sure = np.flatnonzero(one.action_masks()[:1500] & np.all((reads == 0) | (reads == 1), axis=0))
    for chosen in np.random.default_rng(5).choice(sure, 10, replace=False):
        a, *_ = one.step(int(chosen))
        b, *_ = two.step(int(chosen))
        places = [[(r.mounting, r.rho) for r in e.unwrapped.records] for e in (one, two)]
        assert places[0] == places[1]
        readings = [[r.reading for r in e.unwrapped.records] for e in (one, two)]
        assert readings[0][-1] != readings[1][-1]
        np.testing.assert_array_equal(a, b)


def test_the_vector_form_is_a_loop_of_single_envs() -> None:
    envs = gym.make_vec(ID, num_envs=2, conditions="lab", budget_s=BUDGET_S, gauge_sigma=0.02)
    assert isinstance(envs.unwrapped, DesignLabVector)
    singles = [design(conditions="lab"), design(conditions="lab")]
    obs, _ = envs.reset(seed=7)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=7 + i)[0])
    rng = np.random.default_rng(2)
    for _ in range(6):
        masks = envs.unwrapped.action_masks()
        np.testing.assert_array_equal(masks, [env.action_masks() for env in singles])
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        obs, rewards, terms, truncs, _ = envs.step(actions)
        for i, env in enumerate(singles):
            o, r, term, trunc, _ = env.step(int(actions[i]))
            np.testing.assert_array_equal(obs[i], o)
            assert (rewards[i], terms[i], truncs[i]) == (r, term, trunc)
            if term or trunc:
                env.reset()


def test_masked_ppo_trains_and_acts_within_the_mask() -> None:
    """The optional learner: sb3-contrib's MaskablePPO on the design view as it is."""
    sb3_contrib = pytest.importorskip("sb3_contrib")
    env = design(budget_s=300.0)
    model = sb3_contrib.MaskablePPO("MlpPolicy", env, n_steps=32, batch_size=16, n_epochs=1,
                                    seed=0, device="cpu")
    model.learn(total_timesteps=64)
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
    assert env.action_masks()[int(action)]


def test_the_training_selects_a_round_by_its_held_out_score(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    """``train_masked.py --select-round`` writes the DAgger round of the lowest error on
    the curve machines, and is refused where there are no rounds to choose from."""
    monkeypatch.syspath_prepend(str(Path(__file__).parents[1] / "examples"))
    from train_masked import parse, round_file, selected_round

    rows = [{"tcp_rigid_median_mm": v} for v in (0.02, 0.011, 0.013, 0.011)]
    assert selected_round(rows) == 1
    assert round_file(Path("r/m.zip"), 3) == Path("r/m.round3.zip")
    assert parse(["--imitate", "2", "--steps", "0", "--select-round", "--view", "2"]).view == 2
    for argv in (["--select-round"], ["--imitate", "2", "--select-round"],
                 ["--view", "3"]):
        with pytest.raises(SystemExit):
            parse(argv)
    assert "--select-round" in capsys.readouterr().err


def test_a_standardised_fit_is_folded_back_onto_the_view_s_observation(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``train_masked.py --standardise``: the imitation's fit moves the first layer to the
    observations' centred and scaled coordinates and folds it back after its steps, so the
    file's network reads the view's raw observation.  With no step, the move and the fold
    give back the network's logits: float32 rounding of products of size |W| |x| (about
    1 here), so 1e-4."""
    sb3_contrib = pytest.importorskip("sb3_contrib")
    torch = pytest.importorskip("torch")
    monkeypatch.syspath_prepend(str(Path(__file__).parents[1] / "examples"))
    from train_masked import fit, masked_logits

    env = design(budget_s=300.0)
    observation, _ = env.reset(seed=3)
    data: tuple[list, list, list] = ([], [], [])
    rng = np.random.default_rng(0)
    for _ in range(6):
        mask = env.action_masks()
        move = int(rng.choice(np.flatnonzero(mask[:env.belief.n_postures])))
        for store, value in zip(data, (observation, mask, move), strict=True):
            store.append(value)
        observation, *_ = env.step(move)
    model = sb3_contrib.MaskablePPO("MlpPolicy", env, seed=0, device="cpu")
    x = torch.as_tensor(np.array(data[0]))
    masks = torch.as_tensor(np.array(data[1]))
    with torch.no_grad():
        before = masked_logits(model, x, masks).numpy()
    fit(model, data, 0, rng, standardise=True)
    with torch.no_grad():
        after = masked_logits(model, x, masks).numpy()
    np.testing.assert_allclose(after, before, atol=1e-4)
    # A fit's steps move the network: the fold is not a copy of the weights before it.
    fit(model, data, 20, rng, standardise=True)
    with torch.no_grad():
        assert not np.allclose(masked_logits(model, x, masks).numpy(), before, atol=1e-2)


def test_op_codes_of_a_move_are_flicks_then_the_move() -> None:
    env = design()
    env.reset(seed=0)
    belief = env.belief
    _, after, _ = belief.moves()
    posture = int(np.flatnonzero(after.sum(axis=0) < belief.engaged.sum())[0])
    ops = belief.operations(posture)
    assert [o["op"] for o in ops[:-1]] == [Op.LIFT] * (len(ops) - 1) and ops[-1]["op"] == Op.MOVE
    assert env.step(posture)[-1]["lab_steps"] == len(ops)


SMALL = Path(__file__).resolve().parents[1] / "examples" / "designs" / "small.json"
LAB = {"conditions": "lab", "gauge_sigma": 0.02, "budget_s": 300.0}


def view_of(model: object) -> int:
    """The design view's version a model of the prototype's lab acts in (its input size)."""
    return int(model.observation_space.shape[0] == 269 + 3)


@pytest.fixture(scope="module", params=[0, 1], ids=["v0", "v1"])
def masked_policy(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest
                  ) -> Path:
    """A tiny MaskablePPO policy of the design view (of each version) saved to a file."""
    sb3_contrib = pytest.importorskip("sb3_contrib")
    env = design_lab_env(version=request.param, **LAB)
    model = sb3_contrib.MaskablePPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1,
                                    seed=0, device="cpu")
    model.learn(total_timesteps=64)
    path = tmp_path_factory.mktemp("policy") / "masked.zip"
    return save_policy(model, path, spec_of(env, "MaskablePPO", LAB))


def test_a_design_policy_file_records_its_view_and_plays_in_the_lab(masked_policy: Path
                                                                   ) -> None:
    """``policy:FILE`` of a design-view policy keeps the view's belief from the lab's own
    observations (the wrapper's, step for step) and draws open operations from the
    network's distribution, whose logits it computes as torch does."""
    import sb3_contrib
    import torch

    model = sb3_contrib.MaskablePPO.load(masked_policy, device="cpu")
    version = view_of(model)
    assert read_spec(masked_policy).env_id == (ID_V1 if version else ID)
    agent = get_agent(f"policy:{masked_policy}")
    assert isinstance(agent, DesignPolicyAgent)
    episode = run_episode(gym.make(orthoglide_env.LAB_ENV_ID, **LAB), agent, seed=4)
    assert episode.measurements.experiment_time_s <= LAB["budget_s"]
    wrapped = design_lab_env(version=version, **LAB)
    observation, _ = wrapped.reset(seed=4)
    lab = gym.make(orthoglide_env.LAB_ENV_ID, **LAB)
    raw, info = lab.reset(seed=4)
    agent.reset(lab, raw, np.random.default_rng(0))
    for _ in range(5):
        np.testing.assert_array_equal(agent.belief.observation(), observation)
        with torch.no_grad():
            tensor, _ = model.policy.obs_to_tensor(observation)
            expected = model.policy.get_distribution(tensor).distribution.logits[0]
        logits = agent.actor.logits(observation)
        # The same float32 network: log-softmax equal to torch's to its rounding (~1e-6).
        np.testing.assert_allclose(logits - np.logaddexp.reduce(logits), expected.numpy(),
                                   atol=1e-5)
        mask = wrapped.action_masks()
        assert all(mask[agent.decide()] for _ in range(50))
        operation = agent.decide()
        observation, *_ = wrapped.step(operation)
        for step in agent.belief.operations(operation):
            agent.last = step
            raw, _, _, _, info = lab.step(action(step["op"], step["rho"], step["stand"],
                                                 step["slot"]))
            agent.belief.observe(step, raw, bool(info["refused"]))


def test_a_design_policy_is_refused_on_a_lab_of_another_design(masked_policy: Path) -> None:
    env = gym.make(orthoglide_env.LAB_ENV_ID, design=MachineDesign.from_file(SMALL), **LAB)
    observation, _ = env.reset(seed=0)
    agent = get_agent(f"policy:{masked_policy}")
    with pytest.raises(ValueError, match=r"another design \(L = 310.25 mm.*retrain.*train_masked"):
        agent.reset(env, observation, np.random.default_rng(0))


def test_an_argmax_policy_plays_its_most_likely_open_operation(masked_policy: Path,
                                                             tmp_path: Path) -> None:
    """A file of ``play="argmax"`` (an imitated policy's) plays the open operation of the
    largest logit, whatever the agent's random stream; a file of another play, or asked
    for, is refused with the plays there are."""
    import sb3_contrib

    model = sb3_contrib.MaskablePPO.load(masked_policy, device="cpu")
    env = design_lab_env(version=view_of(model), **LAB)
    path = save_policy(model, tmp_path / "argmax.zip",
                       spec_of(env, "MaskablePPO", LAB, play="argmax"))
    agent = get_agent(f"policy:{path}")
    lab = gym.make(orthoglide_env.LAB_ENV_ID, **LAB)
    raw, _ = lab.reset(seed=4)
    chosen = set()
    for seed in range(5):
        agent.reset(lab, raw, np.random.default_rng(seed))
        logits = agent.actor.logits(agent.belief.observation())
        chosen.add(agent.decide())
    assert chosen == {int(np.argmax(np.where(agent.belief.action_mask(), logits, -np.inf)))}
    with pytest.raises(ValueError, match="play must be one of"):
        spec_of(env, "MaskablePPO", LAB, play="mean")
    spec = dataclasses.replace(read_spec(path), play="mean")
    with zipfile.ZipFile(path, "a") as archive, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the entry written again: a duplicate name
        archive.writestr(SPEC_ENTRY, spec.to_json())
    with pytest.raises(ValueError, match=r"plays 'mean'.*\['draw', 'argmax'\]"):
        read_spec(path)


def test_the_plan_expert_played_alone_is_the_optimal_plan() -> None:
    """The imitation's expert, following the view's operations from the lab's clock and
    stands, takes the ``optimal`` plan's moves in their order (the same planner, the same
    readings expected, in the textbook world the same clock), for as long as the view
    offers the plan's move (a move where no stand reads more likely than not is no
    candidate of the view, and the expert then takes the planner's best one that is)."""
    budget = 120.0
    env = design(budget_s=budget)
    env.reset(seed=6)
    belief = env.belief
    expert = PlanExpert(env.unwrapped, belief)
    steps, _ = fixed_plan(tuple(int(s) for s in belief.slots),
                          tuple(bool(e) for e in belief.engaged), belief.sigma,
                          budget - belief.time_s, belief.design, env.unwrapped.conditions)
    planned = [s.rho for s in steps if s.op == Op.MOVE]
    played = 0
    for rho in planned:
        best = expert.planner.best_move()
        if best is None or not env.action_masks()[best[0]]:
            break
        chosen = expert.choose(belief)
        assert tuple(float(v) for v in belief.table.postures[chosen]) == rho
        env.step(chosen)
        expert.follow(chosen, belief)
        played += 1
    else:
        assert expert.choose(belief) == belief.n_actions - 1
    # Not vacuous: seed 6's plan offers its first eight moves at least.
    assert played >= 8
    chosen = expert.choose(belief)
    assert env.action_masks()[chosen]
