"""Faults against the commands: each fault kind written into a clean sheet is named by
``fit`` in one warning line that says its kind and where (exit status 0: the readings are
a user's, the fit goes on); a fault kind the lab does not know is refused in one line with
exit status 2 (``ValueError`` in the env)."""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import pytest
from conftest import command_here

import orthoglide_env
from calibrators.measurements import Measurements

#: The clean sheet: a 20-minute designed experiment on realistic machine 3, dial sigma
#: 0.02 mm read to 0.01 mm, in the textbook's world (explicit: the default changes).
SIGMA = "0.02"


def run(*argv: str) -> subprocess.CompletedProcess:
    """The command, run in this process (``command_here``): what it writes and its status
    are tested here, the process a user starts in tests/test_cli.py."""
    return command_here(list(argv))


@pytest.fixture(scope="session")
def sheet(tmp_path_factory) -> tuple[Path, Measurements]:
    folder = tmp_path_factory.mktemp("faults")
    path = folder / "clean.csv"
    proc = run("calibrate", "--agent", "optimal", "--backend", "exact", "--budget", "1200",
               "--seed", "3", "--sigma", SIGMA, "--conditions", "ideal", "--params",
               "extended", "--save-measurements", str(path), "--json")
    assert proc.returncode == 0, proc.stderr
    return folder, Measurements.read(path)


def fit(folder: Path, data: Measurements, name: str) -> list[str]:
    """``fit`` of ``data`` (written to ``name``): its exit status 0 and its warning lines."""
    path = folder / name
    data.write(path)
    proc = run("fit", str(path), "--sigma", SIGMA, "--params", "extended")
    assert proc.returncode == 0, proc.stderr
    return [line for line in proc.stdout.splitlines() if line.startswith("warning: ")]


def longest_mounting(data: Measurements) -> list[int]:
    """The readings of the mounting with the most, in order."""
    by: dict[str, list[int]] = {}
    for k, m in enumerate(data.items):
        by.setdefault(m.mounting, []).append(k)
    return max(by.values(), key=len)


@pytest.mark.slow
def test_a_clean_sheet_names_no_fault(sheet) -> None:
    folder, data = sheet
    assert not [w for w in fit(folder, data, "same.csv") if w.startswith("warning: fault")]


def test_a_knocked_stand_is_named_and_given_a_new_mounting(sheet) -> None:
    folder, data = sheet
    mine = longest_mounting(data)
    half = mine[len(mine) // 2:]
    # 0.06 mm, three sigma of a reading: a knock found by the readings together.
    items = [replace(m, reading=m.reading + 0.06, design=data.design) if k in half else m
             for k, m in enumerate(data.items)]
    lines = fit(folder, replace(data, items=items), "knock.csv")
    named = [w for w in lines if w.startswith("warning: fault knock: stand "
                                              f"{data.items[mine[0]].mounting} moved by")]
    assert len(named) == 1, lines
    assert "refitted with a new mounting from there on" in named[0]


def test_a_reading_written_with_the_wrong_sign_is_named(sheet) -> None:
    folder, data = sheet
    k = max(range(len(data.items)), key=lambda j: abs(data.items[j].reading))
    items = list(data.items)
    items[k] = replace(items[k], reading=-items[k].reading, design=data.design)
    lines = fit(folder, replace(data, items=items), "sign.csv")
    assert [w for w in lines if w.startswith(f"warning: fault sign: line {k + 2} ")], lines


def test_a_stuck_plunger_is_named(sheet) -> None:
    folder, data = sheet
    mine = longest_mounting(data)
    # The reading that moved most since its mounting's previous one sticks.
    j = max(range(1, len(mine)), key=lambda i: abs(data.items[mine[i]].reading
                                                   - data.items[mine[i - 1]].reading))
    items = list(data.items)
    items[mine[j]] = replace(items[mine[j]], reading=items[mine[j - 1]].reading,
                             design=data.design)
    lines = fit(folder, replace(data, items=items), "stick.csv")
    assert [w for w in lines if w.startswith(f"warning: fault stick: line {mine[j] + 2} ")], \
        lines


def test_a_skipped_row_is_named_and_put_back(sheet) -> None:
    folder, data = sheet
    mine = longest_mounting(data)
    late = mine[len(mine) // 2:]
    items = list(data.items)
    for a, b in zip(late[1:], late, strict=False):
        items[a] = replace(items[a], reading=data.items[b].reading, design=data.design)
    lines = fit(folder, replace(data, items=items), "skip.csv")
    assert [w for w in lines if w.startswith("warning: fault skip: ")
            and "a row skipped on the sheet" in w], lines


@pytest.mark.parametrize("argv", [
    ["compare", "--machines", "1", "--agents", "paper", "--faults", "knock,bump"],
    ["calibrate", "--backend", "exact", "--faults", "bump"],
])
def test_an_unknown_fault_kind_is_refused_in_one_line(argv: list[str]) -> None:
    proc = run(*argv)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.splitlines() == [
        f"orthoglide {argv[0]}: error: --faults: unknown fault kind 'bump'; kinds are knock, "
        "stick, sign, skip, thermal-step, lost-steps"]


def test_a_door_opened_in_a_world_without_a_room_is_refused_in_one_line() -> None:
    proc = run("calibrate", "--backend", "exact", "--conditions", "ideal", "--faults",
               "thermal-step")
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.splitlines() == [
        "orthoglide calibrate: error: faults: 'thermal-step' steps the room's temperature: "
        "it needs conditions 'lab' or 'workshop' with the room effect"]


@pytest.mark.parametrize(("faults", "words"), [
    ("bump", "faults: unknown fault kind 'bump'; kinds are knock, stick, sign, skip"),
    (3, "faults: faults must be a list of fault kinds"),
    (["knock", 1], "faults: faults must be a list of fault kinds"),
])
def test_the_env_refuses_an_unknown_fault(faults, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        gym.make(orthoglide_env.LAB_ENV_ID, conditions="lab", faults=faults)
