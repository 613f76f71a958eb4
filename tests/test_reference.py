"""The length reference: a gauge block the lab zeroes a platform gauge against, what its
readings measure, how the model reads them, and the agents that use it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.base import action
from calibrators.agents.reference import POSTURES, reference_seconds, reference_steps
from calibrators.measurements import Measurements
from calibrators.study.episodes import measurements_of, run_episode
from orthoglide_env.instruments.slots import GaugeSpec, Part, layout_from_names
from orthoglide_env.lab.operations import SLOTS, TIME, Op, slot_catalogue
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.reading_model import ReadingLayout, parameters_of, predict
from orthoglide_env.world.table import REFERENCE_DEVIATION, REFERENCE_LENGTH_MM

LAB = orthoglide_env.LAB_ENV_ID


def reference_lab(**kwargs) -> gym.Env:
    kwargs = {"reference": True, "gauge_sigma": 0.0, "gauge_resolution": 0.0, **kwargs}
    return gym.make(LAB, **kwargs)


def read_references(env: gym.Env, seed: int) -> list:
    """The reference procedure alone on machine ``seed``: its records of reference
    mountings."""
    env.reset(seed=seed)
    for act in reference_steps(env.unwrapped.n_stands, PROTOTYPE):
        env.step(act)
    return [r for r in env.unwrapped.records if r.spec.part == Part.REFERENCE]


def test_the_catalogue_has_reference_slots_only_in_a_lab_with_the_block() -> None:
    plain, block = slot_catalogue(PROTOTYPE), slot_catalogue(PROTOTYPE, True)
    assert plain == SLOTS  # a lab without the block is as it was, indices and all
    assert block[:len(plain)] == plain
    assert [s.slot for s in block[len(plain):]] == ["reference/x", "reference/y", "reference/z"]
    assert reference_lab().unwrapped.observation_space["slot"].nvec[0] == len(block) + 1
    assert gym.make(LAB).unwrapped.observation_space["slot"].nvec[0] == len(plain) + 1
    assert layout_from_names(["reference/y"]) == (GaugeSpec.reference(1),)
    with pytest.raises(ValueError, match="platform gauge has no leg"):
        GaugeSpec(0, 1, part=Part.REFERENCE)


@pytest.mark.parametrize("conditions", ["ideal", "lab"])
def test_the_zeroing_reading_is_through_the_block_and_priced(conditions: str) -> None:
    """A re-mount at a reference slot reads 0 at Zero (the dial was zeroed on the block),
    costs the block's handling on top of a re-mount, and afterwards the bare face is out
    of reach at Zero (no reading) and in it a block's length back."""
    env = reference_lab(conditions=conditions)
    env.reset(seed=4)
    for k in range(1, 6):
        env.step(action(Op.LIFT, stand=k))
    slot = [s.slot for s in env.unwrapped.slots].index("reference/x")
    obs, _, _, _, info = env.step(action(Op.REMOUNT, stand=0, slot=slot))
    assert obs["valid"][0] == 1 and abs(obs["gauges"][0]) < 1e-6
    assert info["step_time_s"] == pytest.approx(
        float(TIME.move(np.zeros(3), np.zeros(3))) + TIME.remount_s + TIME.reference_s)
    obs, *_ = env.step(action(Op.MOVE, np.array([1.0, 0.0, 0.0])))
    assert obs["valid"][0] == 0  # the face is a block's length beyond the plunger
    obs, *_ = env.step(action(Op.MOVE, np.array([-REFERENCE_LENGTH_MM, 0.0, 0.0])))
    assert obs["valid"][0] == 1 and abs(obs["gauges"][0]) < 0.5


def test_the_readings_measure_the_platform_travel_against_the_block() -> None:
    """In an ideal world with exact gauges a bare-face reading minus the zeroing reading
    is the platform's true travel along the axis less the block's length, up to the
    cosine of the stand's tilt (5 mrad: a relative 1e-5 of a few mm)."""
    env = reference_lab(conditions="ideal")
    env.reset(seed=6)
    for k in range(1, 6):
        env.step(action(Op.LIFT, stand=k))
    batch = env.unwrapped._batch
    slot = [s.slot for s in env.unwrapped.slots].index("reference/y")
    env.step(action(Op.REMOUNT, stand=0, slot=slot))
    zero = batch.true_tcp(0)
    for along in (-51.0, -49.0, -48.0):
        obs, *_ = env.step(action(Op.MOVE, np.array([2.0, along, -3.0])))
        travel = batch.true_tcp(0)[1] - zero[1]
        assert obs["gauges"][0] == pytest.approx(travel + REFERENCE_LENGTH_MM, abs=1e-4)


@pytest.mark.parametrize("backend", ["exact", "pybullet"])
def test_the_model_reads_the_reference_as_the_lab_does(backend: str) -> None:
    """The exact model (the block's nominal length over the ray's cosine at Zero) gives
    the lab's readings up to each mounting's zero, on both backends, within 1e-6 mm (in
    the textbook world, which the model is of)."""
    env = reference_lab(backend=backend, conditions="ideal")
    records = read_references(env, seed=5)
    assert {r.mounting.split("#")[0] for r in records} == {
        "reference/x", "reference/y", "reference/z"}
    design = ReadingLayout.of([r.mounting for r in records], [r.spec for r in records],
                       np.array([r.rho for r in records]), PROTOTYPE)
    assert np.count_nonzero(design.through) == 3  # one zeroing reading per mounting
    batch = env.unwrapped._batch
    theta = parameters_of(design, batch.machines[0], batch.true_gauges(0))
    residual = np.array([r.reading for r in records]) - predict(theta, design)
    for m in range(len(design.mountings)):
        assert np.ptp(residual[design.mounting == m]) < 1e-6


def test_the_block_deviation_is_drawn_within_its_grade() -> None:
    """Under lab conditions each episode's block deviates from its nominal length within
    the grade's limit, drawn after the machine."""
    low, high = REFERENCE_DEVIATION.at("lab")
    env = reference_lab(conditions="lab")
    lengths = []
    for seed in range(20):
        env.reset(seed=seed)
        lengths.append(env.unwrapped._batch.block_length[0])
    deviation = np.abs(np.array(lengths) - REFERENCE_LENGTH_MM) * 1e3
    assert np.all((deviation >= low) & (deviation <= high)) and np.ptp(deviation) > 0
    # Drawn after the machine and its world: the same seed draws the same machine.
    plain, block = gym.make(LAB, conditions="lab"), reference_lab(conditions="lab")
    plain.reset(seed=3)
    block.reset(seed=3)
    assert np.array_equal(plain.unwrapped._batch.machines.to_vector(),
                          block.unwrapped._batch.machines.to_vector())


@pytest.mark.slow
def test_an_agent_with_the_reference_keeps_its_time_back() -> None:
    """``paper+reference`` plays the paper's procedure, then the reference's, within the
    budget; an agent that plans to the budget ends its own part that much earlier."""
    env = reference_lab(gauge_sigma=0.02, gauge_resolution=0.01, budget_s=1800.0)
    episode = run_episode(env, get_agent("paper+reference"), 7)
    names = {r.mounting.split("#")[0] for r in env.unwrapped.records}
    assert {"reference/x", "reference/y", "reference/z"} <= names
    assert episode.time_s < 1800.0
    reads = [r for r in env.unwrapped.records if r.spec.part == Part.REFERENCE]
    assert len(reads) == 3 * (1 + len(POSTURES))  # every posture in the plunger's travel
    agent = get_agent("optimal+reference")
    env = reference_lab(gauge_sigma=0.02, gauge_resolution=0.01, budget_s=1800.0)
    observation, _ = env.reset(seed=7)
    agent.reset(env, observation, np.random.default_rng(0))
    assert agent.inner.reserved_s == reference_seconds(6, PROTOTYPE)
    ops = [int(a["op"]) for a in agent.plan]
    assert ops[-1] == Op.STOP and ops.count(Op.STOP) == 1


def test_agents_that_need_the_block_are_refused_without_it() -> None:
    env = gym.make(LAB)
    observation, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="needs a lab with the gauge block"):
        get_agent("active+reference").reset(env, observation, np.random.default_rng(0))
    with pytest.raises(ValueError, match="already reads the length reference"):
        get_agent("paper+reference+reference")
    with pytest.raises(ValueError, match="unknown agent"):
        get_agent("+reference")


def test_a_measurement_file_carries_reference_readings(tmp_path) -> None:
    """Reference readings go through a CSV file and back unchanged (their gauge's name
    says the zeroing reading is through the block)."""
    env = reference_lab(gauge_sigma=0.02, gauge_resolution=0.01)
    read_references(env, seed=2)
    data = measurements_of(list(env.unwrapped.records), design=PROTOTYPE)
    for suffix in ("csv", "json"):
        path = tmp_path / f"readings.{suffix}"
        data.write(path)
        back = Measurements.read(path)
        assert back.items == data.items
    assert any(m.gauge == GaugeSpec.reference(2) for m in back.items)
