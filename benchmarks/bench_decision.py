"""The time a decision costs: a masked policy on the design view against ``active``, in one
run on the same machines of the same lab.

    python benchmarks/bench_decision.py [--policy results/masked.zip] [--machines 5]
        [--budget 330] [--conditions lab] [--sigma 0.02] [--seed 1] [--chunk 1]

Each agent plays its episodes through the lab env (``OrthoglideLab-v0``), as ``compare``
plays them, ``--chunk`` machines together (each agent class's ``act_all``: the policy's
agents decide together, one batched observation and one network pass for the chunk;
``active``'s price their moves together); every ``act_all`` call is timed in CPU seconds
of the process (``time.process_time``), which a machine shared with other work inflates
far less than its wall clock (on a 2-core machine at load 35, the policy's choice took
0.4 ms of CPU and 5.6 ms of wall time).
A decision is a call that chose a new operation (a move with its lever flicks, a
re-mount, stop); the calls that play a chosen operation's further lab actions are counted
in the agent's time but are not decisions.

What is counted, for both agents alike: an agent's time is its ``act_all`` calls and
nothing else (taking in the readings of the lab's last step, choosing, handing back the
lab action); the lab env's ``step`` (the machine moving, the dials read, the notebook
written) is the same work whichever agent asks for it, and is timed apart, as the lab's
seconds per episode.  The time per decision is an agent's whole time over its decisions
(``ms/decision``), and its choice alone over them (``ms/choice``).  The table gives each
agent's seconds per decision and per episode (the agent's, and the lab's steps beside
them), and their ratios, then where the policy's decision goes (:data:`PARTS`: the
beliefs' updates, their observations, the masks, the network's choice); the issue's
targets are a decision at least 100x cheaper than ``active``'s, and a whole episode at
least 10x (agent time; with the lab's steps, which both pay, the ratio is also printed).
Without ``--policy`` the policy is an untrained MaskablePPO network of
``examples/train_masked.py``'s shape: a decision costs about the same whatever the
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

# Registers the filters that policy files of flicks other than "prior" play with.
import calibrators.planning.shortlist  # noqa: F401
import orthoglide_env
from calibrators.agents import active as active_module
from calibrators.agents import get_agent
from calibrators.agents import policy as policy_module
from calibrators.agents.names import POLICY_PREFIX
from calibrators.agents.policy import save_policy, spec_of
from calibrators.study.episodes import agent_rng, machine_seed
from orthoglide_env.lab.counting_rows import CountingRows
from orthoglide_env.wrappers import design_lab_env


def untrained_policy(kwargs: dict, folder: Path) -> Path:
    """An untrained MaskablePPO policy file of the training script's network."""
    from sb3_contrib import MaskablePPO

    env = design_lab_env(**kwargs)
    model = MaskablePPO("MlpPolicy", env, seed=0, device="cpu",
                        policy_kwargs={"net_arch": [128, 128]})
    return save_policy(model, folder / "untrained.zip", spec_of(env, "MaskablePPO", kwargs))


#: Each agent's choice alone, without taking in the readings: the policy's (its agents'
#: observations, network and masks, for a chunk at once; a view-2 chunk's groups of equal
#: states), the planner's (each agent's next operation readied, refits included, the
#: chunk's moves priced at once, the chosen one taken): the module's functions, then each
#: agent's methods.
CHOICE = {"policy": (policy_module, ("decide_all", "decide_counting"), ()),
          "active": (active_module, ("best_moves",), ("_ready", "_moved"))}


#: The parts of a policy's decision, each one call for a chunk's agents: taking in a lab
#: step's readings (the beliefs' stacked Woodbury steps,
#: :func:`~orthoglide_env.lab.design_belief.observe_many`, or a view-2 chunk's rows',
#: :meth:`~orthoglide_env.lab.counting_rows.CountingRows.observe`), the observations (the
#: predicted error's spectra, ``observations``, or the rows'), the masks
#: (``action_masks``, or the rows' states' parts, their candidate moves among them,
#: and masks), the network's choice
#: (:meth:`~calibrators.agents.actor_weights.ActorWeights.choose_many`).
PARTS: tuple[str, ...] = ("update", "observation", "mask", "network")
#: The functions and methods timed as :data:`PARTS`' first three: (owner, name, part).
PART_FUNCTIONS: tuple[tuple[object, str, str], ...] = (
    (policy_module, "observe_many", "update"), (CountingRows, "observe", "update"),
    (policy_module, "observations", "observation"),
    (CountingRows, "observations", "observation"),
    (policy_module, "action_masks", "mask"), (CountingRows, "parts", "mask"),
    (CountingRows, "masks", "mask"))


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
    """A policy's actor whose choices are timed (the actor itself is shared and frozen)."""

    def __init__(self, actor: object, seconds: list[float]) -> None:
        self.actor, self.weights = actor, actor.weights
        timed(self, "choose_many", seconds, 1 + PARTS.index("network"))

    def choose_many(self, *args: np.ndarray | None) -> np.ndarray:
        return self.actor.choose_many(*args)


def play(label: str, name: str, kwargs: dict, seed: int, machines: list[int]
         ) -> list[float]:
    """One episode of agent ``name`` on each of ``machines``, played together as
    ``compare`` plays a chunk (each agent's ``act_all``): its seconds in ``act_all``, the
    labs' seconds in ``step``, its decisions, its lab steps, its seconds in its choice
    (:data:`CHOICE`) and, for the policy, in each of :data:`PARTS` (0 for ``active``)."""
    labs = [gym.make(orthoglide_env.LAB_ENV_ID, **kwargs) for _ in machines]
    firsts = [lab.reset(seed=machine_seed(seed, m)) for lab, m in zip(labs, machines,
                                                                       strict=True)]
    agents = [get_agent(name) for _ in machines]
    for agent, lab, (observation, _), m in zip(agents, labs, firsts, machines, strict=True):
        agent.reset(lab, observation, agent_rng(machine_seed(seed, m)))
    choosing = [0.0] * (1 + len(PARTS))
    owner, functions, methods = CHOICE[label]
    restore = [(owner, function, getattr(owner, function)) for function in functions]
    for function in functions:
        timed(owner, function, choosing, 0)
    for agent in agents:
        for own in methods:
            timed(agent, own, choosing, 0)
    if label == "policy":
        for part_owner, function, part in PART_FUNCTIONS:
            restore.append((part_owner, function, getattr(part_owner, function)))
            timed(part_owner, function, choosing, 1 + PARTS.index(part))
        actor = TimedActor(agents[0].actor, choosing)
        for agent in agents:
            agent.actor = actor
    acting = stepping = 0.0
    decisions = steps = 0
    running = list(range(len(machines)))
    state = [list(first) for first in firsts]
    while running:
        decisions += sum(not agents[i].queue for i in running)
        start = time.process_time()
        actions = type(agents[0]).act_all([agents[i] for i in running],
                                          [state[i][0] for i in running],
                                          [state[i][1] for i in running])
        middle = time.process_time()
        done = []
        for i, chosen in zip(running, actions, strict=True):
            observation, _, terminated, truncated, info = labs[i].step(chosen)
            state[i] = [observation, info]
            if terminated or truncated:
                done.append(i)
        stepping += time.process_time() - middle
        acting += middle - start
        steps += len(running)
        running = [i for i in running if i not in done]
    for owner_, method_, inner in restore:
        setattr(owner_, method_, inner)
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
    parser.add_argument("--chunk", type=int, default=1,
                        help="machines played together, as a comparison's chunk: the "
                             "policy decides for them at once")
    args = parser.parse_args()
    if args.machines < 1 or args.chunk < 1:
        parser.error("--machines and --chunk must be at least 1")
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
            play(label, name, kwargs, args.seed, [0])
        totals = {}
        chunks = [list(range(args.machines))[k:k + args.chunk]
                  for k in range(0, args.machines, args.chunk)]
        for label, name in agents.items():
            runs = [play(label, name, kwargs, args.seed, chunk) for chunk in chunks]
            totals[label] = np.sum(runs, axis=0)
    print(f"{args.machines} machines in chunks of {args.chunk}, seed {args.seed}, "
          f"{args.conditions} conditions, sigma {args.sigma} mm, budget {args.budget:g} s")
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
