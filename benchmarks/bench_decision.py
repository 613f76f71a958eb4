"""The time a decision costs: a masked policy on the design view against ``active``, in one
run on the same machines of the same lab.

    python benchmarks/bench_decision.py [--policy results/masked.zip] [--machines 5]
        [--budget 330] [--conditions lab] [--sigma 0.02] [--seed 1] [--chunk 1]
        [--whole] [--rounds 1]

Each agent plays its episodes as ``compare`` plays them: ``--chunk`` machines together in
the lab's native vector env (``OrthoglideLab-v0``'s, its steps batched), by
:func:`~calibrators.study.episodes.run_episodes` (each agent class's ``act_all``: the
policy's agents decide together, one batched observation and one network pass for the
chunk, reading their labs' entries from the vector env's arrays; ``active``'s price their
moves together); every ``act_all`` call is timed in CPU seconds of the process
(``time.process_time``), which a machine shared with other work inflates far less than
its wall clock (on a 2-core machine at load 35, the policy's choice took 0.4 ms of CPU and
5.6 ms of wall time).  ``--whole`` times ``act_all`` alone: without it, the choice and the
policy's parts are timed inside it too, at about 1 µs a decision of the policy's (six
part timers a call).  ``--rounds R`` plays every chunk R times by both agents, the
order of the two swapped each round, and prints each round's ratios: the spread of a
loaded machine, measured in one run.
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
from contextlib import closing
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
from calibrators.study import episodes
from calibrators.study.episodes import machine_seed, run_episodes
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


def play(label: str, name: str, kwargs: dict, seed: int, machines: list[int],
         whole: bool = False) -> list[float]:
    """One episode of agent ``name`` on each of ``machines``, played as ``compare`` plays a
    chunk (:func:`~calibrators.study.episodes.run_episodes` on the lab's native vector env,
    each agent class's ``act_all``): its seconds in ``act_all``, the labs' seconds in their
    steps, its decisions, its lab steps, its seconds in its choice (:data:`CHOICE`) and,
    for the policy, in each of :data:`PARTS` (0 for ``active``).  ``whole``: ``act_all``
    alone is timed (no timer inside it: the choice and the parts are 0)."""
    agents = [get_agent(name) for _ in machines]
    choosing = [0.0] * (1 + len(PARTS))
    restore = []
    if not whole:
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
    counted = [0.0, 0.0, 0, 0]  # act_all's seconds, the labs' seconds, decisions, steps
    act_all = episodes._act_all

    def acting(chunk: list, observations: list, infos: list) -> list:
        counted[2] += sum(not agent.queue for agent in chunk)
        counted[3] += len(chunk)
        start = time.process_time()
        try:
            return act_all(chunk, observations, infos)
        finally:
            counted[0] += time.process_time() - start

    with closing(gym.make_vec(orthoglide_env.LAB_ENV_ID, num_envs=len(machines),
                              vectorization_mode="vector_entry_point", **kwargs)) as envs:
        step = envs.step

        def stepping(actions: dict) -> tuple:
            start = time.process_time()
            try:
                return step(actions)
            finally:
                counted[1] += time.process_time() - start

        envs.step = stepping
        episodes._act_all = acting
        try:
            run_episodes(envs, agents, [machine_seed(seed, m) for m in machines])
        finally:
            episodes._act_all = act_all
            for owner_, method_, inner in restore:
                setattr(owner_, method_, inner)
    return [*counted, *choosing]


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
    parser.add_argument("--whole", action="store_true",
                        help="time act_all alone, no timer inside it (no choice or parts)")
    parser.add_argument("--rounds", type=int, default=1,
                        help="every chunk played by both agents this many times, the "
                             "order of the agents swapped each round")
    args = parser.parse_args()
    if args.machines < 1 or args.chunk < 1 or args.rounds < 1:
        parser.error("--machines, --chunk and --rounds must be at least 1")
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
            play(label, name, kwargs, args.seed, [0], args.whole)
        chunks = [list(range(args.machines))[k:k + args.chunk]
                  for k in range(0, args.machines, args.chunk)]
        rounds = []
        for r in range(args.rounds):
            order = list(agents.items())[::-1 if r % 2 else 1]
            runs = {label: [] for label in agents}
            for chunk in chunks:
                for label, name in order:
                    runs[label].append(play(label, name, kwargs, args.seed, chunk,
                                            args.whole))
            rounds.append({label: np.sum(done, axis=0) for label, done in runs.items()})
    print(f"{args.machines} machines in chunks of {args.chunk}, seed {args.seed}, "
          f"{args.conditions} conditions, sigma {args.sigma} mm, budget {args.budget:g} s, "
          f"{args.rounds} round(s), " + ("act_all alone timed" if args.whole
                                         else "the choice and its parts timed inside act_all"))
    if args.rounds > 1:
        for r, totals in enumerate(rounds):
            print(f"round {r + 1}: " + ratios(totals))
    totals = {label: np.sum([done[label] for done in rounds], axis=0) for label in agents}
    print(f"{'agent':8}{'ms/decision':>13}{'ms/choice':>11}{'decisions':>11}"
          f"{'agent s/episode':>17}{'lab s/episode':>15}{'lab steps':>11}")
    episodes_played = args.machines * args.rounds
    for label, (acting, stepping, decisions, steps, choosing, *_) in totals.items():
        choice = "-" if args.whole else f"{1e3 * choosing / decisions:.3f}"
        print(f"{label:8}{1e3 * acting / decisions:13.3f}{choice:>11}"
              f"{decisions / episodes_played:11.1f}{acting / episodes_played:17.3f}"
              f"{stepping / episodes_played:15.3f}{steps / episodes_played:11.1f}")
    p = totals["policy"]
    if not args.whole:
        print("the policy's decision, ms: " + ", ".join(
            f"{part} {1e3 * seconds / p[2]:.3f}" for part, seconds in zip(PARTS, p[5:],
                                                                            strict=True))
            + f", the rest of act {1e3 * (p[0] - sum(p[5:])) / p[2]:.3f}")
    print(("all rounds: " if args.rounds > 1 else "") + ratios(totals))


def ratios(totals: dict[str, np.ndarray]) -> str:
    """``active``'s costs over the policy's in ``totals`` (each agent's :func:`play`
    sums): per decision (all of ``act_all``), per choice (where timed) and per episode
    (``act_all`` and the labs' steps)."""
    p, a = totals["policy"], totals["active"]
    choice = (f"{(a[4] / a[2]) / (p[4] / p[2]):.0f}x per choice, " if p[4] > 0 else "")
    return (f"active / policy: {(a[0] / a[2]) / (p[0] / p[2]):.0f}x per decision (all of "
            f"act; policy {1e3 * p[0] / p[2]:.4f} ms, active {1e3 * a[0] / a[2]:.3f} ms), "
            f"{choice}{a[0] / p[0]:.0f}x per episode in agent time, "
            f"{(a[0] + a[1]) / (p[0] + p[1]):.1f}x with the labs' steps")


if __name__ == "__main__":
    main()
