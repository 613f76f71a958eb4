"""Machine designs: the description as data, its file's rigour, and a second design
(``examples/designs/small.json``: L = 250 mm, d = 60 mm, r = 25 mm, limits -80 .. +50 mm,
10 x 10 mm bars) through the whole pipeline of the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibrators.cli import main
from orthoglide_env import MachineDesign
from orthoglide_env.model.design import PROTOTYPE, RULES, DesignError
from orthoglide_env.model.errors import MachineFileError, MachineParams, check_validity
from orthoglide_env.model.kinematics import direct, paper_posture
from orthoglide_env.world.machine_file import read_machine_file

SMALL_FILE = Path(__file__).resolve().parents[1] / "examples" / "designs" / "small.json"
SMALL = MachineDesign.from_file(SMALL_FILE)
PROTOTYPE_FILE = (Path(__file__).resolve().parents[1] / "orthoglide_env" / "model"
                  / "prototype.json")


def test_the_example_is_the_second_design_and_the_rest_is_the_prototype() -> None:
    assert (SMALL.L, SMALL.d, SMALL.r, SMALL.rho_min, SMALL.rho_max, SMALL.bar_section) == (
        250.0, 60.0, 25.0, -80.0, 50.0, (10.0, 10.0))
    given = set(json.loads(SMALL_FILE.read_text()))
    for key in set(RULES) - given:
        assert getattr(SMALL, key) == getattr(PROTOTYPE, key), key
    # The validity range's lengths scale with L when the file leaves it out; angles stay.
    for key, (limit, unit) in SMALL.validity_range.items():
        scale = SMALL.L / PROTOTYPE.L if unit == "mm" else 1.0
        assert limit == pytest.approx(PROTOTYPE.validity_range[key][0] * scale, rel=1e-15)


def test_the_prototype_lives_in_its_file_and_round_trips() -> None:
    assert PROTOTYPE.to_dict() == json.loads(PROTOTYPE_FILE.read_text())
    assert MachineDesign.from_dict({}) == PROTOTYPE
    assert MachineDesign.from_dict(SMALL.to_dict()) == SMALL
    assert MachineDesign.from_dict(json.loads(SMALL.to_json())) == SMALL
    # The paper's numbers, section 2.1 of the paper.
    assert (PROTOTYPE.L, PROTOTYPE.d, PROTOTYPE.r, PROTOTYPE.rho_min, PROTOTYPE.rho_max) == (
        310.25, 80.0, 31.0, -100.0, 60.0)


def test_a_250_mm_leg_is_a_design_and_its_errors_are_relative_to_it() -> None:
    machine = MachineParams(dL=[1.0, -2.0, 0.5], design=SMALL)
    np.testing.assert_array_equal(machine.leg_lengths, [251.0, 248.0, 250.5])
    assert machine.with_paper_params(np.zeros(3), np.zeros(3)).design == SMALL
    assert MachineParams.from_vector(machine.to_vector(), SMALL) == machine
    assert machine != MachineParams(dL=[1.0, -2.0, 0.5])  # the prototype's
    with pytest.raises(MachineFileError, match=r"\[-8.05802, 8.05802\] mm"):
        check_validity(MachineParams(dL=[9.0, 0.0, 0.0], design=SMALL))
    check_validity(MachineParams(dL=[9.0, 0.0, 0.0]))  # within the prototype's 10 mm
    with pytest.raises(ValueError, match="shares one design"):
        MachineParams.stack([machine, MachineParams()])


def test_the_paper_postures_follow_L_and_the_limits() -> None:
    for name in ("XMax", "YMin"):
        rho = paper_posture(name, SMALL)
        tcp = direct(MachineParams(design=SMALL), rho)
        limit = SMALL.rho_max if name.endswith("Max") else SMALL.rho_min
        leg = "XYZ".index(name[0])
        # The TCP on the leg's axis at L sin(alpha), sin(alpha) = limit / L.
        np.testing.assert_allclose(tcp, limit * np.eye(3)[leg], atol=1e-9)
        assert SMALL.rho_min <= rho.min() and rho.max() <= SMALL.rho_max


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize(("name", "text", "message"), [
    ("unknown.json", '{\n  "L": 250,\n  "legs": 3\n}', ":3: unknown design key(s) ['legs']"),
    ("type.json", '{\n  "d": "60"\n}',
     ":2: design key 'd' must be a number, > 0 (mm), got '60' (str)"),
    ("bool.json", '{\n  "L": 250,\n  "r": true\n}',
     ":3: design key 'r' must be a number, >= 0 (mm), got True (bool)"),
    ("range.json", '{\n  "rho_max": -5\n}', ":2: design key 'rho_max' must be a number, > 0"),
    ("shape.json", '{\n  "bar_section": [10]\n}',
     ":2: design key 'bar_section' must be a list of 2 numbers, each > 0 (mm), got [10]"),
    ("twice.json", '{\n  "L": 250,\n  "L": 260\n}', ":3: design key 'L' is given twice"),
    ("relation.json", '{\n  "L": 250,\n  "rho_max": 300\n}',
     ":3: design: rho_max (300 mm) must be below L (250 mm)"),
    ("validity.json", '{\n  "validity": {"dL": 0}\n}',
     ":2: design key 'validity.dL' must be a number, > 0"),
    ("syntax.json", '{\n  "L": 250,\n}', ":3: not valid JSON"),
    ("unknown.toml", 'L = 250\nlegs = 3\n', ":2: unknown design key(s) ['legs']"),
    ("bool.toml", 'L = 250\nd = true\n', ":2: design key 'd' must be a number"),
    ("twice.toml", 'L = 250\nL = 260\n', ":2: not valid TOML (Cannot overwrite a value)"),
    ("range.toml", 'L = 250\n\n[validity]\ndrho = -1\n', ":3: design key 'validity.drho'"),
])
def test_a_bad_design_file_is_refused_with_its_line_and_rule(tmp_path, name: str, text: str,
                                                             message: str) -> None:
    path = _write(tmp_path / name, text)
    with pytest.raises(DesignError) as caught:
        MachineDesign.from_file(path)
    assert str(caught.value).startswith(f"{path}{message}"), str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_toml_design_reads_as_its_json(tmp_path) -> None:
    lines = [f"{k} = {json.dumps(v)}" for k, v in json.loads(SMALL_FILE.read_text()).items()]
    assert MachineDesign.from_file(_write(tmp_path / "small.toml", "\n".join(lines))) == SMALL


def test_machine_files_name_their_design(tmp_path) -> None:
    _write(tmp_path / "small.json", SMALL_FILE.read_text())
    by_path = _write(tmp_path / "by_path.json", '{"dL": [1, 0, 0], "design": "small.json"}')
    by_object = _write(tmp_path / "by_object.json",
                       json.dumps({"dL": [1, 0, 0], "design": {"L": 250, "d": 60, "r": 25,
                                                                "rho_min": -80, "rho_max": 50,
                                                                "bar_section": [10, 10]}}))
    for path in (by_path, by_object):
        assert MachineParams.from_json(path) == MachineParams(dL=[1, 0, 0], design=SMALL)
        assert MachineParams.from_json(path, SMALL).design == SMALL
    with pytest.raises(MachineFileError, match=r"by_path.json:1: machine key 'design' names "
                                               r"another design"):
        MachineParams.from_json(by_path, PROTOTYPE)
    # What a machine writes reads back, design included; the prototype's is left out.
    machine = MachineParams(drho=[0.5, 0, 0], design=SMALL)
    machine.to_json(tmp_path / "out.json")
    assert MachineParams.from_json(tmp_path / "out.json") == machine
    assert "design" not in MachineParams().to_dict()
    bad = _write(tmp_path / "bad.json", '{\n  "drho": [0, 0, 0],\n  "design": {"d": -1}\n}')
    with pytest.raises(MachineFileError, match=r"bad.json:3: design key 'd' must be a number"):
        MachineParams.from_json(bad)


def test_orthoglide_design_prints_the_prototype_and_writes_a_file(tmp_path, capsys) -> None:
    assert main(["design"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(PROTOTYPE_FILE.read_text())
    out = tmp_path / "d.json"
    assert main(["design", "--design", str(SMALL_FILE), "-o", str(out)]) == 0
    assert MachineDesign.from_file(out) == SMALL
    assert main(["pose", "--machine", str(_write(tmp_path / "m.json", "{}")), "--design",
                 str(_write(tmp_path / "bad.json", '{"L": 0}')), "--rho", "0", "0", "0"]) == 2
    assert "bad.json:1: design key 'L' must be a number, > 0 (mm), got 0" in (
        capsys.readouterr().err)


# -- the second design through the command line ----------------------------------------------
@pytest.fixture
def small_machine(tmp_path) -> str:
    """A machine of the small design with every kind of error (a file naming no design)."""
    machine = {"drho": [0.5, -0.3, 0.2], "dL": [-0.4, 0.6, 0.1],
               "axis_tilt": [[1e-3, 0], [0, -2e-3], [1e-3, 1e-3]],
               "axis_offset": [[0.2, 0], [0, 0.3], [-0.1, 0]],
               "attach": [[0.1, 0, 0], [0, 0.2, 0], [0, 0, -0.1]]}
    return str(_write(tmp_path / "machine.json", json.dumps(machine)))


def _json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_pose_of_the_small_design_pybullet_against_exact(capsys, small_machine) -> None:
    design = ["--machine", small_machine, "--design", str(SMALL_FILE), "--noise-free", "--json"]
    for rho in (["3", "-4", "2"], ["30", "-50", "20"], ["-70", "40", "-10"]):
        report = _json(capsys, ["pose", *design, "--rho", *rho])
        gap = np.linalg.norm(np.subtract(report["tcp"], report["tcp_model"]))
        assert gap < 1e-3, rho  # 1 µm
        assert report["loop_residual_mm"] < 1e-3
    # Near Zero the gauges touch their bars of the small design (mid-travel at Zero).
    near = _json(capsys, ["pose", *design, "--rho", "1", "-1", "1"])
    assert all(g["valid"] and abs(g["reading"]) < 3.0 for g in near["gauges"])
    # The design's limits are the command's: 55 mm is beyond the small machine's +50.
    assert main(["pose", *design, "--rho", "55", "0", "0"]) == 2
    assert "outside the joint limits [-80, 50] mm" in capsys.readouterr().err


def test_calibrate_paper_on_the_small_design_recovers_the_paper_parameters(
        tmp_path, capsys) -> None:
    path = _write(tmp_path / "paper.json", '{"drho": [0.5, -0.3, 0.2], "dL": [-0.4, 0.6, 0.1]}')
    report = _json(capsys, ["calibrate", "--machine", str(path), "--design", str(SMALL_FILE),
                            "--agent", "paper", "--params", "paper6", "--conditions", "ideal",
                            "--json"])
    for key in ("drho", "dL"):
        np.testing.assert_allclose(report["estimate"][key], report["truth"][key], atol=1e-6)
    assert report["experiment_time_s"] > 0


def test_fit_reads_the_design_of_a_json_readings_file_or_takes_it_from_the_command(
        tmp_path, capsys) -> None:
    path = _write(tmp_path / "paper.json", '{"drho": [0.5, -0.3, 0.2], "dL": [-0.4, 0.6, 0.1]}')
    common = ["--machine", str(path), "--design", str(SMALL_FILE), "--backend", "exact",
              "--conditions", "ideal", "--json"]
    fits = {}
    noise = ["--sigma", "0", "--resolution", "0", "--params", "paper6", "--json"]
    for suffix in ("json", "csv"):
        saved = tmp_path / f"readings.{suffix}"
        _json(capsys, ["calibrate", *common, "--save-measurements", str(saved)])
        fits[f"{suffix} --design"] = _json(capsys, ["fit", str(saved), "--design",
                                                    str(SMALL_FILE), *noise])["estimate"]["dL"]
    fits["json"] = _json(capsys, ["fit", str(tmp_path / "readings.json"), *noise])[
        "estimate"]["dL"]
    for key in ("json", "json --design", "csv --design"):
        np.testing.assert_allclose(fits[key], [-0.4, 0.6, 0.1], atol=1e-6)
    # A CSV cannot name its design, but its paper postures carry their names: read as the
    # prototype's, XMax is not at the prototype's XMax, and the reading is refused, with
    # the option that reads it right, where the legs would come out 60.25 mm short.
    assert main(["fit", str(tmp_path / "readings.csv"), *noise]) == 2
    err = capsys.readouterr().err
    assert "XMax is the paper posture at rho" in err and "(--design)" in err


def test_compare_on_the_small_design(tmp_path, capsys) -> None:
    assert main(["compare", "--design", str(SMALL_FILE), "--machines", "1", "--agents",
                 "paper,optimal,tracker", "--estimators", "paper,extended", "--budget", "600",
                 "--quiet", "--out", str(tmp_path)]) == 0
    trials = [json.loads(line) for line in (tmp_path / "trials.jsonl").read_text().splitlines()]
    fitted = {(t["agent"], t["estimator"]) for t in trials if not t["failed"]}
    assert {("paper", "paper"), ("paper", "extended"), ("optimal", "extended"),
            ("tracker", "extended")} <= fitted
    for trial in trials:
        if not trial["failed"]:
            # Calibration helps, over the small design's own scoring grid.
            assert trial["tcp_after"]["rigid"] < trial["tcp_before"]["rigid"]
    assert json.loads((tmp_path / "config.json").read_text())["design"] == SMALL.to_dict()


def test_urdf_of_the_small_design_loads_and_closes(tmp_path, capsys, small_machine) -> None:
    yourdfpy = pytest.importorskip("yourdfpy")
    from orthoglide_env.sim.urdf import MM, joint_positions, loop_closures

    out = tmp_path / "small.urdf"
    assert main(["urdf", "--machine", small_machine, "--design", str(SMALL_FILE), "-o",
                 str(out)]) == 0
    machine = MachineParams.from_json(small_machine, SMALL)
    urdf = yourdfpy.URDF.load(str(out), load_meshes=False, build_collision_scene_graph=False)
    kinds = {name: j.type for name, j in urdf.joint_map.items()}
    limits = urdf.joint_map["x_slide"].limit
    assert (limits.lower / MM, limits.upper / MM) == pytest.approx(
        (SMALL.rho_min - SMALL.urdf_margin, SMALL.rho_max + SMALL.urdf_margin))
    for rho in np.random.default_rng(4).uniform(SMALL.rho_min, SMALL.rho_max, (20, 3)):
        values = joint_positions(machine, rho)
        urdf.update_cfg({n: v * MM if kinds[n] == "prismatic" else v for n, v in values.items()})
        tcp = urdf.get_transform("platform", "base")[:3, 3] / MM
        np.testing.assert_allclose(tcp, direct(machine, rho), atol=1e-6)
        for c in loop_closures(machine):
            a, b = urdf.get_transform(c.link_a, "base"), urdf.get_transform(c.link_b, "base")
            np.testing.assert_allclose((a[:3, :3] @ c.point_a * MM + a[:3, 3]) / MM,
                                       (b[:3, :3] @ c.point_b * MM + b[:3, 3]) / MM, atol=1e-6)


def test_the_lab_takes_its_design_limits_and_machines() -> None:
    import gymnasium as gym

    import orthoglide_env

    env = gym.make(orthoglide_env.LAB_ENV_ID, design=SMALL, errors="paper")
    try:
        lab = env.unwrapped
        box = env.action_space["rho"]
        assert (box.low.min(), box.high.max()) == (SMALL.rho_min, SMALL.rho_max)
        env.reset(seed=1)
        assert lab.true_machine.design == SMALL
        assert lab.travel == SMALL.gauge_travel
        move = {"op": 0, "rho": np.array([0.0, 0.0, 55.0]), "stand": 0, "slot": 0}
        with pytest.raises(ValueError, match=r"outside the joint limits \[-80, 50\] mm"):
            env.step(move)
        with pytest.raises(ValueError, match="machine key 'design' names another design"):
            env.reset(options={"machine": {"design": PROTOTYPE.to_dict()}})
        state = lab.np_random.bit_generator.state
        with pytest.raises(ValueError, match="the machine's design is not the lab's"):
            env.reset(options={"machine": MachineParams()})
        assert lab.np_random.bit_generator.state == state  # a refused reset changes nothing
    finally:
        env.close()
    with pytest.raises(ValueError, match="design must be a MachineDesign, got str"):
        gym.make(orthoglide_env.LAB_ENV_ID, design=str(SMALL_FILE))


@pytest.mark.parametrize("backend", ["exact", "pybullet"])
def test_the_calibration_env_takes_its_design(backend: str) -> None:
    """The calibration env on the small design: its limits, travel and machines; with ideal
    gauges it reads what the exact model of its machine and installation gives, within
    the 1 um PyBullet and the exact model agree by."""
    import gymnasium as gym

    import orthoglide_env
    from orthoglide_env.instruments.dial import exact_readings

    env = gym.make(orthoglide_env.ENV_ID, design=SMALL, errors="paper", backend=backend,
                   gauge_sigma=0.0, gauge_resolution=0.0, conditions="ideal")
    try:
        calibration = env.unwrapped
        assert (env.action_space.low.min(), env.action_space.high.max()) == (
            SMALL.rho_min, SMALL.rho_max)
        env.reset(seed=3)
        assert calibration.true_machine.design == SMALL
        assert calibration.travel == SMALL.gauge_travel
        with pytest.raises(ValueError, match=r"outside the joint limits \[-80, 50\] mm"):
            env.step(np.array([0.0, 0.0, 55.0]))
        with pytest.raises(ValueError, match="the machine's design is not the lab's"):
            env.reset(options={"machine": MachineParams()})
        env.reset(seed=3)
        for name in ("XMax", "YMin", "Zero"):
            rho = paper_posture(name, SMALL)
            obs, *_ = env.step(rho)
            exact = exact_readings(calibration.true_machine, calibration.true_gauges, rho)
            valid = obs["valid"].astype(bool)
            np.testing.assert_array_equal(valid, np.isfinite(exact))
            np.testing.assert_allclose(obs["gauges"][valid], exact[valid], atol=1e-3)
    finally:
        env.close()


# -- a design's own slot catalogue ----------------------------------------------------------
#: Three bar places per bar side: 18 bar slots, then the 6 carriage and 3 platform slots.
THREE = {"slot_positions": [0.3, 0.5, 0.7]}


def _three(tmp_path: Path) -> tuple[Path, MachineDesign]:
    path = _write(tmp_path / "three.json", json.dumps(THREE))
    return path, MachineDesign.from_file(path)


def test_the_lab_of_a_design_with_other_slots_has_its_catalogue(tmp_path) -> None:
    import gymnasium as gym

    import orthoglide_env
    from orthoglide_env.instruments.slots import PAPER_LAYOUT
    from orthoglide_env.lab.operations import SLOTS, Op, slot_catalogue, slot_index

    _, design = _three(tmp_path)
    slots = slot_catalogue(design)
    assert len(slots) == 27 and slots is slot_catalogue(design)  # made once per design
    assert [s.slot for s in slots[:3]] == ["x-leg/y@0.3", "x-leg/y@0.5", "x-leg/y@0.7"]
    assert slots[18:] == SLOTS[30:]  # the carriages and the platform are every design's
    only_here = slot_index("x-leg/y@0.3", design=design)
    with pytest.raises(ValueError, match=r"no slot 'x-leg/y@0.3'.*\(0.2, 0.35"):
        slot_index("x-leg/y@0.3", design=PROTOTYPE)  # the prototype's catalogue has no such slot
    env = gym.make(orthoglide_env.LAB_ENV_ID, design=design)
    try:
        lab = env.unwrapped
        assert lab.slots == slots and lab.settings.slots == slots
        assert env.action_space["slot"].n == 27
        assert list(env.observation_space["slot"].nvec) == [28] * 6
        obs, _ = env.reset(seed=0)
        assert list(obs["slot"]) == [slot_index(s, design=design) for s in PAPER_LAYOUT]
        obs, _, _, _, info = env.step({"op": Op.REMOUNT, "rho": np.zeros(3), "stand": 0,
                                       "slot": only_here})
        assert info["refused"] == "" and obs["slot"][0] == only_here and obs["valid"][0]
        read = [r for r in lab.records if r.spec.slot == "x-leg/y@0.3"]
        assert len(read) == 1 and read[0].mounting == "x-leg/y@0.3#7"
        assert read[0].reading == obs["gauges"][0]
        obs, *_ = env.step({"op": Op.LIFT, "rho": np.zeros(3), "stand": 1, "slot": 0})
        assert obs["slot"][1] == slot_index("x-leg/z@0.5", design=design)
        with pytest.raises(ValueError, match=r"action slot must be an integer in \[0, 27\)"):
            env.step({"op": Op.REMOUNT, "rho": np.zeros(3), "stand": 0, "slot": 27})
    finally:
        env.close()


def test_the_vector_lab_of_a_design_with_other_slots_is_its_lone_labs(tmp_path) -> None:
    import gymnasium as gym

    import orthoglide_env
    from orthoglide_env.lab.operations import Op, slot_catalogue, slot_index

    _, design = _three(tmp_path)
    envs = gym.make_vec(orthoglide_env.LAB_ENV_ID, num_envs=2, design=design)
    lone = gym.make(orthoglide_env.LAB_ENV_ID, design=design)
    try:
        assert envs.slots == envs.sub_env(1).slots == slot_catalogue(design)
        assert envs.single_action_space["slot"].n == 27
        envs.reset(seed=4)
        lone.reset(seed=5)  # env 1 of the vector env
        slot = slot_index("z-leg/y@0.7", design=design)
        obs, *_ = envs.step({"op": np.array([Op.REMOUNT] * 2), "rho": np.zeros((2, 3)),
                             "stand": np.array([0, 2]), "slot": np.array([slot] * 2)})
        alone, *_ = lone.step({"op": Op.REMOUNT, "rho": np.zeros(3), "stand": 2, "slot": slot})
        for key, value in alone.items():
            np.testing.assert_array_equal(obs[key][1], value, err_msg=key)
        assert obs["slot"][1][2] == slot and obs["valid"][1][2]
    finally:
        envs.close()
        lone.close()


@pytest.mark.slow
def test_compare_on_a_design_with_other_slots(tmp_path, capsys) -> None:
    path, _ = _three(tmp_path)
    out = tmp_path / "run"
    # A quarter of an hour: the planners still weigh a re-mount (every 300 s) on this
    # design's slots, at a quarter of the hour's cost.
    assert main(["compare", "--design", str(path), "--agents", "paper,random,optimal,active",
                 "--estimators", "extended", "--machines", "2", "--budget", "900", "--quiet",
                 "--out", str(out)]) == 0
    trials = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    assert sorted({t["agent"] for t in trials}) == ["active", "optimal", "paper", "random"]
    assert len(trials) == 8 and not [t["failed"] for t in trials if t["failed"]]


def test_a_design_without_the_mid_leg_slots_is_refused_by_the_lab() -> None:
    import gymnasium as gym

    import orthoglide_env

    design = MachineDesign.from_dict({"slot_positions": [0.3, 0.7]})
    message = ("the lab mounts its stands at the paper's mid-leg slots (e.g. 'x-leg/y@0.5') "
               "at every reset: the design's slot_positions [0.3, 0.7] must include 0.5")
    for make in (gym.make, lambda env_id, **kw: gym.make_vec(env_id, num_envs=2, **kw)):
        with pytest.raises(ValueError) as caught:
            make(orthoglide_env.LAB_ENV_ID, design=design)
        assert str(caught.value) == message


def test_the_stands_follow_the_designs_slot_count() -> None:
    import gymnasium as gym

    import orthoglide_env

    one = MachineDesign.from_dict({"slot_positions": [0.5]})  # 6 + 6 + 3 slots
    gym.make(orthoglide_env.LAB_ENV_ID, design=one, stands=15).close()
    with pytest.raises(ValueError, match=r"^stands must be an integer in \[1, 15\] \(the "
                                         r"design's slot count\), got 16$"):
        gym.make(orthoglide_env.LAB_ENV_ID, design=one, stands=16)
    gym.make(orthoglide_env.LAB_ENV_ID, stands=39).close()
    with pytest.raises(ValueError, match=r"in \[1, 39\] \(the design's slot count\), got 40"):
        gym.make(orthoglide_env.LAB_ENV_ID, stands=40)
    with pytest.raises(ValueError, match=r"in \[1, the design's slot count\], got 0"):
        gym.make(orthoglide_env.LAB_ENV_ID, stands=0)


# --- Every file that holds a design makes the commands use it ------------------------
#: A machine builder's design (not the prototype's, nor the small example's).
BUILDER = {"L": 280.0, "d": 70.0, "r": 28.0}


@pytest.fixture(scope="session")
def builder(tmp_path_factory) -> dict[str, Path]:
    """A builder's design file, an estimate of one of its machines, the compensation's
    machine file and a plan with its filled sheet."""
    import csv

    folder = tmp_path_factory.mktemp("builder")
    files = {"design": _write(folder / "design.json", json.dumps(BUILDER)),
             "estimate": folder / "est.json", "plan": folder / "plan"}
    assert main(["calibrate", "--design", str(files["design"]), "--seed", "3", "--params",
                 "paper6", "--conditions", "ideal", "--save-estimate",
                 str(files["estimate"]), "--json"]) == 0
    assert main(["compensate", str(files["estimate"]), "--out", str(folder / "comp"),
                 "--json"]) == 0
    files["machine"] = folder / "comp" / "machine.json"
    assert main(["plan", "--design", str(files["design"]), "--out",
                 str(files["plan"])]) == 0
    rows = list(csv.reader((files["plan"] / "readings.csv").open()))
    column = rows[0].index("reading_mm")
    for row in rows[1:]:
        row[column] = "0.01"
    files["sheet"] = folder / "filled.csv"
    with files["sheet"].open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    return files


@pytest.mark.parametrize("kind", ["estimate", "machine"])
def test_pose_reads_a_machine_file_of_its_own_design(builder, capsys, kind) -> None:
    """An estimate, or the compensation's machine.json, names its design: pose uses it
    without --design, and refuses a --design that is another in one line."""
    capsys.readouterr()
    # The textbook world: the tool is where the geometry alone puts it.
    assert main(["pose", "--machine", str(builder[kind]), "--rho", "0", "0", "0",
                 "--noise-free", "--conditions", "ideal", "--json"]) == 0
    tcp = json.loads(capsys.readouterr().out)["tcp_model"]
    machine, _ = read_machine_file(builder[kind])
    assert machine.design == MachineDesign.from_dict(BUILDER)
    # The exact model's tool at Zero is the builder's machine's (the prototype's with the
    # same errors would sit elsewhere: its legs are 30 mm longer).
    assert np.allclose(tcp, direct(machine, np.zeros(3)), rtol=0, atol=1e-9)
    assert main(["pose", "--machine", str(builder[kind]), "--rho", "0", "0", "0",
                 "--design", "examples/designs/small.json"]) == 2
    assert "another design" in capsys.readouterr().err


def test_plan_verify_plans_for_the_estimates_design(builder, tmp_path, capsys) -> None:
    """The verification of an estimate is planned on the estimate's machine (its stands
    placed along its bars, its postures within its limits), and a --design that is
    another is refused."""
    out = tmp_path / "verify"
    assert main(["plan", "--verify", str(builder["estimate"]), "--out", str(out)]) == 0
    plan = json.loads((out / "plan.json").read_text())
    assert MachineDesign.from_dict(plan["design"]) == MachineDesign.from_dict(BUILDER)
    capsys.readouterr()
    assert main(["plan", "--verify", str(builder["estimate"]), "--design",
                 "examples/designs/small.json", "--out", str(tmp_path / "no")]) == 2
    assert "another design than the estimate's" in capsys.readouterr().err


def test_fit_takes_the_plans_design(builder, capsys) -> None:
    """A sheet filled from a plan is fitted against the plan without --design (the plan
    holds its design); a --design that is another is refused in one line."""
    capsys.readouterr()
    assert main(["fit", str(builder["sheet"]), "--plan", str(builder["plan"] / "plan.json"),
                 "--params", "paper6", "--json"]) == 0
    capsys.readouterr()
    assert main(["fit", str(builder["sheet"]), "--plan", str(builder["plan"] / "plan.json"),
                 "--design", "examples/designs/small.json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another design than the plan's" in err[0]


def test_the_verification_checks_every_posture_of_the_calibration(builder, tmp_path) -> None:
    """The paper's postures sit at the control limits, and the compensated command of an
    estimated machine with encoder offsets can lie beyond them there: the verification
    pulls such a command inside instead of leaving its posture out, so it has every step
    and reading of the calibration's plan, each command within the limits."""
    out = tmp_path / "verify"
    assert main(["plan", "--verify", str(builder["estimate"]), "--out", str(out)]) == 0
    verification = json.loads((out / "plan.json").read_text())
    calibration = json.loads((builder["plan"] / "plan.json").read_text())
    # This machine's offsets push some commands beyond a limit (else nothing is tested).
    assert any("is verified at" in note for note in verification["notes"])
    assert not any("left out" in note for note in verification["notes"])
    assert len(verification["steps"]) == len(calibration["steps"])
    import csv

    def sheet(folder: Path) -> list[dict[str, str]]:
        with (folder / "readings.csv").open() as handle:
            return list(csv.DictReader(handle))

    rows = sheet(out)
    assert len(rows) == len(sheet(builder["plan"]))
    design = MachineDesign.from_dict(BUILDER)
    for row in rows:
        rho = [float(row[f"rho_{a}"]) for a in "xyz"]
        assert all(design.rho_min <= v <= design.rho_max for v in rho), row


def test_below_the_envs_a_design_is_never_assumed() -> None:
    """The model, the lab and the scoring take the design they work on: a call that forgets
    it fails at once instead of computing the prototype (the envs and ``gym.make`` keep
    the prototype as the user's default)."""
    from orthoglide_env.lab.notebook import Notebook
    from orthoglide_env.lab.operations import slot_index
    from orthoglide_env.model.errors import random_machine, within_limits
    from orthoglide_env.scoring import workspace_grid

    forgetful = [lambda: paper_posture("XMax"), lambda: random_machine(1, "paper"),
                 lambda: within_limits(np.zeros(3)), lambda: slot_index("platform/x"),
                 lambda: workspace_grid(), lambda: Notebook(0.01, 0.005),
                 lambda: MachineParams.from_vector(np.zeros(27))]
    for call in forgetful:
        with pytest.raises(TypeError, match="design"):
            call()
    small = MachineDesign.from_dict({"L": 280.0, "d": 70.0, "r": 28.0})
    assert not np.array_equal(paper_posture("XMax", small), paper_posture("XMax", PROTOTYPE))
