"""The real lab's world: each effect measured on the virtual machine against the size in
the conditions table, both backends agreeing with every effect on, and bad conditions
refused.  Gauges are ideal (no noise, no display step) so an effect is seen alone; each
check fails when its effect is off (the reference is the same machine in the ideal
world, which the world's draws do not change: they come after the machine's)."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from conftest import command_here

import orthoglide_env
from orthoglide_env.lab.operations import Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import EFFECT_NAMES, Conditions
from orthoglide_env.world.table import EFFECTS
from orthoglide_env.world.truth import WALK_HORIZON_S, World

UM = 1e-3
IDEAL_GAUGES = {"gauge_sigma": 0.0, "gauge_resolution": 0.0, "errors": "nominal"}


def lab(conditions: Conditions, **kwargs) -> gym.Env:
    return gym.make(orthoglide_env.LAB_ENV_ID, conditions=conditions, **IDEAL_GAUGES,
                    **kwargs).unwrapped


def move(env: gym.Env, rho) -> dict:
    obs, *_ = env.step({"op": int(Op.MOVE), "rho": np.asarray(rho, float), "stand": 0,
                        "slot": 0})
    return obs


def table_range(effect: str, parameter: str, condition: str) -> tuple[float, float]:
    return EFFECTS[effect][parameter].at(condition)


@pytest.mark.slow
@pytest.mark.parametrize("condition", ["lab", "workshop"])
def test_zero_readings_drift_over_an_hour_by_the_stands_and_the_room(condition: str) -> None:
    """A gauge's Zero reading after an hour of work minus the one at its mounting: its
    stand's arm grows with the room (table: 2-3.5 um/K along the measuring axis, the room
    drifting at 0.3 or 1 K/h) and its magnetic base settles (0-2 or 0-5 um).  The
    temperature is recomputed here from the drawn modes, and the measured drift must be
    that growth plus that settling."""
    conditions = Conditions(condition, ("room", "stands"))
    drifts = []
    for seed in range(6):
        # Room past the hour for the loop's last pair of moves: the lab refuses a move
        # that would end past its budget.
        env = lab(conditions, budget_s=3700.0)
        first = env.reset(seed=seed)[0]["gauges"].copy()
        while env._time < 3600:
            move(env, [0.5, 0, 0])
            last = move(env, [0, 0, 0])
        t1 = env._time
        world = env.true_world
        low, high = table_range("stands", "thermal", condition)
        assert np.all((low * UM <= np.abs(world.thermal)) & (np.abs(world.thermal) <= high * UM))
        rate = table_range("room", "drift", condition)[0]
        assert abs(world.rate[0]) * 3600 == pytest.approx(rate)
        k = np.arange(len(world.walk[0])) + 0.5
        walk = (world.walk[0] * np.sqrt(2) * np.sin(np.pi * k * t1 / WALK_HORIZON_S)
                / (np.pi * k)).sum()
        warmer = world.rate[0] * t1 + walk  # at the mounting (t = 0): the offset
        settled = world.creep[0] * (1 - np.exp(-t1 / world.creep_tau[0]))
        gauges = env.true_gauges
        sign = np.array([g.sign for g in gauges])
        # The structure grows too: the ray from the stand to the bar (mid-travel) with it.
        grown = 11.5e-6 * warmer * np.array([g.travel / 2 for g in gauges])
        expected = sign * (world.thermal[0] * warmer + settled + grown)
        assert last["gauges"] - first == pytest.approx(expected, abs=1e-4 * UM)
        drifts.append(np.abs(last["gauges"] - first))
    assert np.median(drifts) > 0.2 * UM


@pytest.mark.parametrize("condition", ["lab", "workshop"])
def test_the_same_posture_from_two_sides_gives_two_tcps(condition: str) -> None:
    """Zero approached from below and from above: at Zero the TCP follows the carriages one
    to one, so the two TCPs differ by each axis's lost motion, within the table's range."""
    env = lab(Conditions(condition, ("backlash",)))
    env.reset(seed=4)
    move(env, [-5, -5, -5])
    move(env, [0, 0, 0])
    below = env.tcp()
    move(env, [5, 5, 5])
    move(env, [0, 0, 0])
    above = env.tcp()
    backlash = env.true_world.backlash[0]
    low, high = table_range("backlash", "lost_motion", condition)
    assert np.all((low * UM <= backlash) & (backlash <= high * UM))
    assert above - below == pytest.approx(backlash, abs=1e-6 * UM)
    assert np.linalg.norm(above - below) > 0.1 * UM


@pytest.mark.parametrize("condition", ["lab", "workshop"])
def test_a_plunger_driven_out_and_back_gives_two_readings(condition: str) -> None:
    """The same posture read after the plunger came in and after it came out: the two
    readings of every gauge differ by its indicator's retrace (table: up to 2 or 3 um),
    the rest of its error curve being the same at the same depth."""
    env = lab(Conditions(condition, ("dial",)))
    env.reset(seed=5)
    move(env, [0, 8, 8])
    one = move(env, [0, 5, 5])["gauges"]
    move(env, [0, 2, 2])
    other = move(env, [0, 5, 5])["gauges"]
    retrace = env.true_world.retrace[0]
    assert np.all(retrace <= table_range("dial", "retrace", condition)[1] * UM)
    # The x-leg gauges' plungers did not move (the x-leg does not tilt in y or z here).
    moved = np.abs(one - other) > 1e-9
    assert moved.sum() >= 4
    assert np.abs(one - other)[moved] == pytest.approx(retrace[moved], abs=1e-6 * UM)


def test_gravity_and_the_gauges_force_deflect_the_tcp() -> None:
    """The platform's weight (table: 30 N along -z) on drives of 0.03 um/N: at Zero, where
    the TCP follows each carriage one to one, it sinks by 0.9 um, plus what the six
    indicators' forces add (about 0.5 N each passed to the platform); elsewhere the
    deflection changes with the posture."""
    conditions = Conditions("lab", ("compliance",))
    deflected, straight = lab(conditions), lab(Conditions("ideal"))
    deflected.reset(seed=6), straight.reset(seed=6)
    sag = deflected.tcp() - straight.tcp()
    weight = EFFECTS["compliance"]["weight"].lab[0]
    compliance = EFFECTS["compliance"]["actuator"].lab[0] * UM
    assert sag[2] == pytest.approx(-weight * compliance, abs=0.05 * UM)
    assert np.linalg.norm(sag) < 1.1 * weight * compliance
    far = [40.0, -80.0, 40.0]
    move(deflected, far), move(straight, far)
    assert np.linalg.norm(deflected.tcp() - straight.tcp() - sag) > 0.05 * UM


def test_an_indicator_bends_its_bar_by_the_beam_formula() -> None:
    """A bar pinned at its hinges bends under the indicator's force: at mid-span by
    F L^3 / (48 E I) (12 x 12 mm steel, 210 GPa: 2.6 um under 1.5 N, the "about 3 um" of
    a 310 mm tube), and the force rises from 0.6 N (plunger out) to 1.5 N (fully in)."""
    world = World.draw(Conditions("lab", ("compliance",)), np.random.default_rng(0), 1)
    travel = np.array([[10.0]])
    out, pushed = (world.distance_offsets(np.array([[t]]), np.ones((1, 1)), np.zeros(1),
                                          np.array([[0.5]]), np.array([[True]]), travel,
                                          PROTOTYPE) for t in (10.0, 0.0))
    inertia = 12.0**4 / 12
    per_newton = PROTOTYPE.L**3 / (48 * 210e3 * inertia)
    assert out[0, 0] == pytest.approx(0.6 * per_newton, rel=1e-12)
    assert pushed[0, 0] == pytest.approx(1.5 * per_newton, rel=1e-12)
    assert 2 * UM < 1.5 * per_newton < 3.5 * UM


def test_lead_error_stays_within_the_screw_grade() -> None:
    """Over many machines the drawn lead error meets ISO 3408-3 for the condition's grade:
    the deviation at the stroke's end (the linear part) within e_p (C3 12, C5 23 um), and
    the whole curve within e_p + v_300/2 + v_2pi/2 of the commanded position."""
    rho = np.linspace(PROTOTYPE.rho_min, PROTOTYPE.rho_max, 321)[:, None].repeat(3, axis=1)
    for condition, bound in (("lab", 12 + 4 + 3), ("workshop", 23 + 9 + 4)):
        stream = np.random.default_rng(1)
        worlds = World.stack([World.draw(Conditions(condition, ("lead",)), stream, 6)
                              for _ in range(200)])
        error = worlds.lead_error(np.broadcast_to(rho, (200, *rho.shape)), PROTOTYPE)
        assert np.abs(worlds.lead_scale).max() <= table_range("lead", "scale", condition)[1] * UM
        assert np.abs(error).max() <= bound * UM
        assert np.abs(error).max() > 0.5 * bound * UM  # sized like the grade, not smaller


@pytest.mark.slow
def test_both_backends_agree_with_every_effect_on() -> None:
    """With every workshop effect on, PyBullet and the exact model read the same gauges
    and put the TCP at the same place within 1 um, step by step (they share the world's
    maps; what they compute apart is the geometry at the carriages' positions)."""
    envs = [gym.make(orthoglide_env.ENV_ID, backend=b, conditions="workshop",
                     **IDEAL_GAUGES).unwrapped for b in ("exact", "pybullet")]
    try:
        obs = [env.reset(seed=9)[0] for env in envs]
        rng = np.random.default_rng(0)
        for _ in range(12):
            rho = rng.uniform(-4, 4, 3)
            obs = [env.step(rho)[0] for env in envs]
            both = (obs[0]["valid"] == 1) & (obs[1]["valid"] == 1)
            assert both.sum() >= 4
            assert np.abs(obs[0]["gauges"] - obs[1]["gauges"])[both].max() < 1 * UM
            assert np.abs(envs[0].tcp() - envs[1].tcp()).max() < 1 * UM
            assert np.abs(obs[0]["joints"] - obs[1]["joints"]).max() < 1 * UM
            assert obs[0]["joints"] == pytest.approx(rho, abs=1e-9)  # the encoders read the command
    finally:
        for env in envs:
            env.close()


@pytest.mark.parametrize("value, words", [
    ("indoors", "unknown conditions 'indoors'"),
    (3, "conditions must be one of"),
    ({"name": "lab", "effects": ["lead", "rust"]}, "unknown effect(s) ['rust']"),
    ({"name": "lab", "effects": "lead"}, "effects must be a list"),
    ({"name": "ideal", "effects": ["lead"]}, "the ideal conditions have no effects"),
    ({"name": "lab", "colour": 1}, "unknown conditions key(s) ['colour']"),
])
@pytest.mark.parametrize("env_id", [orthoglide_env.LAB_ENV_ID, orthoglide_env.ENV_ID])
def test_bad_conditions_are_refused_by_both_envs(env_id: str, value, words: str) -> None:
    with pytest.raises(ValueError, match="conditions: ") as info:
        gym.make(env_id, conditions=value, backend="exact")
    assert words in str(info.value)


#: Bad conditions of ``calibrate`` and the words of their refusal.
BAD_CONDITIONS = [
    (["--conditions", "indoors"], "invalid choice: 'indoors'"),
    (["--conditions", "lab", "--effects", "lead,rust"], "unknown effect(s) ['rust']"),
    (["--conditions", "ideal", "--effects", "lead"], "the ideal conditions have no effects"),
]


@pytest.mark.parametrize("args, words", BAD_CONDITIONS)
def test_bad_conditions_exit_2_with_one_line(args: list[str], words: str) -> None:
    """The first refusal as the command's child process, the others in this process
    (``command_here``)."""
    result = (subprocess.run([sys.executable, "-m", "calibrators.cli", "calibrate", *args],
                             capture_output=True, text=True, timeout=120)
              if args == BAD_CONDITIONS[0][0] else command_here(["calibrate", *args]))
    assert result.returncode == 2
    assert words in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_the_docs_show_the_conditions_table() -> None:
    """docs/conditions.md's table is the module's, row for row (one source for every
    size)."""
    from pathlib import Path

    from calibrators.cli.conditions import table

    page = (Path(__file__).parents[1] / "docs" / "conditions.md").read_text()
    assert table() in page


def _episode(options: dict | None, seed: int) -> tuple[list[np.ndarray], gym.Env]:
    """Readings and TCPs of a fixed tour (no remounting) in a lab with ideal gauges."""
    env = lab(Conditions("workshop"), backend="exact")
    env.reset(seed=seed, options=options)
    seen = []
    for rho in ([10, 0, 0], [0, -20, 5], [30, 30, -30], [0, 0, 0]):
        obs = move(env, rho)
        seen += [obs["gauges"].copy(), env.tcp()]
    return seen, env


def test_a_machine_file_replays_its_world() -> None:
    """A truth written to a machine file (through JSON) and given back replays its world:
    the same readings and TCPs to the last bit, though the stream (another seed) would
    draw another world; without the file's world the readings differ by um."""
    import json

    from orthoglide_env.world.machine_file import machine_dict

    drawn, env = _episode(None, 5)
    truth = json.loads(json.dumps(machine_dict(env.true_machine, env.true_world)))
    replayed, again = _episode({"machine": truth}, 99)
    assert all(np.array_equal(a, b) for a, b in zip(drawn, replayed, strict=True))
    assert again.true_world.to_dict() == truth["world"]
    other, _ = _episode({"machine": {k: v for k, v in truth.items() if k != "world"}}, 99)
    assert max(np.abs(a - b).max() for a, b in zip(drawn[1::2], other[1::2], strict=True)) > 1 * UM


@pytest.mark.parametrize("change, words", [
    (lambda w: w.update(backlash=[0.0, 0.0, 1.0]), "backlash = 1000 um exceeds the workshop"),
    (lambda w: w.update(warm_tau=[1.0, 1.0, 1.0]), "warm_tau below the workshop"),
    (lambda w: w.update(conditions={"name": "workshop", "effects": ["lead"]}),
     "exceeds zero: backlash is off in workshop[lead]"),
    (lambda w: w.pop("room" if "room" in w else "rate"), "missing ['rate']"),
    (lambda w: w.update(lead_scale="x"), "world: lead_scale must hold numbers"),
    (lambda w: w.update(backlash=[True, 0.0, 0.0]), "world: backlash must hold numbers"),
    (lambda w: w.update(conditions={"name": "workshop", "effects": [
        e for e in EFFECT_NAMES if e != "room"]}, rate=0.0, offset=0.0),
     "walk must be zero: room is off"),
])
def test_a_bad_world_in_a_machine_file_is_refused(change, words: str) -> None:
    """A world outside the table's sizes, drawn under other conditions, or missing a key is
    refused with ``ValueError`` naming it; nothing is clipped."""
    from orthoglide_env.world.machine_file import machine_dict

    _, env = _episode(None, 5)
    truth = machine_dict(env.true_machine, env.true_world)
    change(truth["world"])
    fresh = lab(Conditions("workshop"), backend="exact")
    with pytest.raises(ValueError, match="reset option 'machine'") as info:
        fresh.reset(seed=0, options={"machine": truth})
    assert words in str(info.value)


@pytest.mark.slow
def test_calibrate_writes_a_truth_that_replays(tmp_path) -> None:
    """``calibrate --save-truth`` writes the machine and its world; ``--machine FILE``
    replays it under the file's conditions (left out on the command line), and refuses
    other ones with exit 2."""
    import json

    # The file is written and refused in this process (``command_here``); it is replayed
    # once by a command started as a user starts it and once here, the same estimate.
    truth = tmp_path / "truth.json"
    base = ["calibrate", "--backend", "exact", "--budget", "600", "--json"]
    first = command_here([*base, "--conditions", "lab", "--save-truth", str(truth)])
    assert first.returncode == 0, first.stderr
    written = json.loads(truth.read_text())
    assert written["world"]["conditions"]["name"] == "lab"
    assert json.loads(first.stdout)["truth"] == written
    replay = [*base, "--machine", str(truth)]
    runs = [subprocess.run([sys.executable, "-m", "calibrators.cli", *replay],
                           capture_output=True, text=True, timeout=300), command_here(replay)]
    assert all(run.returncode == 0 for run in runs), [run.stderr for run in runs]
    runs = [json.loads(run.stdout) for run in runs]
    assert runs[0]["truth"] == written
    assert runs[0]["estimate"] == runs[1]["estimate"]
    refused = command_here([*replay, "--conditions", "workshop"])
    assert refused.returncode == 2 and "drawn under lab" in refused.stderr


def test_a_world_of_other_conditions_is_refused() -> None:
    from orthoglide_env.world.machine_file import machine_dict

    env = lab(Conditions("lab"), backend="exact")
    env.reset(seed=1)
    truth = machine_dict(env.true_machine, env.true_world)
    with pytest.raises(ValueError, match="drawn under the conditions 'lab'; this lab's are "
                                         "'workshop'"):
        lab(Conditions("workshop"), backend="exact").reset(seed=0, options={"machine": truth})


@pytest.mark.parametrize("indicator", ["dial", "digital"])
def test_a_digital_indicator_scatters_at_its_strokes_ends(indicator: str) -> None:
    """Noise-free gauges, the indicators' effect alone: a posture read 40 times from the
    same side repeats (to round-off), except on a digital indicator whose tip is within
    the table's end band (0.2 mm) of its stroke's end, which scatters by the table's sigma
    (3 um in the lab; the sample std of 40 is within 25 % of it at 3.5 sigma)."""
    conditions = Conditions("lab", ("dial",), indicator)
    env = lab(conditions, backend="exact")
    env.reset(seed=3)
    seen = []
    for _ in range(40):
        seen.append(move(env, [10.0, 0.0, 0.0])["gauges"].copy())
        move(env, [0.0, 0.0, 0.0])
    seen = np.array(seen)
    half = env.travel / 2
    band = EFFECTS["dial"]["digital_end"].lab[0]
    at_end = np.abs(seen[0]) > half - band
    assert at_end.any() and not at_end.all()  # the posture puts one plunger in the band
    spread = seen.std(axis=0, ddof=1)
    assert np.all(spread[~at_end] < 1e-9)  # round-off of the repeated sums
    sigma = EFFECTS["dial"]["digital_end_sigma"].lab[0] * UM
    if indicator == "digital":
        assert np.all(np.abs(spread[at_end] / sigma - 1) < 0.25)
    else:
        assert np.all(spread[at_end] < 1e-9)


def test_a_digital_indicators_error_curve_has_its_own_size() -> None:
    """Its error over the travel stays within the digital row (3 um peak-to-peak) and it
    has no revolution error; an unknown indicator, or one without the dial effect, is
    refused."""
    stream = np.random.default_rng(0)
    world = World.draw(Conditions("workshop", indicator="digital"), stream, 200)
    assert np.all(world.dial_revolution == 0.0)
    high = EFFECTS["dial"]["digital_range"].workshop[1] * UM / 2
    assert world.dial_range.max() <= high and world.dial_range.max() > 0.8 * high
    with pytest.raises(ValueError, match="unknown indicator 'laser'"):
        Conditions("lab", indicator="laser")
    with pytest.raises(ValueError, match="errors are the dial effect's"):
        Conditions("lab", ("lead",), "digital")
