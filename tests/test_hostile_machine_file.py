"""Machine files against hostile input: one clear MachineFileError naming the file, the
line of the key at fault and the rule; the validity range; array equality."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import command_here
from hypothesis import given, settings
from hypothesis import strategies as st

from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import (
    PRESETS,
    MachineFileError,
    MachineParams,
    check_validity,
    random_machine,
)

SHAPES = {key: np.shape(value) for key, value in MachineParams().to_dict().items()}


def read(tmp_path, text: str) -> MachineParams:
    path = tmp_path / "m.json"
    path.write_text(text)
    return MachineParams.from_json(path)


@pytest.mark.parametrize(
    ("text", "place", "fragment"),
    [
        ('{"drho": [%s, 0, 0]}' % ("9" * 401), ":1:", "beyond the range of a float"),
        ('{"drho": [%s, 0, 0]}' % ("9" * 5000), ": ", "not a machine file"),
        ('{\n "dL": [0, 0, 0],\n "drho": [true, 0, 0]\n}', ":3:", "must hold numbers"),
        ('{"drho": ["1.5", 0, 0]}', ":1:", "must hold numbers, got '1.5'"),
        ('{"drho": [null, 0, 0]}', ":1:", "must hold numbers"),
        ('{"drho": [[1], 0, 0]}', ":1:", "must hold numbers"),
        ('{"drho": {"x": 1}}', ":1:", "must hold numbers"),
        ('{\n "drho": [1, 2, 3],\n "dL": [0, 0, 0],\n "drho": [0, 0, 0]\n}', ":4:",
         "'drho' is given twice"),
        ('{"axis_tilt": [[0, 0], [0]]}', ":1:", "rows of different lengths"),
        ('{"attach": [[0, 0, 0], [0, 0, 0]]}', ":1:", "shape [3, 3]"),
        ('{"dL": [0, 0, 1e400]}', ":1:", "non-finite"),
        ('{"dL": [0, 0, NaN]}', ":1:", "non-finite"),
        ("[" * 100_000 + "]" * 100_000, ": ", "not a machine file"),
        ('{"drho": [0, 0, 0],\n"dL": [0, 25, 0]}', ":2:",
         "'dL' element [1] = 25 mm is outside the validity range [-10, 10] mm"),
        ('{"axis_tilt": [[0, 0], [0, 0], [0, -0.5]]}', ":1:",
         "'axis_tilt' element [2, 1] = -0.5 rad is outside the validity range"),
        ('{"drho": [0, 0, 0]}\n{"x": 1}', ":2:", "not valid JSON"),
    ],
)
def test_hostile_files_give_one_clear_error(tmp_path, text: str, place: str,
                                            fragment: str) -> None:
    with pytest.raises(MachineFileError) as caught:
        read(tmp_path, text)
    message = str(caught.value)
    assert len(message.splitlines()) == 1 and len(message) < 300, message
    assert message.startswith(str(tmp_path / "m.json") + place), message
    assert fragment in message, message


def test_the_command_line_reports_the_same_one_line(tmp_path) -> None:
    path = tmp_path / "m.json"
    path.write_text('{"drho": [%s, 0, 0]}' % ("9" * 401))
    proc = command_here(["pose", "--machine", str(path), "--rho", "0", "0", "0"])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (f"orthoglide pose: error: {path}:1: machine key 'drho' "
                                   "holds an integer beyond the range of a float (+-1.8e+308)")


def _element(key: str) -> st.SearchStrategy:
    limit = PROTOTYPE.validity_range[key][0]
    return st.one_of(st.floats(-2 * limit, 2 * limit), st.integers(-30, 30), st.booleans(),
                     st.text(max_size=2), st.none())


def _value(key: str) -> st.SearchStrategy:
    shape = SHAPES[key]
    rows = st.lists(_element(key), min_size=shape[-1], max_size=shape[-1])
    return rows if len(shape) == 1 else st.lists(rows, min_size=shape[0], max_size=shape[0])


def _is_machine(data: dict) -> bool:
    """The rule: numbers only (ints or floats, not booleans), each inside its range."""
    for key, value in data.items():
        flat = np.ravel(np.array(value, dtype=object))
        if not all(isinstance(v, int | float) and not isinstance(v, bool)
                   and abs(v) <= PROTOTYPE.validity_range[key][0] for v in flat):
            return False
    return True


@settings(max_examples=300, deadline=None)
@given(st.fixed_dictionaries({}, optional={key: _value(key) for key in SHAPES}))
def test_a_dict_is_a_machine_exactly_when_it_holds_numbers_in_range(data: dict) -> None:
    try:
        machine = MachineParams.from_dict(data)
    except MachineFileError:
        assert not _is_machine(data), data
    else:
        assert _is_machine(data), data
        for key, value in data.items():
            np.testing.assert_array_equal(getattr(machine, key), value)


@pytest.mark.parametrize("preset", ["paper", "realistic"])
def test_presets_lie_well_inside_the_validity_range(preset: str) -> None:
    sigmas = PRESETS[preset]
    for key, (limit, _) in PROTOTYPE.validity_range.items():
        # 5 standard deviations: a drawn machine leaves the range with odds below 1e-5.
        assert 5 * getattr(sigmas, key) <= limit, key
    rng = np.random.default_rng(0)
    for _ in range(1000):
        check_validity(random_machine(rng, preset, design=PROTOTYPE))


def test_machines_given_as_objects_are_held_to_the_range() -> None:
    with pytest.raises(MachineFileError, match="'attach' element"):
        check_validity(MachineParams(attach=np.full((3, 3), 40.0)))
    limits = {key: np.full(SHAPES[key], limit)
              for key, (limit, _) in PROTOTYPE.validity_range.items()}
    assert check_validity(MachineParams(**limits)) == MachineParams(**limits)


def test_equality_compares_arrays() -> None:
    a = random_machine(1, "realistic", design=PROTOTYPE)
    assert a == MachineParams.from_dict(json.loads(json.dumps(a.to_dict())))
    assert a == MachineParams(**a.to_dict())
    b = MachineParams(**(a.to_dict() | {"attach": (a.attach + 1e-12).tolist()}))
    assert a != b and not (a == b)
    assert MachineParams() == MachineParams() and MachineParams() != a
    assert a in [MachineParams(), a]
    assert (a == "machine") is False and a != a.to_dict()


def test_equality_sees_shapes() -> None:
    # Array equality includes the shape: values that broadcast equal are not equal.
    a, b = MachineParams(), MachineParams()
    b.drho = np.zeros((1, 3))
    assert a != b


def test_machines_at_the_limits_are_simulated_faithfully() -> None:
    # The corners of the validity box (every error at +-limit), checked as PROTOTYPE.validity_range
    # says it was chosen: the TCP across the joint cube (up to 50 mm: the singular corner
    # (60, 60, 60) is outside the guarantee) and the readings at the postures calibration
    # experiments read at (near Zero and the paper's) within 1 µm; gauge status identical.
    machine_module = pytest.importorskip("orthoglide_env.sim.pybullet")
    from orthoglide_env.instruments.dial import Status, status_of
    from orthoglide_env.instruments.rays import exact_ray_distances
    from orthoglide_env.instruments.slots import PAPER_LAYOUT
    from orthoglide_env.instruments.stands import install
    from orthoglide_env.model.kinematics import direct, paper_posture

    rng = np.random.default_rng(7)
    paper = [paper_posture(name, PROTOTYPE)
             for name in ("XMax", "XMin", "YMax", "YMin", "ZMax", "ZMin")]
    for _ in range(4):
        machine = MachineParams(**{key: limit * rng.choice([-1.0, 1.0], SHAPES[key])
                                   for key, (limit, _) in PROTOTYPE.validity_range.items()})
        gauges = install(PAPER_LAYOUT, machine)
        sim = machine_module.OrthoglideMachine(machine, gauges)
        try:
            t0_sim = sim.gauge_distances()
            t0_exact = exact_ray_distances(machine, gauges, np.zeros(3))
            for k, rho in enumerate(np.vstack([rng.uniform(-8, 8, (5, 3)), paper,
                                               rng.uniform(-100, 50, (5, 3))])):
                sim.move(rho)
                np.testing.assert_allclose(sim.tcp(), direct(machine, rho), atol=1e-3)
                t_sim, t_exact = sim.gauge_distances(), exact_ray_distances(machine, gauges, rho)
                status = status_of(gauges, t_sim)
                np.testing.assert_array_equal(status, status_of(gauges, t_exact))
                if k < 5 + len(paper):
                    ok = status == Status.VALID
                    np.testing.assert_allclose((t_sim - t0_sim)[ok], (t_exact - t0_exact)[ok],
                                               atol=1e-3)
        finally:
            sim.close()
