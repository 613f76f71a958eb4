"""The time a decision costs: a masked policy on the design view against ``active``, in one
run on the same machines of the same lab.

    python benchmarks/bench_decision.py [--policy results/masked.zip] [--machines 5]
        [--budget 330] [--conditions lab] [--sigma 0.02] [--seed 1]

Each agent plays its episodes through the lab env (``OrthoglideLab-v0``), as ``compare``
plays them; every ``act`` call is timed in CPU seconds of the process
(``time.process_time``), which a machine shared with other work inflates far less than
its wall clock (on a 2-core machine at load 35, the policy's choice took 0.4 ms of CPU
and 5.6 ms of wall time).
A decision is a call that chose a new operation (a move with its lever flicks, a
re-mount, stop); the calls that play a chosen operation's further lab actions are counted
in the agent's time but are not decisions.
The table gives each agent's seconds per decision (all its ``act`` time, taking in the
readings included; and the choice alone, :data:`CHOICE`) and per episode (the agent's,
and the lab's steps beside them), and their ratios, then where the policy's decision
goes (:data:`PARTS`: the belief's updates, its observation, the mask, the network); the
issue's targets are a decision at least 100x cheaper than ``active``'s, and a whole
episode at least 10x.  Without ``--policy`` the policy is an untrained MaskablePPO
network of ``examples/train_masked.py``'s shape: a decision costs the same whatever the
weights.  Needs sb3-contrib (``pip install -e '.[rl]'``).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.names import POLICY_PREFIX
from calibrators.agents.policy import save_policy, spec_of
from calibrators.study.episodes import agent_rng, machine_seed
from orthoglide_env.wrappers import design_lab_env


def untrained_policy(kwargs: dict, folder: Path) -> Path:
    """An untrained MaskablePPO policy file of the training script's network."""
    from sb3_contrib import MaskablePPO

    env = design_lab_env(**kwargs)
    model = MaskablePPO("MlpPolicy", env, seed=0, device="cpu",
                        policy_kwargs={"net_arch": [128, 128]})
    return save_policy(model, folder / "untrained.zip", spec_of(env, "MaskablePPO", kwargs))


#: Each agent's method that chooses its next operation (the choice alone, without taking
#: in the readings): the policy's network over its mask, the planner's pricing.
CHOICE = {"policy": "decide", "active": "_next"}


#: The parts of a policy's decision (:data:`PARTS`' order): taking in a lab step's
#: readings (the belief's rank-one updates), the observation (the predicted error's
#: spectrum), the mask, the network.
PARTS: tuple[str, ...] = ("update", "observation", "mask", "network")


def timed(owner: object, method: str, seconds: list[float], k: int) -> None:
    """Replace ``owner.method`` by itself adding its CPU seconds to ``seconds[k]``."""
    inner = getattr(owner, method)

    def wrapper(*args: object) -> object:
        start = time.process_time()
        try:
            return inner(*args)
        finally:
            seconds[k] += time.process_time() - start

    setattr(owner, method, wrapper)


class TimedActor:
    """A policy's actor whose logits are timed (the actor itself is shared and frozen)."""

    def __init__(self, actor: object, seconds: list[float]) -> None:
        self.actor, self.weights = actor, actor.weights
        timed(self, "logits", seconds, 1 + PARTS.index("network"))

    def logits(self, observation: np.ndarray) -> np.ndarray:
        return self.actor.logits(observation)


def play(label: str, name: str, kwargs: dict, seed: int, machine: int) -> list[float]:
    """One episode of agent ``name``: its seconds in ``act``, the lab's seconds in ``step``,
    its decisions, its lab steps, its seconds in its choice (:data:`CHOICE`) and, for the
    policy, in each of :data:`PARTS` (0 for ``active``)."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, **kwargs)
    observation, info = env.reset(seed=machine_seed(seed, machine))
    agent = get_agent(name)
    agent.reset(env, observation, agent_rng(machine_seed(seed, machine)))
    choosing = [0.0] * (1 + len(PARTS))
    timed(agent, CHOICE[label], choosing, 0)
    if label == "policy":
        for k, method in enumerate(("observe", "observation", "action_mask")):
            timed(agent.belief, method, choosing, 1 + k)
        agent.actor = TimedActor(agent.actor, choosing)
    acting = stepping = 0.0
    decisions = steps = 0
    while True:
        decisions += not agent.queue
        start = time.process_time()
        action = agent.act(observation, info)
        middle = time.process_time()
        observation, _, terminated, truncated, info = env.step(action)
        stepping += time.process_time() - middle
        acting += middle - start
        steps += 1
        if terminated or truncated:
            return [acting, stepping, decisions, steps, *choosing]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, default=None,
                        help="a design-view policy file (default: an untrained network)")
    parser.add_argument("--machines", type=int, default=5)
    parser.add_argument("--budget", type=float, default=330.0)
    parser.add_argument("--conditions", default="lab")
    parser.add_argument("--sigma", type=float, default=0.02)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    kwargs = {"conditions": args.conditions, "gauge_sigma": args.sigma,
              "budget_s": args.budget}
    with tempfile.TemporaryDirectory() as folder:
        policy = args.policy or untrained_policy(kwargs, Path(folder))
        agents = {"policy": POLICY_PREFIX + str(policy), "active": "active"}
        # One episode each first: the slot table, the fixed plan and torch start once per
        # process, a cost no decision of a sweep pays again.
        for label, name in agents.items():
            play(label, name, kwargs, args.seed, 0)
        totals = {}
        for label, name in agents.items():
            runs = [play(label, name, kwargs, args.seed, m) for m in range(args.machines)]
            totals[label] = np.sum(runs, axis=0)
    print(f"{args.machines} machines, seed {args.seed}, {args.conditions} conditions, sigma "
          f"{args.sigma} mm, budget {args.budget:g} s")
    print(f"{'agent':8}{'ms/decision':>13}{'ms/choice':>11}{'decisions':>11}"
          f"{'agent s/episode':>17}{'lab s/episode':>15}{'lab steps':>11}")
    for label, (acting, stepping, decisions, steps, choosing, *_) in totals.items():
        print(f"{label:8}{1e3 * acting / decisions:13.3f}{1e3 * choosing / decisions:11.3f}"
              f"{decisions / args.machines:11.1f}{acting / args.machines:17.3f}"
              f"{stepping / args.machines:15.3f}{steps / args.machines:11.1f}")
    p, a = totals["policy"], totals["active"]
    print("the policy's decision, ms: " + ", ".join(
        f"{part} {1e3 * seconds / p[2]:.3f}" for part, seconds in zip(PARTS, p[5:], strict=True))
        + f", the rest of act {1e3 * (p[0] - sum(p[5:])) / p[2]:.3f}")
    print(f"active / policy: {(a[0] / a[2]) / (p[0] / p[2]):.0f}x per decision (all of act), "
          f"{(a[4] / a[2]) / (p[4] / p[2]):.0f}x per choice, "
          f"{(a[0] + a[1]) / (p[0] + p[1]):.1f}x per episode (agent and lab)")


if __name__ == "__main__":
    main()
