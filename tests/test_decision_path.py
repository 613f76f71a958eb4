"""The design-view policy's fast decision path: beliefs updated together
(:func:`~orthoglide_env.lab.design_belief.observe_many`), masks together
(:func:`~orthoglide_env.lab.design_belief.action_masks`) and the network's last layer in
float32 over the open actions only (:meth:`ActorWeights.choose_many
<calibrators.agents.actor_weights.ActorWeights.choose_many>`) take the operations that each
belief's own update, observation, mask and float64 logits take."""

from __future__ import annotations

import copy
import dataclasses
import functools
import itertools
from collections.abc import Callable
from contextlib import closing
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents.actor_weights import (
    OPEN_LASTS_KEPT,
    ActorWeights,
    last_layer_bounds,
    read_actor,
)
from calibrators.agents.base import LabRows, action
from calibrators.agents.names import get_agent
from calibrators.agents.policy import DesignPolicyAgent, _taken
from calibrators.study.episodes import agent_rng, machine_seed, run_episodes
from orthoglide_env.lab.counting_rows import FAMILY, TAKEN, CountingRows, taken_of
from orthoglide_env.lab.design_belief import (
    DesignBelief,
    action_masks,
    observations,
    operations_of,
)
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.wrappers import design_lab_env

ROOT = Path(__file__).resolve().parents[1]
SHIPPED_HOUR = ROOT / "examples" / "policies" / "masked_lab3600.zip"
LAB = {"conditions": "lab", "gauge_sigma": 0.02, "budget_s": 3600.0}


def one_by_one(agent: DesignPolicyAgent, observation: dict[str, np.ndarray],
               info: dict[str, Any]) -> dict[str, Any]:
    """The agent's lab action as each agent decided alone before the fast path: its own
    belief's update, observation and mask, and the float64 logits' arg-max (plus a draw's
    noise from the agent's stream, for a policy that draws)."""
    if agent.last is not None:
        agent.belief.observe(agent.last, observation, bool(info.get("refused")))
    if not agent.queue and observation["time"][0] < agent.spec.budget_s:
        logits = agent.actor.logits_many(agent.belief.observation()[None])[0]
        if agent.spec.play == "draw":
            logits += agent.rng.gumbel(size=logits.shape)
        chosen = int(np.argmax(np.where(agent.belief.action_mask(), logits, -np.inf)))
        agent.queue = agent.belief.operations(chosen)
    if not agent.queue:
        return action(Op.STOP)
    agent.last = agent.queue.pop(0)
    return action(agent.last["op"], agent.last["rho"], agent.last["stand"],
                  agent.last["slot"])


def shipped_agent() -> DesignPolicyAgent:
    return get_agent(f"policy:{SHIPPED_HOUR}")


def play(machines: list[int], together: bool, stop_s: float,
         make: Callable[[], DesignPolicyAgent] = shipped_agent, lab: dict[str, Any] = LAB,
         stream: Callable[[int], np.random.Generator] = np.random.default_rng
         ) -> tuple[list[list[tuple[Any, ...]]], list[DesignPolicyAgent]]:
    """Each machine's lab actions (until ``stop_s`` of lab time, or its episode's end) and
    its agent (of ``make``, its stream ``stream`` of the machine's index), on lone labs of
    arguments ``lab``, the chunk deciding together (``act_all``, on lists of the labs'
    observations) or each agent alone (:func:`one_by_one`), its belief then one that
    follows the covariance, as the view's own does."""
    labs = [gym.make(orthoglide_env.LAB_ENV_ID, **lab) for _ in machines]
    agents = [make() for _ in machines]
    state = []
    for lab_, agent, m in zip(labs, agents, machines, strict=True):
        observation, info = lab_.reset(seed=machine_seed(1, m))
        agent.reset(lab_, observation, stream(m))
        if not together and not agent.belief.follows:
            lean = agent.belief
            agent.belief = DesignBelief(lean.design, lean.n_stands, lean.sigma, lean.budget_s,
                                        lean.version)
            agent.belief.start(observation)
        state.append((observation, info))
    taken: list[list[tuple[Any, ...]]] = [[] for _ in machines]
    running = list(range(len(machines)))
    while running:
        if together:
            actions = DesignPolicyAgent.act_all([agents[i] for i in running],
                                                [state[i][0] for i in running],
                                                [state[i][1] for i in running])
        else:
            actions = [one_by_one(agents[i], *state[i]) for i in running]
        done = []
        for i, chosen in zip(running, actions, strict=True):
            taken[i].append((chosen["op"], tuple(chosen["rho"]), chosen["stand"],
                             chosen["slot"]))
            observation, _, terminated, truncated, info = labs[i].step(chosen)
            state[i] = (observation, info)
            if terminated or truncated or observation["time"][0] >= stop_s:
                done.append(i)
        running = [i for i in running if i not in done]
    return taken, agents


@pytest.mark.slow
def test_a_chunk_decides_as_each_agent_alone_did() -> None:
    """Three machines of the one-hour policy, half an hour each: the chunk's fast path
    takes today's operations, action for action, and its beliefs are each agent's own
    to rounding (their stacked products may sum in another order: 1e-9 of the
    covariance's largest entry, the prior's 10^2, is far above that rounding and far
    below anything a reading resolves)."""
    machines = [0, 1, 2]
    fast, fast_agents = play(machines, together=True, stop_s=1800.0)
    slow, slow_agents = play(machines, together=False, stop_s=1800.0)
    assert fast == slow
    # Half an hour of the policy is about 150 operations a machine.
    assert min(len(taken) for taken in fast) > 100
    for a, b in zip(fast_agents, slow_agents, strict=True):
        np.testing.assert_allclose(a.belief.covariance, b.belief.covariance, rtol=0,
                                   atol=1e-9 * np.abs(b.belief.covariance).max())
        np.testing.assert_array_equal(observations([a.belief]), observations([b.belief]))
        np.testing.assert_array_equal(action_masks([a.belief])[0], b.belief.action_mask())


def counting_agent(play: str = "argmax") -> DesignPolicyAgent:
    """An agent of view 2 (``OrthoglideLabDesign-v2``) that plays as ``play`` says: the
    shipped file's spec in that view, with a network of random weights of its sizes
    (seeded; its stop's bias far below, so that it plays the half hour).  What is tested
    is the path to a choice, which is the same whatever the weights."""
    agent = shipped_agent()
    env = design_lab_env(version=2, **LAB)
    size = env.observation_space.shape[0]
    agent.spec = dataclasses.replace(agent.spec, env_id=orthoglide_env.DESIGN_LAB_V2_ENV_ID,
                                     observation_size=size, play=play)
    agent.actor = random_actor(size, env.action_space.n)
    return agent


@functools.cache
def random_actor(inputs: int, actions: int) -> ActorWeights:
    """A network of random weights (seeded) of the shipped one's hidden layers, one for
    all agents of a chunk, as one policy file's agents share theirs."""
    rng = np.random.default_rng(7)
    sizes = (inputs, 128, 128, actions)
    weights = tuple((rng.standard_normal((out, size)) / np.sqrt(size)).astype(np.float32)
                    for size, out in itertools.pairwise(sizes))
    biases = [np.zeros(out, dtype=np.float32) for out in sizes[1:]]
    biases[-1][-1] = -100.0
    return ActorWeights(weights, tuple(biases))


@pytest.mark.slow
def test_view_2_decides_from_counts_as_the_view_s_belief_does() -> None:
    """A policy of view 2 decides without the covariance: its chunk's beliefs only count
    the readings, and take, action for action, the operations that the view's own
    beliefs (which follow the covariance) with float64 logits take, on three machines for
    half an hour.  Their observations and masks are the same floats."""
    machines = [0, 1, 2]
    fast, fast_agents = play(machines, together=True, stop_s=1800.0, make=counting_agent)
    slow, slow_agents = play(machines, together=False, stop_s=1800.0, make=counting_agent)
    assert fast == slow
    assert min(len(taken) for taken in fast) > 100
    # The view holds no value read: the machines passed the same states, one group.
    chunk = fast_agents[0]._chunk
    assert all(a._chunk is chunk for a in fast_agents)
    assert chunk.rows.alike
    assert len(chunk.rows.groups(np.arange(len(machines)))[0]) == 1
    assert_same_beliefs(fast_agents, slow_agents)


def test_view_2_draws_as_each_agent_alone_does() -> None:
    """A view-2 policy that draws: each machine's noise is its own, so the chunk's states
    part and its rows fall into several groups of equal states (and of equal counts);
    each machine still takes, action for action, what its agent alone took, on four
    machines for half an hour."""
    machines = [0, 1, 2, 3]

    def drawing() -> DesignPolicyAgent:
        return counting_agent("draw")

    fast, fast_agents = play(machines, together=True, stop_s=1800.0, make=drawing)
    slow, slow_agents = play(machines, together=False, stop_s=1800.0, make=drawing)
    assert fast == slow
    # A draw of random weights spends more of its time on re-mounts and far moves.
    assert min(len(taken) for taken in fast) > 50
    rows = fast_agents[0]._chunk.rows
    assert not rows.alike
    families = rows.state[:, FAMILY]
    assert len(set(families.tolist())) == len(machines)
    assert_same_beliefs(fast_agents, slow_agents)


class Taken:
    """A watcher of :func:`~calibrators.study.episodes.run_episodes` that keeps each lab's
    actions, as :func:`play` keeps them, and counts the operations its labs refused."""

    def __init__(self, labs: int) -> None:
        self.taken: list[list[tuple[Any, ...]]] = [[] for _ in range(labs)]
        self.refused = 0

    def reset(self, i: int, observation: dict[str, np.ndarray]) -> None:
        pass

    def step(self, i: int, action: dict[str, Any], observation: dict[str, np.ndarray],
             info: Any) -> None:
        self.taken[i].append((action["op"], tuple(action["rho"]), action["stand"],
                              action["slot"]))
        self.refused += bool(info.get("refused"))


def test_a_chunk_reads_its_vector_env_s_arrays_as_its_labs_observations() -> None:
    """Played as ``compare`` plays a chunk (``run_episodes`` on the lab's native vector
    env, which hands over its arrays, :class:`~calibrators.agents.base.LabRows`), a
    view-2 chunk that draws (its rows in several groups) takes, action for action, what
    it takes from lone labs' observations and infos, refusals included: ten-minute labs,
    whose budget's end refuses the operations of a policy trained for an hour."""
    machines, lab = [0, 1, 2], {**LAB, "budget_s": 600.0}

    def drawing() -> DesignPolicyAgent:
        return counting_agent("draw")

    lone, _ = play(machines, together=True, stop_s=np.inf, make=drawing, lab=lab,
                   stream=lambda m: agent_rng(machine_seed(1, m)))
    watched = Taken(len(machines))
    with closing(gym.make_vec(orthoglide_env.LAB_ENV_ID, num_envs=len(machines),
                              vectorization_mode="vector_entry_point", **lab)) as envs:
        run_episodes(envs, [drawing() for _ in machines],
                     [machine_seed(1, m) for m in machines], watch=watched)
    assert watched.taken == lone
    assert watched.refused > 0
    assert min(len(taken) for taken in lone) > 20


def test_a_vector_env_s_arrays_are_taken_in_as_its_labs_observations() -> None:
    """The entries a chunk's rows take in and the refusals, read from a vector env's arrays
    (:class:`~calibrators.agents.base.LabRows`) for labs ``following``, are those read
    lab by lab from each lab's observation and info: a step of three labs in which the
    second refuses a re-mount that would end past the budget, the labs in another order
    than the env's or in its own (whose arrays are then taken in as they are)."""
    with closing(gym.make_vec(orthoglide_env.LAB_ENV_ID, num_envs=3,
                              vectorization_mode="vector_entry_point",
                              **{**LAB, "budget_s": 10.0})) as envs:
        envs.reset(seed=[machine_seed(1, m) for m in range(3)])
        seen, _, _, _, info = envs.step({"op": np.array([Op.LIFT, Op.REMOUNT, Op.ENGAGE]),
                                         "rho": np.zeros((3, 3)), "stand": np.array([0, 1, 1]),
                                         "slot": np.array([0, 3, 0])})
    labs = [{key: value[i] for key, value in seen.items()} for i in range(3)]
    infos = [{key: value[i] for key, value in info.items()
              if not key.startswith("_") and info[f"_{key}"][i]} for i in range(3)]
    assert [bool(i.get("refused")) for i in infos] == [False, True, False]
    for index in (np.array([2, 0, 1]), np.arange(3)):
        rows = LabRows([labs[i] for i in index], seen, index)
        infos_rows = LabRows([infos[i] for i in index], info, index)
        for following in ([0, 1, 2], [1, 2]):
            batch, refused = _taken(rows, infos_rows, following)
            lone, lone_refused = _taken(list(rows), list(infos_rows), following)
            for key in TAKEN:
                np.testing.assert_array_equal(batch[key], lone[key])
            np.testing.assert_array_equal(refused, lone_refused)
            assert refused.tolist() == [i == 1 for i in index[following].tolist()]


def assert_same_beliefs(fast_agents: list[DesignPolicyAgent],
                        slow_agents: list[DesignPolicyAgent]) -> None:
    """The chunk's counting beliefs (written back) observe and mask as the view's own
    beliefs, which followed the covariance, and kept their prior."""
    for a, b in zip(fast_agents, slow_agents, strict=True):
        assert not a.belief.follows and b.belief.follows
        # The view's belief learnt from its readings; the lean one kept its prior.
        assert b.belief.predicted_mse() < 0.1 * np.trace(b.belief.weight)
        np.testing.assert_array_equal(a.belief.covariance, np.eye(len(a.belief.covariance)))
        np.testing.assert_array_equal(observations([a.belief]), [b.belief.observation()])
        np.testing.assert_array_equal(action_masks([a.belief])[0], b.belief.action_mask())


def observed_states() -> tuple[np.ndarray, np.ndarray]:
    """The one-hour policy's observations and masks over the first 300 s of two machines,
    decided one by one."""
    seen, masks = [], []
    for m in (3, 4):
        lab = gym.make(orthoglide_env.LAB_ENV_ID, **LAB)
        agent = get_agent(f"policy:{SHIPPED_HOUR}")
        observation, info = lab.reset(seed=machine_seed(1, m))
        agent.reset(lab, observation, np.random.default_rng(m))
        while observation["time"][0] < 300.0:
            if agent.last is not None:
                agent.belief.observe(agent.last, observation, bool(info.get("refused")))
            seen.append(agent.belief.observation())
            masks.append(agent.belief.action_mask())
            agent.last = None
            observation, _, _, _, info = lab.step(one_by_one(agent, observation, info))
    return np.array(seen), np.array(masks)


@pytest.fixture(scope="session")
def states() -> tuple[np.ndarray, np.ndarray]:
    return observed_states()


def test_the_float32_choice_is_the_float64_choice(states: tuple[np.ndarray, np.ndarray]
                                                  ) -> None:
    """``choose_many`` picks float64's arg-max over the open actions in every state an
    episode reached, in chunks of one and of all, with a draw's noise too."""
    actor = read_actor(SHIPPED_HOUR)
    seen, masks = states
    assert len(seen) > 40
    exact = actor.logits_many(seen)
    best = np.argmax(np.where(masks, exact, -np.inf), axis=1)
    np.testing.assert_array_equal(actor.choose_many(seen, masks), best)
    np.testing.assert_array_equal([actor.choose_many(s[None], m[None])[0]
                                   for s, m in zip(seen, masks, strict=True)], best)
    noise = np.random.default_rng(0).gumbel(size=exact.shape)
    np.testing.assert_array_equal(actor.choose_many(seen, masks, noise),
                                  np.argmax(np.where(masks, exact + noise, -np.inf), axis=1))


def test_open_actions_last_layers_are_kept_and_choose_alike(
        states: tuple[np.ndarray, np.ndarray]) -> None:
    """``choose_many`` keeps the last layer of each set of open actions for the next
    states of the same set: a state decides as float64 does whether its block was made
    or kept, and at most ``OPEN_LASTS_KEPT`` blocks are kept, however many sets pass
    (random masks over the states reached, twice as many sets as are kept)."""
    actor = dataclasses.replace(read_actor(SHIPPED_HOUR))
    seen, masks = states
    exact = actor.logits_many(seen)
    rng = np.random.default_rng(3)
    drawn = rng.random((2 * OPEN_LASTS_KEPT, masks.shape[1])) < 0.25
    for mask_of in (masks, drawn[np.arange(len(seen)) % len(drawn)]):
        best = np.argmax(np.where(mask_of, exact, -np.inf), axis=1)
        for _ in range(2):
            np.testing.assert_array_equal([actor.choose_many(s[None], m[None])[0]
                                           for s, m in zip(seen, mask_of, strict=True)], best)
        assert 1 < len(actor._open_lasts) <= OPEN_LASTS_KEPT
    assert len(actor._open_lasts) == OPEN_LASTS_KEPT


def test_a_near_tie_is_decided_in_float64(states: tuple[np.ndarray, np.ndarray]) -> None:
    """Where two open actions' logits are closer than the float32 bound, float64 decides:
    a noise that brings the runner-up to 1e-12 below or above the best (far inside the
    float32 logits' rounding, about 1e-6) flips the choice as float64 says it must."""
    actor = read_actor(SHIPPED_HOUR)
    seen, masks = states
    exact = actor.logits_many(seen)
    for gap in (1e-12, -1e-12):
        noise = np.zeros_like(exact)
        for k, (row, mask) in enumerate(zip(exact, masks, strict=True)):
            order = np.flatnonzero(mask)[np.argsort(row[mask])]
            if len(order) > 1:
                noise[k, order[-2]] = row[order[-1]] - row[order[-2]] - gap
        expected = np.argmax(np.where(masks, exact + noise, -np.inf), axis=1)
        np.testing.assert_array_equal(actor.choose_many(seen, masks, noise), expected)


def test_the_bound_holds_on_the_float32_logits(states: tuple[np.ndarray, np.ndarray]
                                               ) -> None:
    """Each action's bound is above the distance between its float32 logit (from float64
    hidden values) and its float64 one, in every state reached, yet small beside the
    logits' gaps (below 1e-3: the network's largest row of weights sums to about 100)."""
    actor = read_actor(SHIPPED_HOUR)
    seen, _ = states
    hidden = actor._hidden(seen)
    weight, bias = actor.weights[-1], actor.biases[-1]
    fast = (hidden.astype(np.float32) @ weight.T).astype(np.float64) + bias
    bounds = last_layer_bounds(weight, bias)
    assert np.all(np.abs(fast - actor.logits_many(seen)) <= bounds)
    assert bounds.max() < 1e-3


def test_a_mask_near_the_budget_s_end_is_each_move_s_own() -> None:
    """``action_masks`` opens a move some stand reads likely that ends within the budget:
    the state's readable moves as they are while its longest one ends in time, each move's
    end against the budget once it does not.  Beliefs of one state at clocks from the
    start to past the budget, in one chunk."""
    env = design_lab_env(version=1, **LAB)
    env.reset(seed=0)
    belief = env.belief
    seconds, _, _, readable, latest = belief._candidates()
    assert readable.any() and 0.0 < latest == seconds[readable].max()
    budget = belief.budget_s
    clocks = [0.0, budget - latest, budget - latest + 1.0, budget - seconds[readable].min(),
              budget - 5.0, budget + 1.0]
    beliefs = []
    for clock in clocks:
        twin = copy.copy(belief)
        twin.time_s = clock
        beliefs.append(twin)
    masks = action_masks(beliefs)[:, :belief.n_postures]
    expected = readable & (np.array(clocks)[:, None] + seconds <= budget)
    np.testing.assert_array_equal(masks, expected)
    # Both ways are taken: all readable moves open, some closed, none open.
    assert masks[0].sum() == masks[1].sum() == readable.sum() > masks[2].sum() > 0
    assert not masks[-1].any()


def test_bad_masks_are_refused(states: tuple[np.ndarray, np.ndarray]) -> None:
    actor = read_actor(SHIPPED_HOUR)
    seen, masks = states
    with pytest.raises(ValueError, match="an open action in every row"):
        actor.choose_many(seen[:2], np.zeros_like(masks[:2]))
    with pytest.raises(ValueError, match=r"masks are \(N, 1735\)"):
        actor.choose_many(seen[:2], masks[:3])


def lab_observation(slots: list[int], engaged: list[int], faulted: list[int],
                    time_s: float) -> dict[str, np.ndarray]:
    """A lab observation's entries that a counting belief reads, of the lab's dtypes."""
    return {"slot": np.array(slots, dtype=np.int64), "engaged": np.array(engaged, dtype=np.int8),
            "faulted": np.array(faulted, dtype=np.int8), "valid": np.zeros(len(slots), np.int8),
            "time": np.array([time_s])}


def test_counting_rows_take_in_a_step_as_each_belief_does() -> None:
    """``CountingRows.observe`` of one step in which five rows did different things (a
    move, the same move refused, a re-mount, a lever flick, the same move again with a
    stand at a slot beyond the catalogue and another out of service), then a step that
    stays for one row and leaves for another: each row is what its belief's own
    ``observe`` makes of it, and observes and masks as it does."""
    design = PROTOTYPE
    beliefs = [DesignBelief(design, 6, 0.02, 3600.0, 2, covariance=False) for _ in range(5)]
    first = lab_observation([0, 5, 10, 15, 20, 25], [0] * 6, [0] * 6, 0.0)
    for belief in beliefs:
        belief.start(first)
    rows = CountingRows(beliefs)
    everyone = np.arange(len(beliefs))
    table = beliefs[0].table
    here, there = (int(k) for k in np.flatnonzero(beliefs[0].action_mask()[:table.zero])[:2])
    move = operations_of(table, 6, beliefs[0].n_slots, here, beliefs[0].moves()[1],
                         beliefs[0].engaged)[-1]
    leave = {**move, "rho": table.postures[there].copy()}
    remount = {"op": Op.REMOUNT, "rho": np.zeros(3), "stand": 1, "slot": 3}
    flick = {"op": Op.ENGAGE, "rho": np.zeros(3), "stand": 0, "slot": 0}
    beyond = beliefs[0].n_slots + 2
    steps = [([move, move, remount, flick, move], [False, True, False, False, False],
              [lab_observation([0, 5, 10, 15, 20, 25], [1, 0, 0, 0, 0, 0], [0] * 6, 40.0),
               lab_observation([0, 5, 10, 15, 20, 25], [0] * 6, [0] * 6, 41.0),
               lab_observation([0, 3, 10, 15, 20, 25], [0] * 6, [0] * 6, 90.0),
               lab_observation([0, 5, 10, 15, 20, 25], [1, 0, 0, 0, 0, 0], [0] * 6, 2.0),
               lab_observation([0, 5, beyond, 15, 20, 25], [0, 0, 1, 0, 0, 0],
                               [0, 0, 0, 1, 0, 0], 40.0)]),
             ([move, leave], [False, False],
              [lab_observation([0, 5, 10, 15, 20, 25], [1, 0, 0, 0, 0, 0], [0] * 6, 80.0),
               lab_observation([0, 5, beyond, 15, 20, 25], [0, 0, 1, 0, 0, 0],
                               [0, 0, 0, 1, 0, 0], 80.0)])]
    for which, (operations, refused, seen) in zip((everyone, np.array([0, 4])), steps,
                                                  strict=True):
        step_both(rows, beliefs, which, operations, seen, refused)
    # The second step stayed for row 0 (two readings in a row), left for row 4.
    assert (beliefs[0].run, beliefs[4].run) == (2, 1)
    assert beliefs[4].here == there and beliefs[2].here == table.zero
    assert not rows.alike


def step_both(rows: CountingRows, beliefs: list[DesignBelief], which: np.ndarray,
              operations: list[dict[str, object]], seen: list[dict[str, np.ndarray]],
              refused: list[bool]) -> None:
    """One step taken in by ``rows`` ``which`` and by their beliefs' own ``observe``: each
    row, written back, is its belief, and the rows observe and mask as the beliefs do."""
    rows.observe(which, operations, taken_of(seen), refused)
    for k, operation, observation, no in zip(which.tolist(), operations, seen, refused,
                                             strict=True):
        beliefs[k].observe(operation, observation, no)
    assert_rows_are(rows, beliefs)


def assert_rows_are(rows: CountingRows, beliefs: list[DesignBelief]) -> None:
    """Each row of ``rows``, written back, is its belief of ``beliefs``, and the rows
    observe and mask as the beliefs do."""
    for k, belief in enumerate(beliefs):
        written = copy.copy(belief)
        rows.write_back(k, written)
        for name in ("slots", "engaged", "faulted", "rho", "readings_at"):
            np.testing.assert_array_equal(getattr(written, name), getattr(belief, name))
        assert (written.here, written.run, written.time_s) == (
            belief.here, belief.run, belief.time_s)
    everyone = np.arange(len(beliefs))
    parts = rows.parts(everyone)
    np.testing.assert_array_equal(rows.observations(everyone, parts),
                                  [b.observation() for b in beliefs])
    np.testing.assert_array_equal(rows.masks(everyone, parts),
                                  [b.action_mask() for b in beliefs])


def started_beliefs(count: int, time_s: float = 0.0) -> list[DesignBelief]:
    """``count`` counting beliefs of the prototype's lab (6 stands), started at Zero at
    ``time_s`` with the stands at slots 0, 5, ... 25, plungers up."""
    beliefs = [DesignBelief(PROTOTYPE, 6, 0.02, 3600.0, 2, covariance=False)
               for _ in range(count)]
    for belief in beliefs:
        belief.start(lab_observation([0, 5, 10, 15, 20, 25], [0] * 6, [0] * 6, time_s))
    return beliefs


def test_counting_rows_take_in_a_step_alike_on_one_row(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """A step that every row of one state takes alike (one operation's dict, labs of
    equal records) is taken in on one row and given to all: twice the same move (a stay),
    the rows stay one state, each its belief's own ``observe``.  A step in which one lab
    differs (a stand out of service) is taken in row by row and parts the rows."""
    beliefs = started_beliefs(4)
    rows = CountingRows(beliefs)
    assert rows.alike
    stepped: list[int] = []
    step = rows._step

    def counted(state: np.ndarray, *rest: Any) -> tuple[np.ndarray, np.ndarray]:
        stepped.append(len(state))
        return step(state, *rest)

    monkeypatch.setattr(rows, "_step", counted)
    everyone = np.arange(len(beliefs))
    here = int(np.flatnonzero(beliefs[0].action_mask()[:beliefs[0].n_postures])[0])
    move = beliefs[0].operations(here)[-1]
    for time_s in (40.0, 80.0):
        seen = [lab_observation([0, 5, 10, 15, 20, 25], [0] * 6, [0] * 6, time_s)
                for _ in beliefs]
        step_both(rows, beliefs, everyone, [move] * len(beliefs), seen, [False] * 4)
        assert rows.alike
    assert stepped == [1, 1] and beliefs[0].run == 2
    seen = [lab_observation([0, 5, 10, 15, 20, 25], [0] * 6, [0] * 6, 120.0)
            for _ in beliefs]
    seen[2]["faulted"][1] = 1
    step_both(rows, beliefs, everyone, [move] * len(beliefs), seen, [False] * 4)
    assert stepped == [1, 1, 4] and not rows.alike
    assert rows.groups(everyone)[1].tolist() == [0, 0, 1, 0]


def test_counting_rows_mask_near_the_budget_s_end_as_each_belief_does() -> None:
    """The rows' masks are each state's kept mask until its longest operation would end
    past the budget, then each operation's end against it, as each belief's own
    ``action_mask``: beliefs at Zero (longest readable move 25 s, a re-mount 125 s) at
    clocks from the start to past the budget."""
    budget = 3600.0
    clocks = [0.0, budget - 125.0, budget - 124.0, budget - 24.0, budget - 18.0,
              budget + 1.0]
    beliefs = [started_beliefs(1, clock)[0] for clock in clocks]
    rows = CountingRows(beliefs)
    assert_rows_are(rows, beliefs)
    everyone = np.arange(len(beliefs))
    masks = rows.masks(everyone, rows.parts(everyone))
    postures = beliefs[0].n_postures
    moves, remounts = masks[:, :postures].sum(axis=1), masks[:, postures:-1].sum(axis=1)
    # Both closings are taken: re-mounts from budget - 124 s on, moves from budget - 24 s.
    assert remounts[0] == remounts[1] > 0 == remounts[2]
    assert moves[0] == moves[2] > moves[3] > moves[4] > 0 == moves[5]
