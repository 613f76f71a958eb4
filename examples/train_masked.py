"""Train a masked policy on the lab's design view with sb3-contrib's MaskablePPO (CPU), and
compare it with the designed agents on held-out machines.

    pip install torch --index-url https://download.pytorch.org/whl/cpu  # CPU-only: not GBs
    pip install -e '.[rl]'
    python examples/train_masked.py [--steps 100000] [--budget 330] [--conditions lab]
        [--sigma 0.02] [--seed 0] [--out results/masked.zip] [--max-minutes 30]
        [--imitate 4 [--episodes 16] [--updates 1500]]
    orthoglide compare --agents policy:results/masked.zip,active --estimators full \
        --conditions lab --budget 330 --machines 50 --seed 1

MaskablePPO learns on ``OrthoglideLabDesign-v0`` (:class:`orthoglide_env.wrappers.DesignLab`):
one discrete action over the experiment planner's candidate operations (a move to one of
the slot table's postures with its lever flicks, a re-mount, stop), masked to those open
now; an observation of what the readings so far determine (the predicted TCP error's
spectrum, the stands, the posture, the clock); and, by default, the fall of the log of
the predicted mean-square TCP error at each step, whose sum over an episode is the log of
the prior's over the last: the return is the final predicted error, and ``gamma`` is 1.
``--envs`` envs in one process (DummyVecEnv), env ``k`` seeded ``--seed + k``.

With ``--imitate N`` the policy first learns by imitation (DAgger, Ross et al. 2011) of
the greedy expert (:class:`calibrators.planning.design_expert.PlanExpert`: from the state
reached, never the truth nor the values read, the move ``optimal``'s planner takes next,
and the ``optimal`` plan's re-mounts): ``N`` rounds, each of
``--episodes`` episodes over the ``--envs`` envs, the first played by the expert and the
others by the policy so far (its most likely open operation), every state labelled with
the expert's choice; after each round the policy's network is fitted again to all the
labels (masked cross-entropy, ``--updates`` minibatch steps) and a curve point is scored, its
steps the decisions labelled so far.  Then ``--steps`` of MaskablePPO start from those
weights (0: none; the imitated policy is kept as ``<out>.imitated.zip``), and the file
plays its most likely operation (``play="argmax"``).  ``--view 1`` trains on
``OrthoglideLabDesign-v1``, whose observation also counts the readings taken at the present
posture (an expert's stays of up to 20 re-readings are then a function of what the policy
sees); ``--select-round`` keeps each round's policy and writes the one that scored best on
the curve machines (choose their ``--eval-seed`` apart from the test's).

Every ``--every`` steps the policy so far is saved to ``<out>.last.zip`` and played on the
first ``--curve-machines`` held-out machines, scored against their truth by
:func:`calibrators.study.compare.run` exactly as ``orthoglide compare`` scores any agent
(estimator ``full``); the baselines (``--baselines``) are scored once on the same machines.
The learning curve goes to ``<out>.curve.csv`` and ``<out>.curve.png`` (the baselines as
horizontal lines).  At the end the policy and the baselines are compared on ``--machines``
held-out machines, with the paired ratio of every two agents.

Held-out machines: comparison machine ``i`` of seed ``s`` is drawn from seed
``s * 1000003 + i``; training machines come from each env's own stream, seeded
``--seed + k`` once, so with ``--eval-seed`` >= 1 no held-out machine is a training
machine.  The same command and seed give the same policy (one torch thread, CPU).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from training_curve import (
    add_options,
    check_options,
    curve_callback,
    mean_episode_reward,
    median_rigid,
    plot_curve,
    silent_logger,
    write_curve,
)

from calibrators.agents.names import POLICY_PREFIX
from calibrators.agents.policy import PolicySpec, read_spec, save_policy, spec_of
from calibrators.planning.active_expert import FilteredDesignLab, filtered_design_lab_env
from calibrators.planning.design_expert import PlanExpert
from calibrators.planning.shortlist import (
    SHORTLIST_MOVES,
    LookaheadExpert,
    RankLabels,
    ranked_shortlist_lab_env,
    shortlist_design_lab_env,
)
from calibrators.study import compare, statistics
from orthoglide_env.lab.design_belief import VIEW_VERSIONS
from orthoglide_env.model.design import load_design
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.wrappers import DESIGN_PER, DESIGN_REWARDS, design_lab_env

#: The estimator that scores every evaluation (the comparison's headline).
ESTIMATOR: str = "full"
#: The experts whose pupils act among ``active``'s short list
#: (:class:`~calibrators.planning.shortlist.ShortlistDesignLab`).
SHORTLIST_EXPERTS: tuple[str, ...] = ("active-shortlist", "lookahead")
#: The experts whose pupils choose a rank of ``active``'s short list, seeing its moves
#: (:class:`~calibrators.planning.shortlist.RankedShortlistLab`): ``active``'s choice or
#: the lookahead's, as ranks.
RANKED_EXPERTS: tuple[str, ...] = ("active-ranked", "lookahead-ranked")
#: The designed agents whose levels the curve draws and the final table compares.
BASELINES: str = "paper,optimal,active,random"


def env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The design view's keyword arguments in training: the machines' design (a
    :class:`~orthoglide_env.model.design.MachineDesign`) and JSON (:func:`recorded`)."""
    return {"errors": DEFAULT_PRESET, "gauge_sigma": args.sigma, "budget_s": args.budget,
            "conditions": Conditions(args.conditions).to_dict(), "reward": args.reward,
            "per": args.per, "version": args.view, "design": load_design(args.design)}


def recorded(kwargs: dict[str, Any]) -> dict[str, Any]:
    """The view's keyword arguments the policy file records as JSON: all but the design,
    which the file records on its own (:attr:`calibrators.agents.policy.PolicySpec.design`)."""
    return {k: v for k, v in kwargs.items() if k != "design"}


def config(args: argparse.Namespace, agents: tuple[str, ...]) -> compare.Config:
    return compare.Config(agents, (ESTIMATOR,), budget_s=args.budget, errors=DEFAULT_PRESET,
                          sigma=args.sigma, seed=args.eval_seed,
                          conditions=Conditions(args.conditions),
                          design=load_design(args.design))


def view(kwargs: dict[str, Any], expert: str) -> Any:
    """The design view the policy learns in: its moves' flicks as the fixed plan's
    (``--expert optimal``) or as ``active``'s filter's (``--expert active``,
    :class:`~calibrators.planning.active_expert.FilteredDesignLab`; ``active-reach``: its
    observation also holds the dials the filter lets read at each posture;
    ``active-shortlist``: its mask opens ``active``'s short list only,
    :class:`~calibrators.planning.shortlist.ShortlistDesignLab`; ``active-ranked`` and
    ``lookahead-ranked``: its actions are the short list's ranks and its observation
    holds the listed moves' features,
    :class:`~calibrators.planning.shortlist.RankedShortlistLab`)."""
    if expert == "optimal":
        return design_lab_env(**kwargs)
    if expert in SHORTLIST_EXPERTS:
        return shortlist_design_lab_env(**kwargs)
    if expert in RANKED_EXPERTS:
        return ranked_shortlist_lab_env(**kwargs)
    return filtered_design_lab_env(reach=expert == "active-reach", **kwargs)


def expert_of(env: Any, expert: str) -> Any:
    """The expert that labels the states of ``env``'s episode, just reset: with ``expert``
    "lookahead" the short list's play-out (:class:`LookaheadExpert`; "-ranked": its
    choice or ``active``'s as a rank, :class:`RankLabels`), else the filter's
    ``active`` of a :class:`FilteredDesignLab`, else ``optimal``'s :class:`PlanExpert`."""
    if expert == "lookahead":
        return LookaheadExpert(env.expert)
    if expert == "lookahead-ranked":
        return RankLabels(LookaheadExpert(env.expert), env)
    if expert == "active-ranked":
        return RankLabels(env.expert, env)
    if isinstance(env, FilteredDesignLab):
        return env.expert
    return PlanExpert(env.unwrapped, env.belief)


def make_vec_env(n_envs: int, kwargs: dict[str, Any], seed: int, expert: str) -> Any:
    """``n_envs`` design views as a stable-baselines3 ``DummyVecEnv``, env ``k`` seeded
    ``seed + k``, each in a ``Monitor`` that keeps its episodes' final predicted error."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    def factory() -> Any:
        return Monitor(view(kwargs, expert), info_keywords=("predicted_rigid_mm",))

    vec = DummyVecEnv([factory] * n_envs)
    vec.seed(seed)
    return vec


def play_mode(args: argparse.Namespace) -> str:
    """How the trained file plays (:attr:`calibrators.agents.policy.PolicySpec.play`): an
    imitated policy (or one fine-tuned from an imitated ``--start``) its most likely
    operation, a policy of PPO alone a draw."""
    return "argmax" if args.imitate or args.start else "draw"


def held_out_rigid(args: argparse.Namespace, kwargs: dict[str, Any], model: Any, path: Path
                   ) -> float:
    """``model`` saved to ``path`` and scored on the curve machines: median TCP error
    after rigid motion (mm)."""
    save_policy(model, path, spec_of(view(kwargs, args.expert), "MaskablePPO",
                                     recorded(kwargs), play=play_mode(args)))
    row = statistics.summary(compare.run(config(args, (POLICY_PREFIX + str(path),)),
                                         args.curve_machines))[0]
    return median_rigid(row)


def curve_score(args: argparse.Namespace, kwargs: dict[str, Any]
                ) -> Any:
    """A learning-curve point: the policy saved at the path it is given and scored on the
    curve machines, with its training episodes' reward and final predicted error."""

    def score(model: Any, path: Path) -> dict[str, float]:
        predicted = [e["predicted_rigid_mm"] for e in model.ep_info_buffer]
        scores = {"mean_episode_reward": mean_episode_reward(model),
                  "training_predicted_mm": (float(np.median(predicted)) if predicted
                                            else float("nan")),
                  "tcp_rigid_median_mm": held_out_rigid(args, kwargs, model, path)}
        if args.select_round:
            shutil.copyfile(path, point_file(args.out, model.num_timesteps))
        return scores

    return score


def masked_logits(model: Any, observations: Any, masks: Any) -> Any:
    """The policy's logits (torch, B by actions) of a batch of observations, -1e9 where
    the mask is shut (as MaskablePPO's masked distribution has them)."""
    import torch

    policy = model.policy
    latent = policy.mlp_extractor.forward_actor(policy.extract_features(
        observations, policy.pi_features_extractor))
    return torch.where(masks, policy.action_net(latent), torch.tensor(-1e9))


#: How a rollout's episode chooses: ``choose(env, observation, episode, label)``, the
#: episode's index in its round and the expert's choice.
Choice = Callable[[Any, np.ndarray, int, int], int]


def rollouts(envs: list[Any], episodes: int, choose: Choice | None, expert_name: str | None
             ) -> tuple[list[np.ndarray], list[np.ndarray], list[int], list[float],
                        list[dict[str, float]]]:
    """``episodes`` episodes over ``envs`` in turn (each env's own stream), the operation
    of each state chosen by ``choose(env, observation, episode, label)`` (``None``: the
    expert's, ``label``; the expert named by ``--expert``, ``expert_name``; ``None``: no
    expert, whose labels are then -1 and cost nothing):
    every state's observation, mask, expert label and return from there to the episode's
    end (``gamma`` 1, as PPO learns), and each episode's return and final predicted error
    (mm)."""
    observations, masks, labels, returns, ends = [], [], [], [], []
    for episode in range(episodes):
        env = envs[episode % len(envs)]
        observation, _ = env.reset()
        expert = expert_of(env, expert_name) if expert_name else None
        rewards: list[float] = []
        done, info = False, {}
        while not done:
            observations.append(observation)
            masks.append(env.action_masks())
            labels.append(expert.choose(env.belief) if expert else -1)
            action = (labels[-1] if choose is None
                      else choose(env, observation, episode, labels[-1]))
            observation, reward, terminated, truncated, info = env.step(action)
            if expert:
                expert.follow(action, env.belief)
            rewards.append(float(reward))
            done = terminated or truncated
        returns.extend(np.cumsum(rewards[::-1])[::-1].tolist())
        ends.append({"r": float(np.sum(rewards)),
                     "predicted_rigid_mm": info["predicted_rigid_mm"]})
    return observations, masks, labels, returns, ends


def agreement(model: Any, data: tuple[list, list, list]) -> float:
    """The share of the states of ``data`` (observations, masks, expert labels) whose most
    likely open operation under ``model`` is the label (NaN without states)."""
    import torch

    if not data[2]:
        return float("nan")
    with torch.no_grad():
        logits = masked_logits(model, torch.as_tensor(np.array(data[0]), dtype=torch.float32),
                               torch.as_tensor(np.array(data[1]), dtype=torch.bool))
        return float((logits.argmax(1) == torch.as_tensor(np.array(data[2]))).float().mean())


def fit(model: Any, data: tuple[list, list, list], updates: int, rng: np.random.Generator,
        learning_rate: float = 1e-3, standardise: bool = False) -> float:
    """Fit the policy's actor to the expert's labels: ``updates`` Adam steps of masked
    cross-entropy on minibatches of 256, passes over the labels in ``rng``'s order (a
    round's fit goes on from the last round's weights); returns the share of states whose
    most likely open operation is the label.

    With ``standardise`` the fit sees each observation component centred and scaled by the
    labels' mean and spread, and the first layer is folded back onto the raw observation
    afterwards (``W x + b`` with ``W / s`` and ``b - W m / s``): the file keeps a plain MLP
    of the view's observation, while the fit's steps are not dwarfed by components of a
    large offset or tiny spread (the clock, whose one decision moves it by 0.002 of an
    hour's episode)."""
    import torch

    x = torch.as_tensor(np.array(data[0]), dtype=torch.float32)
    mask = torch.as_tensor(np.array(data[1]), dtype=torch.bool)
    y = torch.as_tensor(np.array(data[2]), dtype=torch.long)
    policy = model.policy
    first = policy.mlp_extractor.policy_net[0]
    centre, spread = torch.zeros(x.shape[1]), torch.ones(x.shape[1])
    if standardise:
        centre, spread = x.mean(0), x.std(0)
        # A component constant over the labels (a slot no stand held) keeps its scale.
        spread = torch.where(spread > 1e-6, spread, torch.ones(()))
        with torch.no_grad():
            first.bias += first.weight @ centre
            first.weight *= spread
    z = (x - centre) / spread
    parameters = [*policy.mlp_extractor.policy_net.parameters(),
                  *policy.action_net.parameters()]
    optimiser = torch.optim.Adam(parameters, lr=learning_rate)
    batches: list[np.ndarray] = []
    for _ in range(updates):
        if not batches:
            batches = np.array_split(rng.permutation(len(y)), max(1, len(y) // 256))
        batch = batches.pop()
        loss = torch.nn.functional.cross_entropy(
            masked_logits(model, z[batch], mask[batch]), y[batch])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    if standardise:
        with torch.no_grad():
            first.weight /= spread
            first.bias -= first.weight @ centre
    return agreement(model, data)


def fit_critic(model: Any, observations: list[np.ndarray], returns: list[float],
               updates: int, rng: np.random.Generator) -> float:
    """Fit the policy's value network to the imitation rollouts' returns (``updates`` Adam
    steps of squared error on minibatches of 256): PPO's first advantages then come from
    values of the imitated policy, not from an untrained critic whose noise would move
    the imitated actor before the critic learns.  Returns the fit's R^2 on all states."""
    import torch

    x = torch.as_tensor(np.array(observations), dtype=torch.float32)
    y = torch.as_tensor(np.array(returns), dtype=torch.float32)
    policy = model.policy
    parameters = [*policy.mlp_extractor.value_net.parameters(),
                  *policy.value_net.parameters()]
    optimiser = torch.optim.Adam(parameters, lr=1e-3)

    def values(batch: Any) -> Any:
        latent = policy.mlp_extractor.forward_critic(policy.extract_features(
            x[batch], policy.vf_features_extractor))
        return policy.value_net(latent).squeeze(-1)

    batches: list[np.ndarray] = []
    for _ in range(updates):
        if not batches:
            batches = np.array_split(rng.permutation(len(y)), max(1, len(y) // 256))
        batch = batches.pop()
        loss = torch.nn.functional.mse_loss(values(batch), y[batch])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        residual = values(slice(None)) - y
        return float(1 - residual.var() / y.var())


def training_envs(args: argparse.Namespace, kwargs: dict[str, Any]) -> list[Any]:
    """``args.envs`` design views of the training machines, env ``k`` seeded
    ``args.seed + k`` once (its later machines from its own stream)."""
    envs = [view(kwargs, args.expert) for _ in range(args.envs)]
    for k, env in enumerate(envs):
        env.reset(seed=args.seed + k)
    return envs


def most_likely(model: Any, env: Any, observation: np.ndarray) -> np.ndarray:
    """The policy's masked logits (NumPy) of ``env``'s state ``observation``."""
    import torch

    with torch.no_grad():
        return masked_logits(model, torch.as_tensor(observation[None]),
                             torch.as_tensor(env.action_masks()[None]))[0].numpy()


def imitate(args: argparse.Namespace, kwargs: dict[str, Any], model: Any) -> list[dict]:
    """DAgger rounds (see the module) on ``args.envs`` design views, env ``k`` seeded
    ``args.seed + k`` once; the learning curve's rows, written as they come."""
    envs = training_envs(args, kwargs)
    rng = np.random.default_rng(args.seed)

    draws = np.random.default_rng(args.seed + 1)

    def policy_choice(env: Any, observation: np.ndarray, episode: int, label: int) -> int:
        if episode > 0 and args.mix and draws.random() < args.mix:
            return label
        logits = most_likely(model, env, observation)
        if args.draw and episode > 0:
            # The masked softmax's draw (the largest logit plus Gumbel noise).
            logits = logits + draws.gumbel(size=logits.shape)
        return int(np.argmax(logits))

    data: tuple[list, list, list, list] = ([], [], [], [])
    rows: list[dict] = []
    start = time.perf_counter()
    for round_ in range(args.imitate):
        *states, ends = rollouts(envs, args.episodes, None if round_ == 0 else policy_choice,
                                args.expert)
        # The round's states before the policy fits them: its match on states it has not
        # been fitted to, those it reached itself after round 0.
        held_out = agreement(model, states[:3]) if round_ else float("nan")
        for store, new in zip(data, states, strict=True):
            store.extend(new)
        fitted = fit(model, data[:3], args.updates, rng, args.fit_learning_rate,
                     args.standardise)
        minutes = (time.perf_counter() - start) / 60
        rows.append({"steps": len(data[2]), "minutes": round(minutes, 2),
                     "mean_episode_reward": float(np.mean([e["r"] for e in ends])),
                     "training_predicted_mm": float(np.median(
                         [e["predicted_rigid_mm"] for e in ends])),
                     "expert_agreement": fitted, "held_out_agreement": held_out,
                     "tcp_rigid_median_mm": held_out_rigid(
                         args, kwargs, model, args.out.with_suffix(".last.zip"))})
        write_curve(rows, args.out.with_suffix(".curve.csv"))
        if args.select_round:
            shutil.copyfile(args.out.with_suffix(".last.zip"), round_file(args.out, round_))
        print(f"round {round_}: {rows[-1]}", flush=True)
        if 0 < args.max_minutes <= minutes:
            break
    if args.steps:
        explained = fit_critic(model, data[0], data[3], args.updates, rng)
        print(f"critic fitted to {len(data[3])} imitation returns: R^2 {explained:.3f}",
              flush=True)
    return rows


def check_start(args: argparse.Namespace, kwargs: dict[str, Any]) -> None:
    """``ValueError`` naming what differs unless the policy file ``args.start`` was trained
    in this run's view and world (its spec is the one this run would write)."""
    spec = read_spec(args.start)
    wanted = PolicySpec.from_json(spec_of(view(kwargs, args.expert), "MaskablePPO",
                                          recorded(kwargs), play="argmax").to_json())
    differ = [f.name for f in dataclasses.fields(spec) if f.name != "env"
              and getattr(spec, f.name) != getattr(wanted, f.name)]
    differ += [f"env {key}" for key in sorted({*spec.env, *wanted.env})
               if spec.env.get(key) != wanted.env.get(key)]
    if differ:
        raise ValueError(f"'{args.start}' was trained in another view or world than this "
                         f"run's (--expert, --view, --conditions, --sigma, --budget, "
                         f"--reward, --per, --design); what differs: {', '.join(differ)}")


def start_from(args: argparse.Namespace, kwargs: dict[str, Any], model: Any) -> None:
    """PPO's start from the policy file ``args.start`` (:func:`check_start`): its actor's
    weights, then the critic fitted to the returns of ``args.episodes`` episodes that
    actor plays on the training machines (its most likely open operation, the file's
    play), as after imitation (:func:`fit_critic`).  The view's reward comes from the
    readings' places and the nominal model only, so those returns never see the truth."""
    model.set_parameters(str(args.start), device="cpu")
    envs = training_envs(args, kwargs)
    observations, _, _, returns, _ = rollouts(
        envs, args.episodes,
        lambda env, observation, episode, label: int(np.argmax(
            most_likely(model, env, observation))), None)
    explained = fit_critic(model, observations, returns, args.updates,
                           np.random.default_rng(args.seed))
    print(f"critic fitted to {len(returns)} returns of {args.start}'s episodes: "
          f"R^2 {explained:.3f}", flush=True)


def round_file(out: Path, round_: int) -> Path:
    """Where ``--select-round`` keeps DAgger round ``round_``'s policy."""
    return out.with_suffix(f".round{round_}.zip")


def point_file(out: Path, steps: int) -> Path:
    """Where ``--select-round`` with ``--start`` keeps the policy of the PPO curve point
    at ``steps``."""
    return out.with_suffix(f".ppo{steps}.zip")


def selected_round(rows: list[dict]) -> int:
    """The curve row (a DAgger round, or a PPO point from ``--start``) whose policy scored
    the lowest median error on the curve machines (the first of equals)."""
    return int(np.argmin([row["tcp_rigid_median_mm"] for row in rows]))


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_options(parser, steps=100_000, envs=4, envs_help="envs stepped in turn",
                budget=330.0, budget_help="lab seconds of an episode, in training and "
                "evaluation", every=10_000, out="results/masked.zip")
    parser.add_argument("--reward", default="log_mse", choices=DESIGN_REWARDS,
                        help="the fall of the predicted mean-square TCP error, or of its log")
    parser.add_argument("--per", default="step", choices=DESIGN_PER,
                        help="the reward per step or per second")
    parser.add_argument("--imitate", type=int, default=0,
                        help="DAgger rounds of imitation of the greedy expert before PPO "
                             "(0: PPO alone)")
    parser.add_argument("--episodes", type=int, default=16,
                        help="episodes of each DAgger round")
    parser.add_argument("--updates", type=int, default=1500,
                        help="minibatch steps of the fit at each DAgger round")
    parser.add_argument("--net", default="128,128",
                        help="the actor's and the critic's hidden layers (widths, comma "
                             "separated)")
    parser.add_argument("--fit-learning-rate", type=float, default=1e-3,
                        help="Adam's step size of the imitation's fit")
    parser.add_argument("--standardise", action="store_true",
                        help="the imitation's fit sees the observations centred and scaled "
                             "(folded back into the first layer: the file's network reads "
                             "the view's observation)")
    parser.add_argument("--draw", action="store_true",
                        help="in each DAgger round after the first, every episode but the "
                             "first draws its operations from the policy's masked softmax, "
                             "so that the expert labels states near the policy's path too")
    parser.add_argument("--mix", type=float, default=0.0,
                        help="in each DAgger round after the first, every episode but the "
                             "first takes the expert's operation at each decision with this "
                             "probability, the policy's otherwise (Ross et al.'s mixture): "
                             "the expert labels the policy's mistakes all along its path, "
                             "not only up to the policy's first loop")
    parser.add_argument("--learning-rate", type=float, default=3e-4,
                        help="PPO's Adam step size (fine-tuning an imitated policy: small, "
                             "so that it does not forget what it imitated)")
    parser.add_argument("--target-kl", type=float, default=0.0,
                        help="PPO stops an update's epochs once the policy has moved this "
                             "far from the rollout's (approximate KL; 0: no limit)")
    parser.add_argument("--view", type=int, default=0, choices=VIEW_VERSIONS,
                        help="the design view's version: 0 (OrthoglideLabDesign-v0), 1 "
                             "(-v1: also the readings taken at the present posture) or 2 "
                             "(-v2: the readings taken at every posture, no spectrum)")
    parser.add_argument("--select-round", action="store_true",
                        help="keep every DAgger round's policy (<out>.round<k>.zip) and write "
                             "to <out> the round of the lowest error on the curve machines, "
                             "not the last (those of --eval-seed: choose a seed other than "
                             "the one the policy is tested on)")
    parser.add_argument("--expert", default="optimal",
                        choices=("optimal", "active", "active-reach", *SHORTLIST_EXPERTS,
                                 *RANKED_EXPERTS),
                        help="the imitation's expert: optimal's planner from the view's "
                             "state, or active's filter of the values read, whose flicks the "
                             "view's moves then take (active-reach: the view's observation "
                             "also holds the dials the filter lets read at each posture; "
                             "active-shortlist: the view opens active's choice and its next "
                             f"best moves, {SHORTLIST_MOVES} in all, and stop; lookahead: "
                             "the same view, labelled with the short list's move after which "
                             "active's greedy play-out leaves the lowest predicted error; "
                             "active-ranked, lookahead-ranked: their labels as ranks of the "
                             "short list, whose moves' gains, seconds and dials the view "
                             "observes; the file records it)")
    parser.add_argument("--start", type=Path, metavar="FILE",
                        help="instead of --imitate, PPO's --steps fine-tune this policy file "
                             "of the same view and world (a DAgger round's, "
                             "<out>.round<k>.zip), its critic first fitted to the returns of "
                             "--episodes episodes it plays on the training machines; with "
                             "--select-round every curve point's policy is kept "
                             "(<out>.ppo<steps>.zip) and the best written to <out>")
    parser.add_argument("--design", metavar="FILE",
                        help="the machines' design (a JSON file, as orthoglide's --design; "
                             "default: the prototype)")
    parser.add_argument("--baselines", default=BASELINES,
                        help="agents of the curve's lines and the final table")
    args = parser.parse_args(argv)
    check_options(parser, args, min_steps=0 if args.imitate else 1)
    if args.imitate < 0:
        parser.error("--imitate must be at least 0")
    for name in ("episodes", "updates"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1")
    for name in ("learning_rate", "fit_learning_rate"):
        value = getattr(args, name)
        if not (np.isfinite(value) and value > 0):
            parser.error(f"--{name.replace('_', '-')} must be a positive number, got {value}")
    try:
        args.net = [int(w) for w in args.net.split(",")]
    except ValueError:
        parser.error(f"--net is widths separated by commas, got {args.net!r}")
    if not args.net or min(args.net) < 1:
        parser.error(f"--net widths must be at least 1, got {args.net}")
    if not 0 <= args.mix <= 1:
        parser.error(f"--mix is a probability, got {args.mix}")
    if not (np.isfinite(args.target_kl) and args.target_kl >= 0):
        parser.error(f"--target-kl must be a number >= 0, got {args.target_kl}")
    if args.start is not None and args.imitate:
        parser.error("--start fine-tunes a trained policy: it takes no --imitate")
    if args.start is not None and not args.start.is_file():
        parser.error(f"--start: no policy file '{args.start}'")
    if args.select_round and not ((args.imitate and not args.steps)
                                  or (args.start is not None and args.steps)):
        parser.error("--select-round chooses among DAgger rounds (it needs --imitate and "
                     "--steps 0) or among the curve points of PPO from --start")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    # One thread: reproducible from the seed, and the learner shares the cores.
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch
    from sb3_contrib import MaskablePPO

    torch.set_num_threads(1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    kwargs = env_kwargs(args)
    if args.start is not None:
        try:
            check_start(args, kwargs)
        except ValueError as error:
            print(f"train_masked.py: error: {error}", file=sys.stderr)
            raise SystemExit(2) from None
    baselines = tuple(a for a in args.baselines.split(",") if a)
    levels = (statistics.summary(compare.run(config(args, baselines), args.curve_machines))
              if baselines else [])
    for row in levels:
        print(f"{row['agent']:>10}: held-out TCP (rigid) median {median_rigid(row):.4f} mm "
              f"on {args.curve_machines} curve machines", flush=True)
    vec = make_vec_env(args.envs, kwargs, args.seed, args.expert)
    # An imitated policy is fine-tuned without the entropy bonus, which would spread the
    # one operation per state it learned.
    model = MaskablePPO("MlpPolicy", vec, n_steps=256, batch_size=256, n_epochs=5,
                        gamma=1.0, gae_lambda=0.95,
                        ent_coef=0.0 if args.imitate or args.start else 0.01,
                        learning_rate=args.learning_rate, target_kl=args.target_kl or None,
                        seed=args.seed, device="cpu", policy_kwargs={"net_arch": args.net},
                        verbose=0)
    silent_logger(model)
    start = time.perf_counter()
    rows = imitate(args, kwargs, model) if args.imitate else []
    if args.start is not None:
        start_from(args, kwargs, model)
    if args.imitate and args.steps:
        # What PPO starts from, kept: its fine-tuning is judged against it.
        save_policy(model, args.out.with_suffix(".imitated.zip"),
                    spec_of(view(kwargs, args.expert), "MaskablePPO", recorded(kwargs),
                            play="argmax"))
    if args.steps:
        curve = curve_callback(args.out, args.every, args.max_minutes, curve_score(args, kwargs),
                               earlier=rows)
        model.learn(total_timesteps=args.steps, callback=curve)
        rows = curve.rows
    minutes = (time.perf_counter() - start) / 60
    if args.select_round:
        best = selected_round(rows)
        chosen = (point_file(args.out, rows[best]["steps"]) if args.start
                  else round_file(args.out, best))
        shutil.copyfile(chosen, args.out)
        print(f"{chosen} scored best on the curve machines")
    else:
        save_policy(model, args.out, spec_of(view(kwargs, args.expert), "MaskablePPO",
                                             recorded(kwargs), play=play_mode(args)))
    vec.close()
    print(f"wrote {args.out} ({rows[-1]['steps']} steps in {minutes:.1f} min)")
    world = config(args, ()).world
    path = plot_curve(rows, levels, args.out.with_suffix(".curve.png"),
                      reward_label="mean episode reward\n(log fall of predicted MSE)",
                      footnote=f"{world}; {ESTIMATOR}; curve machines of the held-out seed")
    print(f"wrote {path}")
    from calibrators.cli import main as orthoglide

    orthoglide(["compare", "--agents", ",".join((POLICY_PREFIX + str(args.out), *baselines)),
                "--estimators", ESTIMATOR, "--budget", str(args.budget), "--machines",
                str(args.machines), "--seed", str(args.eval_seed), "--conditions",
                args.conditions, "--sigma", str(args.sigma), "--jobs", str(args.jobs),
                *(("--design", str(args.design)) if args.design else ())])


if __name__ == "__main__":
    main()
