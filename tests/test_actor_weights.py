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

import numpy as np
import pytest

from calibrators.agents.actor_weights import actor_of, read_actor

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "examples" / "policies" / "masked_lab330.zip"


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
        logits = agent.actor.logits(agent.belief.observation())
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


def test_the_weights_are_torchs_bit_for_bit() -> None:
    """The arrays read are the bytes torch holds: the same float32 actor."""
    sb3_contrib = pytest.importorskip("sb3_contrib")
    policy = sb3_contrib.MaskablePPO.load(SHIPPED, device="cpu").policy
    actor = read_actor(SHIPPED)
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
