"""Machine parameter sets: JSON schema, presets, frames and input validation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import (
    PRESETS,
    R_LEG,
    MachineFileError,
    MachineParams,
    check_rho,
    get_preset,
    random_machine,
)


def test_leg_frames_are_right_handed_cyclic_permutations() -> None:
    for i, frame in enumerate(R_LEG):
        np.testing.assert_array_equal(frame @ frame.T, np.eye(3))
        assert np.linalg.det(frame) == pytest.approx(1.0)
        # The leg's actuator is world axis i and the frames follow x -> y -> z -> x.
        np.testing.assert_array_equal(frame[:, 0], np.eye(3)[i])
        np.testing.assert_array_equal(R_LEG[(i + 1) % 3], np.roll(frame, 1, axis=0))


def test_json_round_trip_is_exact(tmp_path) -> None:
    machine = random_machine(7, "realistic", design=PROTOTYPE)
    path = tmp_path / "m.json"
    machine.to_json(path)
    again = MachineParams.from_json(path)
    for key, value in machine.to_dict().items():
        np.testing.assert_array_equal(getattr(again, key), value)


def test_paper_only_file_is_a_valid_machine_and_missing_keys_are_zero(tmp_path) -> None:
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"drho": [1, 2, 3], "dL": [0.5, 0, -0.5]}))
    machine = MachineParams.from_json(path)
    np.testing.assert_array_equal(machine.drho, [1, 2, 3])
    assert not machine.axis_tilt.any() and not machine.attach.any()
    assert machine.is_paper_model


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        ('{"drho": [0, 0, 0], "bogus": 1}', "unknown machine key"),
        ('{"drho": [0, "a", 0]}', "must hold numbers"),
        ('{"drho": [0, 0]}', "shape [3]"),
        ('{"dL": [0, 0, NaN]}', "non-finite"),
        ('{"dL": [-300, 0, 0]}', "leg length"),
        ("[1, 2]", "JSON object"),
        ("{drho: 1}", "not valid JSON"),
    ],
)
def test_bad_machine_files_name_the_problem(tmp_path, content: str, fragment: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(MachineFileError, match=fragment.replace("[", r"\[").replace("]", r"\]")):
        MachineParams.from_json(path)


def test_missing_machine_file(tmp_path) -> None:
    with pytest.raises(MachineFileError, match="not found"):
        MachineParams.from_json(tmp_path / "nope.json")


def test_presets_are_seeded_and_paper_preset_has_only_paper_errors() -> None:
    a, b = (random_machine(3, "realistic", design=PROTOTYPE),
            random_machine(3, "realistic", design=PROTOTYPE))
    np.testing.assert_array_equal(a.axis_tilt, b.axis_tilt)
    assert not np.array_equal(a.drho, random_machine(4, "realistic", design=PROTOTYPE).drho)
    paper = random_machine(3, "paper", design=PROTOTYPE)
    assert paper.is_paper_model and paper.drho.any()
    assert random_machine(3, "nominal", design=PROTOTYPE).to_dict() == MachineParams().to_dict()
    with pytest.raises(ValueError, match="unknown error preset"):
        get_preset("wild")
    assert set(PRESETS) >= {"paper", "realistic"}


def test_with_paper_params_keeps_extended_errors() -> None:
    machine = random_machine(5, "realistic", design=PROTOTYPE)
    other = machine.with_paper_params(np.ones(3), np.zeros(3))
    np.testing.assert_array_equal(other.attach, machine.attach)
    np.testing.assert_array_equal(other.drho, np.ones(3))


@pytest.mark.parametrize(
    ("rho", "fragment"),
    [([0, 0], "3 components"), ([0, np.nan, 0], "finite"), ([0, 0, 60.5], "joint limits")],
)
def test_check_rho_refuses_bad_targets(rho, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        check_rho(np.array(rho, dtype=float), design=PROTOTYPE)
    np.testing.assert_array_equal(check_rho([-100, 60, 0], design=PROTOTYPE), [-100, 60, 0])
