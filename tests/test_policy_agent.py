"""The learned agent ``policy:FILE``: a saved stable-baselines3 policy plays in the lab and
in ``compare``; a file it cannot run is refused with the reason."""

from __future__ import annotations

import dataclasses
import sys
import zipfile
from pathlib import Path
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent, policy
from calibrators.agents.policy import SPEC_ENTRY, PolicySpec, _load_model, save_policy, spec_of
from calibrators.cli import main
from calibrators.study import compare, statistics
from calibrators.study.episodes import run_episode
from orthoglide_env.lab.operations import SLOT_NAMES
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.wrappers import flat_lab_env

LAB = {"errors": "realistic", "gauge_sigma": 0.01, "budget_s": 600.0}


def spec_only_file(path: Path, spec: PolicySpec) -> Path:
    """A zip holding only a spec: enough for every check made before the network loads."""
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(SPEC_ENTRY, spec.to_json())
    return path


@pytest.fixture(scope="module")
def lab_spec() -> PolicySpec:
    return spec_of(flat_lab_env(**LAB), "PPO", LAB)


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """A tiny PPO policy (a few hundred steps, normalised observations) saved to a file,
    with the VecNormalize it was trained behind."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    vec = VecNormalize(DummyVecEnv([lambda: flat_lab_env(reward="information", **LAB)] * 2))
    vec.seed(0)
    model = PPO("MlpPolicy", vec, n_steps=128, batch_size=64, n_epochs=2, seed=0)
    model.learn(total_timesteps=256)
    path = tmp_path_factory.mktemp("policy") / "tiny.zip"
    save_policy(model, path, spec_of(flat_lab_env(**LAB), "PPO", LAB, vec))
    return path, vec


def test_missing_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no policy file"):
        get_agent(f"policy:{tmp_path / 'none.zip'}")


def test_a_file_that_is_not_a_policy_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "notes.zip"
    path.write_text("not a zip")
    with pytest.raises(ValueError, match="not a policy file"):
        get_agent(f"policy:{path}")


def test_a_policy_of_another_slot_catalogue_is_refused(tmp_path: Path,
                                                       lab_spec: PolicySpec) -> None:
    """A catalogue that has grown since training changes the flat action and observation:
    the file says which catalogue it learned on, and is refused before loading."""
    older = dataclasses.replace(lab_spec, slots=SLOT_NAMES[:-3])
    path = spec_only_file(tmp_path / "old.zip", older)
    with pytest.raises(ValueError, match=f"{len(SLOT_NAMES) - 3} slots.*retrain"):
        get_agent(f"policy:{path}")


def _network(path: str, *_: object) -> SimpleNamespace:
    """A stand-in for the network: the spaces its file's spec says (no learning library)."""
    spec = policy.read_spec(path)
    return SimpleNamespace(observation_space=SimpleNamespace(shape=(spec.observation_size,)),
                           action_space=SimpleNamespace(shape=(spec.action_size,)))


SMALL = Path(__file__).resolve().parents[1] / "examples" / "designs" / "small.json"


@pytest.mark.parametrize(("design", "refusal"), [
    # A lab's catalogue is its design's: other slot positions, other slots.
    ({"slot_positions": [0.3, 0.5, 0.7]}, r"trained on a lab with 39 slots; this lab's design "
                                           r"has 27 \(bar slots at \[0.3, 0.5, 0.7\]\).*retrain"),
    # The prototype's slot names but other lengths and limits: the same flat action is
    # another joint target.
    (None, r"another design \(L = 310.25 mm, limits \[-100, 60\] mm; this lab's: L = 250 mm, "
           r"\[-80, 50\] mm\).*retrain"),
])
def test_a_policy_of_another_design_is_refused_at_reset(
        tmp_path: Path, lab_spec: PolicySpec, monkeypatch: pytest.MonkeyPatch,
        design: dict | None, refusal: str) -> None:
    """A policy of the prototype is refused on a lab of another design as the episode
    opens, and one trained there plays there."""
    monkeypatch.setattr(policy, "_load_model", _network)
    design = MachineDesign.from_file(SMALL) if design is None else MachineDesign.from_dict(design)
    env = gym.make(orthoglide_env.LAB_ENV_ID, design=design, **LAB)
    observation, _ = env.reset(seed=0)
    agent = get_agent(f"policy:{spec_only_file(tmp_path / 'prototype.zip', lab_spec)}")
    with pytest.raises(ValueError, match=refusal):
        agent.reset(env, observation, np.random.default_rng(0))
    spec = spec_of(flat_lab_env(design=design, **LAB), "PPO", LAB)
    assert spec.slots == tuple(s.slot for s in env.unwrapped.slots)
    agent = get_agent(f"policy:{spec_only_file(tmp_path / 'there.zip', spec)}")
    agent.reset(env, observation, np.random.default_rng(0))
    env.close()


def test_a_policy_saved_before_designs_were_recorded_is_the_prototypes(
        tmp_path: Path, lab_spec: PolicySpec, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(policy, "_load_model", _network)
    older = dataclasses.replace(lab_spec, design=None)
    env = gym.make(orthoglide_env.LAB_ENV_ID, **LAB)
    observation, _ = env.reset(seed=0)
    get_agent(f"policy:{spec_only_file(tmp_path / 'older.zip', older)}").reset(
        env, observation, np.random.default_rng(0))
    env.close()


def test_without_stable_baselines3_the_error_names_the_extra(
        tmp_path: Path, lab_spec: PolicySpec, monkeypatch: pytest.MonkeyPatch) -> None:
    path = spec_only_file(tmp_path / "ok.zip", lab_spec)
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import fails
    _load_model.cache_clear()
    with pytest.raises(RuntimeError, match=r"pip install '\.\[rl\]'"):
        get_agent(f"policy:{path}")


def test_compare_cli_reports_a_missing_policy(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "none.zip"
    assert main(["compare", "--agents", f"paper,policy:{missing}", "--machines", "1"]) == 2
    assert "no policy file" in capsys.readouterr().err


def test_the_agent_normalises_observations_as_training_did(trained: tuple[Path, object]
                                                           ) -> None:
    path, vec = trained
    agent = get_agent(f"policy:{path}")
    flat = flat_lab_env(**LAB)
    observation, _ = flat.reset(seed=3)
    assert np.allclose(agent.spec.normalise(observation), vec.normalize_obs(observation))


def test_the_policy_plays_deterministic_episodes_in_the_lab(trained: tuple[Path, object]
                                                            ) -> None:
    path, _ = trained
    notebooks = []
    for _ in range(2):
        env = gym.make(orthoglide_env.LAB_ENV_ID, **LAB)
        episode = run_episode(env, get_agent(f"policy:{path}"), seed=11)
        notebooks.append([(r.mounting, r.rho, r.reading) for r in env.unwrapped.records])
        env.close()
    assert notebooks[0] == notebooks[1]
    assert episode.time_s > 0


def test_a_lab_of_other_sizes_is_refused_at_reset(trained: tuple[Path, object]) -> None:
    path, _ = trained
    env = gym.make(orthoglide_env.LAB_ENV_ID, stands=4, **LAB)
    with pytest.raises(ValueError, match=r"6 stands.*this lab \(4 stands"):
        run_episode(env, get_agent(f"policy:{path}"), seed=0)
    env.close()


def test_compare_runs_the_policy_like_any_agent(trained: tuple[Path, object]) -> None:
    path, _ = trained
    name = f"policy:{path}"
    config = compare.Config((name, "paper"), ("extended",), budget_s=LAB["budget_s"],
                            seed=5)
    trials = compare.run(config, 2)
    mine = [t for t in trials if t.agent == name]
    assert [t.machine for t in mine] == [0, 1]
    assert all(t.time_s > 0 and t.readings >= 6 for t in mine)  # six stands read at Zero
    rows = statistics.summary(trials)
    assert [r["agent"] for r in rows] == [name, "paper"]


def test_the_agent_draws_from_the_policy_distribution(trained: tuple[Path, object]) -> None:
    """The mean it draws around is the policy's own deterministic action, and its spread
    the policy's; the draw comes from the agent's random stream."""
    path, _ = trained
    agent = get_agent(f"policy:{path}")
    observation, _ = flat_lab_env(**LAB).reset(seed=4)
    flat = agent.spec.normalise(observation)
    mean, std = agent._distribution(flat)
    deterministic, _ = agent.model.predict(flat, deterministic=True)
    assert np.allclose(np.clip(mean, -1, 1), deterministic, atol=1e-6)
    assert np.allclose(std, np.exp(agent.model.policy.log_std.detach().numpy()))
