"""A move that leaves the interferometer unread (``OrthoglideLab-v4``'s action key
``laser``): what it saves and skips, that it changes nothing else, that every face of
the lab agrees on it, and that v3 keeps its spaces."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents.base import action
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.lab.operations import TIME, Op

V3, V4 = orthoglide_env.LAB_V3_ENV_ID, orthoglide_env.LAB_V4_ENV_ID
OWNED = ["dial", "interferometer"]
#: Postures every stand of the paper's layout reads at (small moves about Zero).
POSTURES = (np.array([5.0, -3.0, 2.0]), np.array([-4.0, 6.0, -1.0]), np.array([2.0, 2.0, -6.0]))


def _lab(env_id: str = V4, conditions: str = "ideal", backend: str = "exact") -> gym.Env:
    return gym.make(env_id, backend=backend, conditions=conditions, instruments=OWNED,
                    budget_s=1e5)


def _played(env: gym.Env, lasers: list[int | None], seed: int = 3, align: bool = True
            ) -> tuple[list[dict], list[dict]]:
    """Reset, set the laser up along y (or not), then move to :data:`POSTURES` in turn,
    each move's ``laser`` key from ``lasers`` (None: left out): every observation and
    info from the set-up on."""
    env.reset(seed=seed)
    seen = [env.step(action(Op.ALIGN, axis=1))] if align else []
    for k, laser in enumerate(lasers):
        keys = {} if laser is None else {"laser": laser}
        seen.append(env.step(action(Op.MOVE, POSTURES[k % len(POSTURES)], **keys)))
    return [s[0] for s in seen], [s[4] for s in seen]


def _laser_records(env: gym.Env) -> list:
    return [r for r in env.unwrapped.records if isinstance(r.spec, InterferometerAxis)]


def test_v3_keeps_its_spaces_and_refuses_the_key():
    v3, v4 = _lab(V3), _lab(V4)
    assert "laser" not in v3.action_space.spaces
    assert v4.action_space["laser"] == gym.spaces.Discrete(2)
    assert v4.observation_space == v3.observation_space
    assert {k: s for k, s in v4.action_space.spaces.items() if k != "laser"} == dict(
        v3.action_space.spaces)
    v3.reset(seed=0)
    with pytest.raises(ValueError, match="keys"):
        v3.step(action(Op.MOVE, POSTURES[0], laser=0))


def test_a_move_without_the_laser_saves_its_dwell_and_reads_the_same_dials():
    # From the same state: the move that leaves the laser unread takes exactly the dwell
    # less, writes no laser record and shows none, and every dial reads the same bytes
    # (no world: the dwell's seconds move nothing the dials see).
    read, skipped = _lab(), _lab()
    (*_, on), (*_, on_info) = _played(read, [1, 1])
    (*_, off), (*_, off_info) = _played(skipped, [1, 0])
    assert on_info["step_time_s"] - off_info["step_time_s"] == TIME.interferometer_target_s
    assert on["interferometer_valid"][0] == 1 and off["interferometer_valid"][0] == 0
    assert off["interferometer"][0] == 0.0
    assert np.array_equal(on["gauges"], off["gauges"]) and np.array_equal(on["valid"],
                                                                           off["valid"])
    assert len(_laser_records(read)) == len(_laser_records(skipped)) + 1
    dials = [[r for r in env.unwrapped.records if not isinstance(r.spec, InterferometerAxis)]
             for env in (read, skipped)]
    assert [(r.spec, r.reading, r.rho) for r in dials[0]] == [
        (r.spec, r.reading, r.rho) for r in dials[1]]
    # The laser keeps its count: the next move that reads it reads it as if none was
    # skipped (its zero and set-up unchanged).
    assert on["interferometer_axis"] == off["interferometer_axis"] == 1


def test_the_key_left_out_or_one_is_v3_bit_for_bit():
    # v1-v3's behaviour is v4's with the key left out or 1, under the lab's world (time,
    # warm-up and every draw of the stream included).
    runs = []
    for env_id, lasers in ((V3, [None] * 4), (V4, [None] * 4), (V4, [1] * 4)):
        env = _lab(env_id, "lab")
        obs, infos = _played(env, lasers)
        runs.append((obs, [i["step_time_s"] for i in infos], env.unwrapped.records))
    for obs, times, records in runs[1:]:
        assert times == runs[0][1] and records == runs[0][2]
        for got, expected in zip(obs, runs[0][0], strict=True):
            assert all(np.array_equal(got[k], expected[k]) for k in expected)


def test_the_key_does_nothing_without_a_laser_set_up_or_off_a_move():
    # Before any set-up a move's laser key changes nothing; on the set-up itself (not a
    # move) neither: its reading at Zero is taken.
    plain, asked = _lab(), _lab()
    _played(plain, [1, 1], align=False)
    _played(asked, [0, 0], align=False)
    assert plain.unwrapped.records == asked.unwrapped.records
    for env in (plain, asked):
        env.reset(seed=4)
    plain.step(action(Op.ALIGN, axis=0))
    obs, *_ = asked.step(action(Op.ALIGN, axis=0, laser=0))
    assert obs["interferometer_valid"][0] == 1
    assert plain.unwrapped.records == asked.unwrapped.records


@pytest.mark.parametrize("bad", [2, -1, True, 0.5, "0"])
def test_bad_values_are_refused_naming_the_key(bad):
    env = _lab()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="laser"):
        env.step(action(Op.MOVE, POSTURES[0]) | {"laser": bad})
    envs = gym.make_vec(V4, num_envs=2, vectorization_mode="vector_entry_point",
                        backend="exact", conditions="ideal", instruments=OWNED)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="laser"):
        envs.step({"op": np.full(2, Op.MOVE), "rho": np.stack(POSTURES[:2]),
                   "stand": np.zeros(2, int), "slot": np.zeros(2, int),
                   "laser": np.array([1, 2]) if not isinstance(bad, str) else bad})


def test_both_backends_agree():
    seen = []
    for backend in ("exact", "pybullet"):
        env = _lab(conditions="lab", backend=backend)
        obs, infos = _played(env, [0, 1, 0, 1], seed=5)
        seen.append(([float(o["interferometer"][0]) for o in obs],
                     [int(o["interferometer_valid"][0]) for o in obs],
                     [i["step_time_s"] for i in infos]))
        env.close()
    assert seen[0] == seen[1]
    assert seen[0][1] == [1, 0, 1, 0, 1]


def test_a_batch_of_n_is_n_lone_labs():
    n = 3
    envs = gym.make_vec(V4, num_envs=n, vectorization_mode="vector_entry_point",
                        backend="exact", conditions="lab", instruments=OWNED, budget_s=1e5)
    envs.reset(seed=11)
    base = {"rho": np.zeros((n, 3)), "stand": np.zeros(n, int), "slot": np.zeros(n, int)}
    steps = [{**base, "op": np.full(n, Op.ALIGN), "axis": np.arange(n)}]
    for k, lasers in enumerate(([0, 1, 0], [1, 0, 0], [1, 1, 0])):
        steps.append({**base, "op": np.full(n, Op.MOVE),
                      "rho": np.tile(POSTURES[k], (n, 1)), "laser": np.array(lasers)})
    batched = [envs.step(step) for step in steps]
    for i in range(n):
        env = _lab(conditions="lab")
        env.reset(seed=11 + i)
        for step, (obs, _, _, _, info) in zip(steps, batched, strict=True):
            one = {k: v[i] for k, v in step.items()}
            lone, *_, lone_info = env.step(one)
            assert all(np.array_equal(lone[k], obs[k][i]) for k in lone)
            assert lone_info["step_time_s"] == info["step_time_s"][i]
        assert env.unwrapped.records == envs.unwrapped.records[i]


def test_check_env_is_clean_with_the_laser_key():
    import warnings

    from gymnasium.utils.env_checker import check_env
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(_lab(conditions="lab").unwrapped, skip_render_check=True)
    # The one warning left, as for v0 to v3: joint targets are in mm, not a normalised box.
    messages = {str(w.message) for w in caught}
    assert all("symmetric and normalized" in m for m in messages), messages
