"""The step gauge in the lab (``OrthoglideLab-v3``): what it reads of the machine, that both
backends and every face of the lab agree on it, its refusals, its readings' rows in the
``full`` fit (the lead error's pitch table recovered), ``active``'s refits of a notebook with
its readings, its rows in a reading file, and the ``step-gauge`` agent's needs."""

from __future__ import annotations

import itertools
import re
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import (
    assert_batch_reads_as_alone,
    assert_refused_in_one_line,
    command_here,
    refit_misfit,
)
from scipy.stats import chi2

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.agents.base import PlannedAgent, action
from calibrators.agents.step_gauge import (
    MAX_RUNS,
    face_command,
    gauge_steps,
    least_budget_s,
    programme_seconds,
    runs_for,
)
from calibrators.estimators.catalogue import get_estimator
from calibrators.measurements import Measurements
from calibrators.study.episodes import machine_seed, measurements_of, run_episode
from calibrators.study.labs import lab_kwargs
from orthoglide_env.instruments import step_gauge
from orthoglide_env.instruments.step_gauge import StepGaugeSpec
from orthoglide_env.lab.operations import PAPER_SLOTS, TIME, V2_OPS, Op
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import direct
from orthoglide_env.reading_model import ReadingLayout, jacobian, predict
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import STEP_GAUGE_FACES, STEP_GAUGE_PITCH_MM

V3 = orthoglide_env.LAB_V3_ENV_ID
OWNED = ["dial", "step-gauge"]
#: One run along an axis: face 0 at the set-up, up through every face, down again.
FACES = [0, *range(1, STEP_GAUGE_FACES), *range(STEP_GAUGE_FACES - 2, -1, -1)]


def _run(env: gym.Env, axis: int, seed: int = 3) -> tuple[list[dict], list[np.ndarray]]:
    """Lift the stands, lay the gauge along ``axis`` and read :data:`FACES`: every
    observation from the set-up on, and the TCP the machine truly reached at each (its
    geometry at the carriages, before the room grows it: the lab takes it to 20 C)."""
    obs, _ = env.reset(seed=seed)
    for k in range(len(obs["slot"])):
        env.step(action(Op.LIFT, stand=k))
    batch = env.unwrapped._batch
    seen, tcp = [], []
    for n, face in enumerate(FACES):
        rho = face_command(PROTOTYPE, axis, face)
        step = action(Op.PLACE, rho, axis=axis) if n == 0 else action(Op.MOVE, rho)
        seen.append(env.step(step)[0])
        tcp.append(batch.tcp[0].copy())
    return seen, tcp


def _readings(seen: list[dict]) -> np.ndarray:
    return np.array([o["step_gauge"][0] for o in seen])


def test_v2_keeps_its_spaces_and_refuses_the_step_gauge():
    env = gym.make(orthoglide_env.LAB_V2_ENV_ID, backend="exact", conditions="ideal")
    assert env.action_space["op"].n == V2_OPS == 7
    assert not any(k.startswith("step_gauge") for k in env.observation_space.spaces)
    with pytest.raises(ValueError, match="OrthoglideLab-v3"):
        gym.make(orthoglide_env.LAB_V2_ENV_ID, backend="exact", instruments=OWNED)
    v3 = gym.make(V3, backend="exact", conditions="ideal")
    assert v3.action_space["op"].n == len(Op) == 8
    v3.reset(seed=0)
    *_, info = v3.step(action(Op.PLACE, face_command(PROTOTYPE, 0, 0), axis=0))
    assert "no step gauge" in info["refused"]
    assert info["step_time_s"] == TIME.lift_s


@pytest.mark.parametrize(("names", "words"), [
    (["dial", "step_gauge"], "unknown instrument"), (["step-gauge"], "include 'dial'")])
def test_bad_instruments_are_refused_in_one_line(names, words):
    with pytest.raises(ValueError, match=words) as info:
        gym.make(V3, backend="exact", conditions="ideal", instruments=names)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("conditions", ["ideal", "lab"])
def test_a_reading_is_the_tcp_s_displacement_less_the_face_s(conditions: str):
    """At every face a reading is the true TCP's displacement along the gauge from face 0
    less the face's nominal distance, within the gauge's stated error: the probe's
    scatter and rounding, and under ``lab`` each face's calibration (U / 2), the scale
    error (U / 2 per length), the cosine error of up to 1 mrad and the two
    coefficients' difference over the room's offset (0.01 um): at most 0.3 um at one
    standard deviation over the 160 mm.  5 of those bound 17 readings (p < 1e-4 each)."""
    env = gym.make(V3, errors="realistic", backend="exact", conditions=conditions,
                   instruments=OWNED)
    axis = 1
    seen, tcp = _run(env, axis)
    values = _readings(seen)
    truth = np.array([t[axis] - tcp[0][axis] - STEP_GAUGE_PITCH_MM * f
                      for t, f in zip(tcp, FACES, strict=True)])
    assert all(o["step_gauge_valid"][0] == 1 and o["step_gauge_in"][0] == 1 for o in seen)
    sigma = step_gauge.sigma(Conditions(conditions))
    if conditions == "lab":
        sigma = float(np.hypot(sigma, 0.1e-3 + 0.25e-6 * 160 + 0.5e-6 * 160))
    assert np.max(np.abs(values - truth)) < 5 * sigma
    # The test can tell: the machine's own positioning error is far beyond that.
    assert np.max(np.abs(truth)) > 20 * sigma


def test_both_backends_read_the_same():
    """The probe reads the TCP: the PyBullet machine and the exact model put it within
    the workbench's 1 um of each other (the same draws, so only their TCPs differ)."""
    readings = [_readings(_run(gym.make(V3, errors="realistic", backend=backend,
                                        conditions="lab", instruments=OWNED), axis=0)[0])
                for backend in ("exact", "pybullet")]
    assert np.max(np.abs(readings[0] - readings[1])) <= 1e-3


def test_a_batch_reads_what_separate_labs_read():
    batched = assert_batch_reads_as_alone(
        V3, gauge_steps(6, PROTOTYPE, 1)[:30], {"axis": 0},
        ("step_gauge", "step_gauge_valid", "step_gauge_in", "gauges", "time"),
        errors="realistic", conditions="lab", instruments=OWNED, thermometer=True)
    assert batched["step_gauge_valid"].all()


def test_a_move_off_the_faces_is_refused_before_anything_changes():
    env = gym.make(V3, errors="realistic", backend="exact", conditions="lab",
                   instruments=OWNED)
    _run(env, axis=2)
    lab = env.unwrapped
    before = (float(lab._batch.time[0]), len(lab.records))
    between = face_command(PROTOTYPE, 2, 3) + np.array([0.0, 0.0, 7.0])
    for rho, words in ((face_command(PROTOTYPE, 2, 0)[[1, 2, 0]], "off the gauge's line"),
                       (between, "outside the probe's range")):
        with pytest.raises(ValueError, match=re.escape(words)) as info:
            env.step(action(Op.MOVE, rho))
        assert "\n" not in str(info.value)
    assert (float(lab._batch.time[0]), len(lab.records)) == before
    # Any operation but a move takes the probe off; then a move anywhere is a move.
    env.step(action(Op.LIFT, stand=0))
    obs, *_ = env.step(action(Op.MOVE, np.zeros(3)))
    assert obs["step_gauge_in"][0] == 0 and obs["step_gauge_valid"][0] == 0
    # A gauge laid with face 0 mid-stroke has no face behind it.
    env.step(action(Op.PLACE, face_command(PROTOTYPE, 2, 3), axis=2))
    with pytest.raises(ValueError, match="outside its faces"):
        env.step(action(Op.MOVE, face_command(PROTOTYPE, 2, 2)))


def test_check_env_is_clean_with_the_step_gauge():
    import warnings

    from gymnasium.utils.env_checker import check_env
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(V3, backend="exact", conditions="lab",
                           instruments=OWNED).unwrapped, skip_render_check=True)
    # The one warning left, as for v0 to v2: joint targets are in mm, not a normalised box
    # (besides Gymnasium's note that v4, the lab whose moves may leave the laser unread,
    # exists).
    messages = {str(w.message) for w in caught if "is out of date" not in str(w.message)}
    assert all("symmetric and normalized" in m for m in messages), messages


def test_the_model_row_is_the_tcp_along_the_axis():
    """A row's model is the TCP's coordinate along the gauge less the face's distance
    (its set-up's zero takes face 0's place); its derivatives are the model's finite
    differences."""
    spec = StepGaugeSpec(0, tuple(face_command(PROTOTYPE, 0, 0)))
    rho = np.array([face_command(PROTOTYPE, 0, f) for f in (0, 3, 8)])
    layout = ReadingLayout.of(["step-gauge#1"] * 3, [spec] * 3, rho, PROTOTYPE)
    n = len(layout.space)
    truth = np.random.default_rng(0).normal(0.0, 0.05, n)
    machine = MachineParams.from_vector(truth[None, :27], PROTOTYPE)
    expected = direct(machine, rho[None])[0, :, 0] - STEP_GAUGE_PITCH_MM * np.array([0, 3, 8])
    np.testing.assert_allclose(predict(truth, layout), expected, atol=1e-12)
    analytic = jacobian(truth, layout, np.ones(n, bool), np.ones(n))
    numeric = np.zeros_like(analytic)
    for k in range(n):
        e = np.zeros(n)
        e[k] = 1e-6
        numeric[:, k] = (predict(truth + e, layout) - predict(truth - e, layout)) / 2e-6
    # Central differences of a model smooth on the legs' scale: error ~1e-9 of the largest.
    assert np.max(np.abs(analytic - numeric)) <= 1e-6 * np.max(np.abs(numeric))


class GaugeOnly(PlannedAgent):
    """The ``step-gauge`` procedure's gauge, ``RUNS`` runs on each axis, and nothing
    else."""

    name = "step-gauge-only"
    RUNS = 2

    def make_plan(self, observation: dict) -> list[dict]:
        return [*gauge_steps(len(observation["slot"]), self.env.design, self.RUNS),
                action(Op.STOP)]


def _episode(conditions: Conditions, seed: int = 0):
    """The gauge alone on a machine of nominal geometry: along a line a realistic
    machine's geometry (errors of a millimetre) moves the TCP by tens of micrometres as
    smoothly as the lead error does, which the gauges' experiment tells apart (the
    agent's second half), not the gauge."""
    env = gym.make(V3, backend="exact", conditions=conditions, errors="nominal",
                   instruments=OWNED)
    return run_episode(env, GaugeOnly(), machine_seed(1, seed))


def _true_table(episode, nodes: np.ndarray) -> np.ndarray:
    """The world's smooth lead error at the pitch table's nodes (3, nodes), 0 at the
    reference: the table's part (its periodic part is the screw's, apart)."""
    world = episode.world
    x = (nodes - PROTOTYPE.rho_min) / (PROTOTYPE.rho_max - PROTOTYPE.rho_min)
    return (world.lead_scale[0][:, None] * x + world.lead_a1[0][:, None] * np.sin(np.pi * x)
            + world.lead_a2[0][:, None] * np.sin(2 * np.pi * x))


def _exact_readings(episode) -> Measurements:
    """The episode's readings as the model says they are at the truth, without any noise
    or instrument error: the dial gauges' as read less their noise is not at hand, so the
    step gauge's readings alone, each the true TCP at the carriages the lead error moved,
    along the gauge, less the face's distance and face 0's."""
    data = episode.measurements
    items = [m for m in data.items if isinstance(m.gauge, StepGaugeSpec)]
    truth, world = episode.truth, episode.world
    rho = np.array([m.rho for m in items])
    carriage = rho + world.lead_error(rho[None], PROTOTYPE)[0]
    tcp = direct(truth, carriage)
    out, first = [], {}
    for m, point in zip(items, tcp, strict=True):
        along = point[m.gauge.axis]
        face = int(step_gauge.faces_of(PROTOTYPE, m.gauge, np.asarray(m.rho))[0])
        zero = first.setdefault(m.mounting, along)
        out.append(m.again(along - zero - STEP_GAUGE_PITCH_MM * face, m.repetition, m.time_s))
    return replace(data, items=out)


@pytest.mark.parametrize("noisy", [False, True])
def test_the_full_fit_recovers_the_pitch_table_within_its_error_bars(noisy: bool):
    """Under the lead error alone, the step gauge's readings give the pitch table: at
    every node the fitted value is within 4 of its reported standard deviations (plus
    0.05 um for the table's linear interpolation between nodes of a smooth curve) of the
    true smooth lead error there (the table is 0 at its reference node, the stroke's back
    end, where face 0 lies).  Noise-free: the model's readings at the truth; noisy: the
    lab's, with the probe's scatter and the gauge's own errors (see :func:`_episode` for
    the machine)."""
    conditions = Conditions("lab", ("lead",))
    episode = _episode(conditions)
    data = episode.measurements if noisy else _exact_readings(episode)
    est = get_estimator("full", sigma=episode.sigma, conditions=conditions,
                        verify=False).fit(data)
    table = est.pitch_table
    truth = _true_table(episode, table.nodes)
    assert np.all(np.abs(table.values - truth) <= 4 * table.sigma + 5e-5)
    # Told apart from its prior (7.7 um at the far node): known to about a micrometre.
    assert np.median(table.sigma[:, 1:]) < 1.5e-3


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_active_refits_the_gauge_s_readings_under_lab_with_the_drives_terms(seed: int):
    """The probe reads the TCP along the gauge to 0.2 um, where the drives' lead, lost
    motion and warm-up move it by microns.  After one run along each axis (51 readings)
    and 384 dial readings, ``active``'s refit told an ideal world either misfits the
    gauge's readings by more than twice their sigma or does not converge at all (a refit
    that fails is skipped: on machines 1 and 3 of these three); told the lab, whose world
    the refits of such a notebook are told, it leaves none out and fits them to their
    scatter on every machine (the chi-square's 99.9 % quantile over 51 honest readings
    bounds their RMS at 1.31 sigma; the fit's degrees of freedom only lower it)."""
    from calibrators.agents.active import refit_world
    lab = Conditions("lab")
    env = gym.make(V3, errors="realistic", backend="exact", conditions=lab, instruments=OWNED)
    obs, _ = env.reset(seed=seed)
    for step in gauge_steps(len(obs["slot"]), PROTOTYPE, 1):
        assert not env.step(step)[4].get("refused")
    for offset in itertools.product((-3.0, -1.0, 1.0, 3.0), repeat=3):
        assert not env.step(action(Op.MOVE, np.array(offset)))[4].get("refused")
    records = env.unwrapped.records
    assert refit_world(lab, records) == lab
    data = measurements_of(records, design=PROTOTYPE)
    faces = np.flatnonzero([isinstance(m.gauge, StepGaugeSpec) for m in data.items])
    assert len(faces) == 51
    sigma_um = step_gauge.sigma(lab) * 1e3

    try:
        misfit = refit_misfit(data, StepGaugeSpec, None, "step-gauge")[1] > 2 * sigma_um
    except RuntimeError as error:
        misfit = "did not converge" in str(error)
    assert misfit
    left_out, rms_um, _ = refit_misfit(data, StepGaugeSpec, lab, "step-gauge")
    assert left_out == 0 and rms_um < np.sqrt(chi2.ppf(0.999, 51) / 51) * sigma_um


def test_the_agent_plans_the_gauge_along_each_axis_and_needs_it():
    agent = get_agent("step-gauge")
    with pytest.raises(ValueError, match="needs the step-gauge"):
        lab_kwargs(agent, ("dial",))
    assert lab_kwargs(agent, tuple(OWNED))["instruments"] == OWNED
    stands = len(PAPER_SLOTS)
    assert runs_for(3 * 3600.0, PROTOTYPE, stands) == 5
    assert runs_for(3600.0, PROTOTYPE, stands) == 2
    steps = gauge_steps(6, PROTOTYPE, 1)
    places = [s for s in steps if s["op"] == Op.PLACE]
    assert [s["axis"] for s in places] == [0, 1, 2]
    # Every face is read both ways in a run: 1 + 2 (faces - 1) readings per axis; then the
    # way back to Zero and the gauges' zeros read there.
    assert sum(s["op"] == Op.MOVE for s in steps) == 3 * 2 * (STEP_GAUGE_FACES - 1) + 2


def test_the_runs_are_the_most_whose_programme_leaves_the_gauges_half():
    """The run count is timed by the programme the lab charges: the most runs whose
    programme leaves :data:`~calibrators.agents.step_gauge.GAUGE_SHARE` of the budget, on
    a grid from ten minutes to four hours.  The count steps up at each
    ``programme_seconds(runs) / (1 - GAUGE_SHARE)``: 3500.7, 4268.7, 5036.7 and 5804.7 s
    on the prototype, 86.7 s later than the sum of set-ups and runs the count took before
    (it left out the lifts, the drive to the first set-up, the way back to Zero, the
    engagements and the zeros' reading: 43.3 s of programme), so budgets in those 87 s
    windows take one run fewer; an hour (two runs) and three hours (five) keep theirs."""
    stands = len(PAPER_SLOTS)
    seconds = {runs: programme_seconds(PROTOTYPE, stands, runs)
               for runs in range(1, MAX_RUNS + 1)}
    for budget in np.arange(600.0, 4 * 3600.0, 50.0):
        runs, room = runs_for(budget, PROTOTYPE, stands), 0.5 * budget
        assert runs == 1 or seconds[runs] <= room
        assert runs == MAX_RUNS or seconds[runs + 1] > room
    # The first window: two runs by the former sum from 3414.0 s, by the clock from 3500.7 s.
    assert runs_for(3450.0, PROTOTYPE, stands) == 1
    assert runs_for(3501.0, PROTOTYPE, stands) == 2


def test_the_programme_takes_the_time_the_lab_charges():
    """The programme's clock is the lab's: a lab that plays the gauge's runs and stops
    ends at :func:`~calibrators.agents.step_gauge.programme_seconds` of them (one source,
    the time table, for the agent's run count and the lab's charge)."""
    episode = _episode(Conditions("ideal"))
    assert episode.time_s == pytest.approx(
        programme_seconds(PROTOTYPE, len(PAPER_SLOTS), GaugeOnly.RUNS), rel=1e-12)


def test_a_budget_shorter_than_one_run_along_each_axis_is_refused(capsys):
    """Below the programme with one run per axis the procedure is refused before the lab
    starts, as ``iso230-2`` refuses its own: in the API's lab arguments, at the agent's
    reset in a lab made without them, and by ``compare`` in one line with exit 2.  From
    the least budget up it is accepted."""
    from calibrators.cli import main
    agent = get_agent("step-gauge")
    least = least_budget_s(PROTOTYPE, len(PAPER_SLOTS))
    # Three set-ups and three runs of the paper's 6 stands: about 23 minutes.
    assert least == pytest.approx(1366.3, abs=0.05)
    words = f"needs a budget of at least {least:.1f} s"
    with pytest.raises(ValueError, match=words):
        lab_kwargs(agent, tuple(OWNED), budget_s=least - 1.0)
    lab_kwargs(agent, tuple(OWNED), budget_s=least)
    env = gym.make(V3, backend="exact", conditions="lab", instruments=OWNED, budget_s=900.0)
    observation, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match=words):
        agent.reset(env, observation, np.random.default_rng(0))
    assert main(["compare", "--agents", "step-gauge,active", "--instruments",
                 "dial,step-gauge", "--budget", "900", "--machines", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err


def _file(tmp_path: Path, *rows: str) -> Path:
    path = tmp_path / "readings.csv"
    header = ("mounting,leg,axis,at,rho_x,rho_y,rho_z,repetition,reading_mm,instrument,"
              "start_x,start_y,start_z,face")
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


START = ",".join(repr(float(v)) for v in face_command(PROTOTYPE, 0, 0))
AT_2 = ",".join(repr(float(v)) for v in face_command(PROTOTYPE, 0, 2))


def test_a_reading_file_keeps_the_set_up(tmp_path: Path):
    data = Measurements.read(_file(tmp_path, f"g#1,,x,,{AT_2},1,0.0123,step-gauge,{START},2"))
    assert data.items[0].gauge == StepGaugeSpec(0, tuple(face_command(PROTOTYPE, 0, 0)))
    data.write(tmp_path / "back.csv")
    assert Measurements.read(tmp_path / "back.csv").items == data.items
    data.write(tmp_path / "back.json")
    assert Measurements.read(tmp_path / "back.json").items == data.items


#: Bad rows and the words of their refusal.
BAD_ROWS = [
    (f"g#1,,x,,{AT_2},1,0.0123,step-gauge,{START},9", "an integer 0..8"),
    (f"g#1,,x,,{AT_2},1,0.0123,step-gauge,{START},3", "at face 2, not 3"),
    (f"g#1,,x,,{AT_2.replace('-60.0', '-61.0', 1)},1,0.0123,step-gauge,{START},",
     "outside the probe's range"),
    (f"g#1,,x,,{AT_2},1,0.0123,step-gauge,,-13.3,-13.3,", "(start_x): empty"),
    (f"g#1,,,,{AT_2},1,0.0123,step-gauge,{START},", "(axis): empty"),
    (f"g#1,,x,,{AT_2},1,0.9,step-gauge,{START},", "probe reads within its range"),
    (f"g#1,x,y,,{AT_2},1,0.01,dial,{START},", "only a step-gauge reading")]


@pytest.mark.parametrize(("row", "words"), BAD_ROWS)
def test_a_bad_step_gauge_row_is_refused_in_one_line(tmp_path: Path, row: str, words: str):
    # The first row's refusal is the command's as a child; the others run in this process.
    assert_refused_in_one_line(_file(tmp_path, row), words, child=(row, words) == BAD_ROWS[0])


def test_the_commands_refuse_an_unknown_instrument_in_one_line():
    done = command_here(["compare", "--instruments", "dial,stepgauge", "--machines", "1"])
    assert done.returncode == 2
    assert "unknown instrument" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
