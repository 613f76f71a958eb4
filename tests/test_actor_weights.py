"""A design-view policy's network read from its file in NumPy, without torch
(:mod:`calibrators.agents.actor_weights`)."""

from __future__ import annotations

import io
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from calibrators.agents.actor_weights import actor_of, read_actor

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "examples" / "policies" / "masked_lab330.zip"
SHIPPED_HOUR = ROOT / "examples" / "policies" / "masked_lab3600.zip"
SHIPPED_RANKED = ROOT / "examples" / "policies" / "ranked_lab330.zip"
SHIPPED_COUNTS = ROOT / "examples" / "policies" / "counts_lab3600.zip"


def test_the_shipped_policy_plays_without_torch() -> None:
    """``policy:FILE`` of the shipped design-view policy plays a lab episode in a process
    that never imports torch nor stable-baselines3, each operation the most likely open
    one (its file plays ``argmax``)."""
    script = f"""
import sys
import gymnasium as gym
import numpy as np
import orthoglide_env
from calibrators.agents.names import get_agent
agent = get_agent("policy:{SHIPPED}")
lab = gym.make(orthoglide_env.LAB_ENV_ID, conditions="lab", gauge_sigma=0.02, budget_s=330.0)
observation, info = lab.reset(seed=3)
agent.reset(lab, observation, np.random.default_rng(0))
decisions = 0
while True:
    if not agent.queue:
        logits = agent.actor.logits_many(agent.belief.observation()[None])[0]
        best = int(np.argmax(np.where(agent.belief.action_mask(), logits, -np.inf)))
        assert agent.decide() == best
        decisions += 1
    observation, _, terminated, truncated, info = lab.step(agent.act(observation, info))
    if terminated or truncated:
        break
assert not {{"torch", "stable_baselines3", "sb3_contrib"}} & set(sys.modules)
print(decisions, float(observation["time"][0]))
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
    assert out.returncode == 0, out.stderr
    decisions, seconds = out.stdout.split()
    # A 330 s episode of single moves of a few seconds each: tens of decisions, all
    # within the training episode's budget.
    assert 10 <= int(decisions) and float(seconds) <= 330.0


def _play_first_moves(path: Path, env_id: str) -> Any:
    """Starts the shipped one-hour policy ``path`` (made for ``env_id``) on a lab machine
    and plays 20 steps, each decision an open operation and none ending the episode: its
    agent's belief."""
    import gymnasium as gym

    import orthoglide_env
    from calibrators.agents.names import get_agent
    from calibrators.agents.policy import read_spec

    spec = read_spec(path)
    assert (spec.env_id, spec.budget_s, spec.play) == (env_id, 3600.0, "argmax")
    agent = get_agent(f"policy:{path}")
    lab = gym.make(orthoglide_env.LAB_ENV_ID, conditions="lab", gauge_sigma=0.02,
                   budget_s=3600.0)
    observation, info = lab.reset(seed=5)
    agent.reset(lab, observation, np.random.default_rng(0))
    for _ in range(20):
        if not agent.queue:
            assert agent.belief.action_mask()[agent.decide()]
        observation, _, terminated, truncated, info = lab.step(agent.act(observation, info))
        assert not (terminated or truncated)
    return agent.belief


def test_the_one_hour_policy_plays_view_1_within_its_mask() -> None:
    """The shipped one-hour policy acted in the design view's version 1: its agent keeps
    that view's belief (the readings here in its observation) on an hour's budget, and
    its first decisions are open operations."""
    import orthoglide_env

    belief = _play_first_moves(SHIPPED_HOUR, orthoglide_env.DESIGN_LAB_V1_ENV_ID)
    assert belief.version == 1 and len(belief.observation()) == 272


def test_the_counting_policy_plays_view_2_without_the_covariance() -> None:
    """The shipped one-hour policy of view 2 keeps a belief that counts the readings and
    never forms the covariance (it stays the prior's identity), and its first decisions
    are open operations that read: the counts of the postures it chose grow."""
    import orthoglide_env

    belief = _play_first_moves(SHIPPED_COUNTS, orthoglide_env.DESIGN_LAB_V2_ENV_ID)
    assert belief.version == 2 and not belief.follows
    assert len(belief.observation()) == 6 * (39 + 3) + 3 + 1 + 2 + 1500
    # Zero read at the reset, then a reading after each move.
    assert belief.readings_at.sum() > 1
    np.testing.assert_array_equal(belief.covariance, np.eye(len(belief.covariance)))


def test_a_chunk_of_machines_decides_as_each_machine_alone() -> None:
    """``compare`` plays a chunk of machines' episodes together, and the policy's agents
    then decide together (one network pass): each machine's episode is the one it plays
    alone, reading for reading."""
    import gymnasium as gym

    import orthoglide_env
    from calibrators.agents.names import get_agent
    from calibrators.study.episodes import run_episode, run_episodes

    lab = {"conditions": "lab", "gauge_sigma": 0.02, "budget_s": 330.0}
    seeds = [11, 12, 13]
    envs = gym.vector.SyncVectorEnv([lambda: gym.make(orthoglide_env.LAB_ENV_ID, **lab)] * 3)
    together = run_episodes(envs, [get_agent(f"policy:{SHIPPED}") for _ in seeds], seeds)
    for seed, episode in zip(seeds, together, strict=True):
        alone = run_episode(gym.make(orthoglide_env.LAB_ENV_ID, **lab),
                            get_agent(f"policy:{SHIPPED}"), seed)
        assert [(r.mounting, r.rho, r.reading) for r in episode.records] == [
            (r.mounting, r.rho, r.reading) for r in alone.records]
        assert len(episode.records) > 30


def test_the_fused_network_is_the_layers_of_the_file() -> None:
    """``logits_many`` (float64, a matrix product per layer for a chunk) is the float32
    layers' network to float32's rounding (logits of order 10, so 1e-5), and a row's logits
    do not depend on the rows beside it beyond float64's rounding, also where the rows
    read other inputs (the first layer multiplies only the columns some row of the chunk
    reads: alone, a sparse row's product has fewer terms)."""
    actor = read_actor(SHIPPED)
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((7, actor.weights[0].shape[1])).astype(np.float32)
    rows[1::2, 13:] = 0.0
    rows[2, ::3] = 0.0
    many = actor.logits_many(rows)
    for k, row in enumerate(rows):
        np.testing.assert_allclose(many[k], actor.logits(row), rtol=0, atol=1e-5)
        np.testing.assert_allclose(many[k], actor.logits_many(row[None])[0], rtol=0,
                                   atol=1e-12)
    with pytest.raises(ValueError, match=r"observations are \(N, 269\)"):
        actor.logits_many(rows[:, :5])


@pytest.mark.parametrize("path", [SHIPPED, SHIPPED_RANKED], ids=["imitated", "ranked"])
def test_the_weights_are_torchs_bit_for_bit(path: Path) -> None:
    """The arrays read are the bytes torch holds: the same float32 actor, also in the
    file PPO fine-tuned (its critic and optimiser state beside the actor are not read)."""
    sb3_contrib = pytest.importorskip("sb3_contrib")
    policy = sb3_contrib.MaskablePPO.load(path, device="cpu").policy
    actor = read_actor(path)
    linears = [m for m in policy.mlp_extractor.policy_net if hasattr(m, "weight")]
    for module, weight, bias in zip([*linears, policy.action_net], actor.weights,
                                    actor.biases, strict=True):
        np.testing.assert_array_equal(module.weight.detach().numpy(), weight)
        np.testing.assert_array_equal(module.bias.detach().numpy(), bias)


class _Shell:
    def __reduce__(self) -> tuple:
        return (os.system, ("echo run",))


def test_a_file_whose_pickle_holds_other_objects_is_refused(tmp_path: Path) -> None:
    """The unpickler builds a state dict and nothing else: a file that would run a
    command when unpickled is refused, and the command is not run."""
    pth = io.BytesIO()
    with zipfile.ZipFile(pth, "w") as archive:
        archive.writestr("archive/data.pkl", pickle.dumps({"x": _Shell()}))
        archive.writestr("archive/byteorder", "little")
    path = tmp_path / "evil.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("data", json.dumps({"policy_class": {
            "__module__": "sb3_contrib.common.maskable.policies"}, "policy_kwargs": {}}))
        archive.writestr("policy.pth", pth.getvalue())
    with pytest.raises(ValueError, match=r"cannot be read in NumPy.*holds no posix.system|"
                                         r"cannot be read in NumPy.*holds no nt.system"):
        read_actor(path)


def test_an_actor_other_than_the_default_mlp_is_refused() -> None:
    weights = {"mlp_extractor.policy_net.0.weight": np.zeros((4, 3), np.float32),
               "mlp_extractor.policy_net.0.bias": np.zeros(4, np.float32),
               "action_net.weight": np.zeros((2, 5), np.float32),
               "action_net.bias": np.zeros(2, np.float32)}
    with pytest.raises(ValueError, match=r"\['activation_fn'\] is not sb3's default MLP"):
        actor_of(weights, {"net_arch": [4], "activation_fn": "ReLU"})
    with pytest.raises(ValueError, match=r"do not chain: \(4, 3\) then \(2, 5\)"):
        actor_of(weights, {"net_arch": [4]})
    del weights["action_net.bias"]
    with pytest.raises(ValueError, match=r"no 'action_net\.bias'"):
        actor_of(weights, {})
