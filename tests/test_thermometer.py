"""The lab's room thermometer: what its records carry, that it changes nothing else, and
what the ``full`` estimator makes of it."""

from __future__ import annotations

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import orthoglide_env
from calibrators.cli import main
from calibrators.estimators.catalogue import for_study
from calibrators.estimators.consider import WORLD_PREFIX, consider_terms
from calibrators.estimators.gauss_newton import layout_and_values
from calibrators.measurements import Measurements
from calibrators.study.episodes import measurements_of
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import machine_dict
from orthoglide_env.world.table import EFFECTS
from orthoglide_env.world.truth import REFERENCE_C, WALK_MODES

#: Where the room's growth of the stands' arms is the only drift: a shop's 1 K/h drift
#: and its walk, each stand's creep and give.  The drives' warm-up, also a smooth drift
#: of every reading, is left out: it trades with the arms' growth with or without a
#: thermometer.
GROWTH = Conditions("workshop", ("room", "stands", "thermometer"))
#: A heating cycle (K): the room's fastest walk mode (a period of 2.1 h) at this amplitude.
SWING_K = 0.6


def _hour(conditions: Conditions | str, thermometer: bool, seed: int = 3,
          budget_s: float = 3600.0, swing: bool = False) -> tuple[gym.Env, list[dict]]:
    """A lab that reads the paper's six gauges (0.5 um noise, 0.1 um resolution) at small
    moves about Zero (within their travel) until its budget runs out, and its
    observations; ``swing``: its room, as drawn, with a heating cycle of :data:`SWING_K`
    on its walk."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, backend="exact", conditions=conditions,
                   thermometer=thermometer, gauge_sigma=0.0005, gauge_resolution=0.0001,
                   budget_s=budget_s)
    observation, _ = env.reset(seed=seed)
    if swing:
        lab = env.unwrapped
        walk = lab.true_world.walk.copy()
        k = WALK_MODES - 0.5  # the mode's amplitude is sqrt(2) / (pi k) of its value
        walk[0, -1] += SWING_K * np.pi * k / np.sqrt(2)
        world = lab.true_world.replace(walk=walk)
        observation, _ = env.reset(seed=seed, options={
            "machine": machine_dict(lab.true_machine, world)})
    seen = [observation]
    moves = np.random.default_rng(0).uniform(-3.0, 3.0, (12, 3))
    k, done = 0, False
    while not done:
        observation, _, terminated, truncated, _ = env.step(
            {"op": 0, "rho": moves[k % len(moves)], "stand": 0, "slot": 0})
        seen.append(observation)
        done, k = terminated or truncated, k + 1
    return env, seen


def test_records_carry_the_room_temperature_within_the_thermometers_error() -> None:
    """Each record's temperature is the room's at its time plus the lab's one offset,
    within the class A tolerance, rounded to the resolution; without the thermometer
    effect it is the truth."""
    tolerance = EFFECTS["thermometer"]["tolerance"].workshop[1]
    step = EFFECTS["thermometer"]["resolution"].workshop[0]
    env, _ = _hour("workshop", True, budget_s=900.0)
    records = env.unwrapped.records
    world = env.unwrapped.true_world
    truth = REFERENCE_C + world[np.zeros(len(records), int)].temperature(
        np.array([r.time_s for r in records]))
    read = np.array([r.temperature_c for r in records])
    error = read - truth
    assert np.all(np.abs(error) <= tolerance + step / 2 + 1e-9)
    # One offset: the errors differ by the rounding alone.
    assert np.ptp(error) <= step + 1e-9
    np.testing.assert_allclose(read / step, np.round(read / step), atol=1e-6)
    exact, _ = _hour(Conditions("workshop", ("room", "stands")), True, budget_s=300.0)
    records = exact.unwrapped.records
    world = exact.unwrapped.true_world
    np.testing.assert_array_equal(
        [r.temperature_c for r in records],
        REFERENCE_C + world[np.zeros(len(records), int)].temperature(
            np.array([r.time_s for r in records])))


def test_the_thermometer_changes_nothing_else() -> None:
    """With the thermometer the lab draws what it draws without one (the offset comes from
    a jump of the stream): every observation and reading is the same number; without it
    the records carry no temperature, and the fit of the readings with the temperatures
    taken out is the fit without a thermometer, bit for bit."""
    off, seen_off = _hour("workshop", False, budget_s=900.0)
    on, seen_on = _hour("workshop", True, budget_s=900.0)
    assert len(seen_off) == len(seen_on)
    for a, b in zip(seen_off, seen_on, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    assert all(r.temperature_c is None for r in off.unwrapped.records)
    assert [replace(r, temperature_c=None) for r in on.unwrapped.records] == (
        off.unwrapped.records)
    bare = measurements_of(off.unwrapped.records, 900.0, design=PROTOTYPE)
    warm = measurements_of(on.unwrapped.records, 900.0, design=PROTOTYPE)
    stripped = Measurements([replace(m, temperature_c=None) for m in warm.items], 900.0)
    conditions = Conditions("workshop")
    sigma = off.unwrapped.noise.effective_sigma
    plain, again = (for_study("full", sigma, conditions).fit(d) for d in (bare, stripped))
    np.testing.assert_array_equal(plain.theta, again.theta)
    np.testing.assert_array_equal(plain.covariance, again.covariance)


def _growth_error(env: gym.Env, data: Measurements) -> float:
    """RMS (mm) over the gauge readings of the ``full`` fit's growth of the stands' arms
    minus the true growth, each centred within its mounting (whose zero takes a
    constant)."""
    lab = env.unwrapped
    design, values = layout_and_values(data)
    times = np.array([[m.time_s for m in data.items]])
    heat = [m.temperature_c for m in data.items]
    temperatures = None if None in heat else np.array([heat])
    terms = consider_terms(design, values[None], times, GROWTH, temperatures=temperatures)
    est = for_study("full", lab.noise.effective_sigma, GROWTH).fit(data)
    k = terms.drive.shape[-1]
    fitted = np.zeros(len(design))
    for j, name in enumerate(terms.names[k:]):
        if name.startswith("stands.thermal"):
            fitted += terms.reading[0, :, j] * est.theta[est.space.index(WORLD_PREFIX + name)]
    world = lab.true_world
    gauges = lab._batch.notebooks[0].installed
    stand = [list(gauges).index(name) for name in design.mountings]
    sign = np.array([gauges[name].sign for name in design.mountings])
    room = world[np.zeros(len(design), int)].temperature(times[0])
    true = (sign * world.thermal[0, stand])[design.mounting] * room
    miss = fitted - true
    for m in range(len(design.mountings)):
        mine = design.mounting == m
        miss[mine] -= miss[mine].mean()
    return float(np.sqrt(np.mean(miss**2)))


@pytest.mark.parametrize("seed", [3, 4])
def test_the_fit_against_the_thermometer_recovers_the_stands_growth_better(seed: int) -> None:
    """An hour of small moves in a shop whose room drifts 1 K/h and swings by 0.6 K with
    its heating: fitted against the thermometer, the arms' growth over the readings is
    within 0.1 um RMS of the truth, and at most a quarter as far off as the fit that sees
    the growth as linear in the clock.  The bounds: each arm's coefficient is known to
    about 0.08 um/K (its reported std) over a swing of about 1 K, and the thermometer's
    rounding adds 0.01 um; the clock's line cannot follow the swing, 0.6 K at 2-3.5 um/K,
    which leaves 0.4-0.6 um here.  (Under the drawn walk alone, 0.3 K per root hour, the
    room is nearly linear in the clock over an hour: 0.04 um against 0.04-0.2 um.)"""
    env, _ = _hour(GROWTH, True, seed=seed, swing=True)
    data = measurements_of(env.unwrapped.records, 3600.0, design=PROTOTYPE)
    clock = Measurements([replace(m, temperature_c=None) for m in data.items], 3600.0)
    with_thermometer, without = _growth_error(env, data), _growth_error(env, clock)
    assert with_thermometer < 1e-4
    assert with_thermometer < 0.25 * without


@pytest.mark.parametrize("cell,fragment", [
    ("293.15", "column 11 (temperature_c): must lie in [0, 50] C (a room's), got '293.15'"),
    ("warm", "column 11 (temperature_c): must be a number, got 'warm'"),
    ("nan", "column 11 (temperature_c): must be finite"),
])
def test_a_bad_temperature_in_a_sheet_is_one_line_and_exit_2(tmp_path, capsys, cell: str,
                                                              fragment: str) -> None:
    header = "mounting,leg,axis,at,posture,rho_x,rho_y,rho_z,repetition,reading_mm,temperature_c"
    rows = ["x-leg/y,x,y,0.5,Zero,0,0,0,1,0.0,20.1", f"x-leg/y,x,y,0.5,XMax,,,,1,0.1,{cell}"]
    path = tmp_path / "sheet.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    assert main(["fit", str(path)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and f"sheet.csv:3: {fragment}" in lines[0], lines
    assert "Traceback" not in captured.err and captured.out == ""


def test_a_sheets_temperatures_survive_both_formats(tmp_path) -> None:
    env, _ = _hour("lab", True, budget_s=300.0)
    data = measurements_of(env.unwrapped.records, 300.0, design=PROTOTYPE)
    for suffix in (".csv", ".json"):
        data.write(tmp_path / f"m{suffix}")
        back = Measurements.read(tmp_path / f"m{suffix}")
        assert [m.temperature_c for m in back.items] == [m.temperature_c for m in data.items]
    assert "temperature_c" in (tmp_path / "m.csv").read_text().splitlines()[0]


def test_a_world_saved_before_the_thermometer_replays_in_a_lab_lab() -> None:
    """A machine file written before the thermometer existed names every effect but it:
    its world was drawn the same way, so a ``lab`` lab replays it (one of other conditions
    still refuses it)."""
    env = gym.make(orthoglide_env.LAB_ENV_ID, conditions="lab")
    env.reset(seed=4)
    batch = env.unwrapped._batch
    world = batch.world[0]
    old = Conditions("lab", [e for e in world.conditions.effects if e != "thermometer"])
    saved = machine_dict(batch.machines[0], replace(world, conditions=old))
    env.reset(seed=5, options={"machine": saved})
    assert np.array_equal(batch.world[0].lead_scale, world.lead_scale)
    with pytest.raises(ValueError, match="drawn under the conditions"):
        gym.make(orthoglide_env.LAB_ENV_ID, conditions="workshop").reset(
            seed=5, options={"machine": saved})
