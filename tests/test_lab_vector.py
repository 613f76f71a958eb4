"""The native vector env of the lab: N labs in one batch give exactly what N separate
labs give (observations, rewards, flags, infos, notebooks), through re-mounts, lever
flicks, refusals, overtravels, crashes, budget truncations, resets and autoresets."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from test_vector_env import CRASHING, assert_same

import orthoglide_env
from calibrators.study.compare import Config, agent_episodes, run_chunk
from calibrators.study.episodes import make_estimator
from orthoglide_env.envs.lab_vector import OrthoglideLabVectorEnv
from orthoglide_env.lab.machines import ExactMachines, Sight
from orthoglide_env.lab.operations import PAPER_SLOTS, SLOTS, V0_OPS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

N = 4
LAB = orthoglide_env.LAB_ENV_ID
#: A posture whose bars press the y and z legs' x-gauges past their travel.
PRESSING = np.array([-100.0, -16.56, -16.56])


def random_actions(rng: np.random.Generator, stands: int) -> dict[str, np.ndarray]:
    """Per env: mostly moves (small ones that read, across the cube where gauges lose
    their bars, the pressing posture, the crash corner), lever flicks, re-mounts (some
    onto taken slots) and stops."""
    op = rng.choice(V0_OPS, size=N, p=[0.6, 0.12, 0.12, 0.12, 0.04])
    kind = rng.integers(10, size=N)
    rho = rng.uniform(-15, 15, (N, 3))
    rho[kind >= 6] = rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (int(np.sum(kind >= 6)), 3))
    rho[kind == 5] = PRESSING
    rho[(kind == 4) | (kind == 3)] = PROTOTYPE.rho_max
    # Half the re-mounts aim at the paper's slots, where stands stand at the start.
    slot = np.where(rng.random(N) < 0.5, rng.choice(PAPER_SLOTS, size=N),
                    rng.integers(len(SLOTS), size=N))
    return {"op": op, "rho": rho, "stand": rng.integers(stands, size=N), "slot": slot}


def random_reset(rng: np.random.Generator, ended: np.ndarray) -> dict:
    """A reset: an int seed, a list of seeds or none; the crashing machine or a drawn one;
    a mask of envs (every ended env among them)."""
    kwargs: dict = {}
    if rng.random() < 0.5:
        kwargs["seed"] = (int(rng.integers(1000)) if rng.random() < 0.5 else
                          [int(s) if s >= 0 else None for s in rng.integers(-3, 1000, N)])
    options: dict = {}
    if rng.random() < 0.5:
        options["machine"] = CRASHING.to_dict()
    mask = (rng.random(N) < 0.5) | ended
    if mask.any():
        options["reset_mask"] = mask
    kwargs["options"] = options
    return kwargs


def copied(kwargs: dict) -> dict:
    """A fresh copy of reset arguments (SyncVectorEnv pops the mask from the options)."""
    return {**kwargs, "options": {k: (v.copy() if isinstance(v, np.ndarray) else v)
                                  for k, v in kwargs["options"].items()}}


CASES = {
    # Two stands never mounted (refused flicks), short budgets (truncations).
    "next-step": (AutoresetMode.NEXT_STEP, {"stands": 8, "budget_s": 600.0}),
    "same-step tracker ideal": (AutoresetMode.SAME_STEP, {
        "tracker": True, "gauge_sigma": 0.0, "gauge_resolution": 0.0, "budget_s": 400.0}),
    "disabled information": (AutoresetMode.DISABLED, {"reward": "information",
                                                      "budget_s": 300.0, "stands": 3}),
    "accuracy": (AutoresetMode.NEXT_STEP, {"reward": "accuracy", "budget_s": 300.0}),
    # Every effect of the world, re-mountings (their own draws) and the tracker's MPE.
    "workshop world": (AutoresetMode.NEXT_STEP, {"conditions": "workshop", "tracker": True,
                                                 "stands": 8, "budget_s": 600.0}),
    # Digital indicators scatter more at their stroke's ends, from the same draws.
    "digital indicators": (AutoresetMode.NEXT_STEP, {
        "conditions": {"name": "lab", "indicator": "digital"}, "budget_s": 300.0}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_lab_vector_env_is_n_separate_labs(case: str) -> None:
    mode, kwargs = CASES[case]
    if kwargs.get("reward") == "accuracy":
        kwargs = {**kwargs, "estimator": make_estimator("paper6")}
    rng = np.random.default_rng(list(CASES).index(case))
    fast = gym.make_vec(LAB, num_envs=N, autoreset_mode=mode, **kwargs)
    assert isinstance(fast, OrthoglideLabVectorEnv)
    slow = gym.vector.SyncVectorEnv([lambda: gym.make(LAB, **kwargs) for _ in range(N)],
                                    autoreset_mode=mode)
    stands = slow.single_action_space["stand"].n
    # The first episodes on a machine that crashes near the (60, 60, 60) corner; the
    # autoresets draw realistic machines.
    first = {"seed": 7, "options": {"machine": CRASHING.to_dict()}}
    assert_same(fast.reset(**copied(first)), slow.reset(**copied(first)))
    ended = np.zeros(N, dtype=bool)
    seen = {"refused": 0, "overtravel": 0, "remount": 0, "ended": 0, "collision": 0}
    for step in range(70):
        reset = None
        if mode == AutoresetMode.DISABLED and ended.any():
            reset = {"options": {"reset_mask": ended}}
        elif rng.random() < 0.04:
            reset = random_reset(rng, ended)
        if reset is not None:
            assert_same(fast.reset(**copied(reset)), slow.reset(**copied(reset)), f"reset {step}")
            ended[:] = False
        actions = random_actions(rng, stands)
        out = fast.step({k: v.copy() for k, v in actions.items()})
        assert_same(out, slow.step(actions), f"step {step}")
        for i, env in enumerate(slow.envs):
            assert fast.records[i] == env.unwrapped.records, (step, i)
        _, _, terminated, truncated, info = out
        ended = terminated | truncated
        live = info.get("_refused", np.zeros(N, bool))
        seen["refused"] += sum(bool(info["refused"][i]) for i in np.flatnonzero(live))
        seen["overtravel"] += sum(len(o) for o in info["overtravel"] if o)
        seen["remount"] += int(np.sum((actions["op"] == Op.REMOUNT) & live))
        seen["ended"] += int(ended.sum())
        seen["collision"] += int(np.sum(terminated & (actions["op"] != Op.STOP)))
    for i, env in enumerate(slow.envs):
        assert fast.true_machines[i] == env.unwrapped.true_machine
        assert [g.origin.tolist() for g in fast.true_gauges(i)] == [
            g.origin.tolist() for g in env.unwrapped.true_gauges]
    fast.close()
    slow.close()
    # The run went through what it is meant to compare.
    assert all(seen.values()), seen


def test_lab_vector_env_checks_like_the_single_lab() -> None:
    envs = gym.make_vec(LAB, num_envs=3)
    with pytest.raises(RuntimeError, match="reset"):
        envs.step(envs.action_space.sample())
    obs, info = envs.reset(seed=0)
    assert envs.observation_space.contains(obs) and list(info["op"]) == ["reset"] * 3
    # Moves and lever flicks (no stop: every env goes on, so every row is checked below).
    ops = np.array([[0, 1, 2], [2, 0, 1], [0, 0, 0]])
    for op in ops:
        obs, reward, *_ = envs.step({"op": op, "rho": np.full((3, 3), 5.0),
                                     "stand": np.arange(3), "slot": np.zeros(3, int)})
        assert envs.observation_space.contains(obs) and reward.dtype == np.float64
    bad = {"op": np.array([0, 7, 0]), "rho": np.zeros((3, 3)), "stand": np.zeros(3, int),
           "slot": np.zeros(3, int)}
    before = [list(r) for r in envs.records]
    with pytest.raises(ValueError, match="op of env 1"):
        envs.step(bad)
    rho = np.zeros((3, 3))
    rho[2, 0] = 75.0
    with pytest.raises(ValueError, match="rho of env 2"):
        envs.step({**bad, "op": np.zeros(3, int), "rho": rho})
    assert [list(r) for r in envs.records] == before  # no env stepped
    with pytest.raises(ValueError, match="exact"):
        gym.make_vec(LAB, num_envs=2, backend="pybullet")


@pytest.mark.parametrize("conditions", ["ideal", "lab"])
def test_batched_compare_gives_the_per_machine_trials(conditions: str) -> None:
    """compare's batched path (each agent's episodes in one lab vector env) and its
    per-machine path (one lone lab at a time) give the same trials to the last bit: the
    same notebooks, so the same estimates and scores.  A planned agent, one with a
    tracker, and one that acts on its own readings and spends the whole budget; in the
    ideal world and with every effect of the lab's."""
    config = Config(("paper", "tracker", "random"), ("paper", "paper6"), budget_s=600.0,
                    seed=2, conditions=Conditions(conditions))
    batched = run_chunk(config, [0, 1, 2], set(), batched=True)
    alone = run_chunk(config, [0, 1, 2], set(), batched=False)
    assert [t.to_json() for t in batched] == [t.to_json() for t in alone]
    assert len(batched) == 3 * 2 * 3 and any(not t.failed for t in batched)


@pytest.mark.parametrize("conditions", ["ideal", "lab"])
def test_kept_looks_are_the_traced_ones(conditions: str, monkeypatch: pytest.MonkeyPatch
                                        ) -> None:
    """A look the exact machines keep (asked again at the same postures, machines and
    gauges) is the one tracing it again gives: the paper's procedure (every posture
    revisited) and the random agent (its moves, lever flicks and re-mounts) write the same
    notebooks at the same times, to the last bit, either way."""
    config = Config(("paper", "random"), ("paper6",), budget_s=600.0, seed=3,
                    conditions=Conditions(conditions))
    traced = ExactMachines._traced
    calls: list[int] = []

    def counted(*args: np.ndarray) -> Sight:
        calls.append(1)
        return traced(*args)

    def notebooks() -> list[tuple[float, list]]:
        return [(e.run.time_s, e.run.records) for agent in config.agents
                for e in agent_episodes(config, agent, [0, 1, 2])]

    monkeypatch.setattr(ExactMachines, "_traced", staticmethod(counted))
    kept = notebooks()
    misses = len(calls)
    calls.clear()
    monkeypatch.setattr(ExactMachines, "look",
                        lambda self, rows, *args: ExactMachines._traced(*args))
    assert notebooks() == kept
    if conditions == "ideal":
        # The paper's revisits were kept (the lab's carriages drift between visits).
        assert misses < len(calls)
