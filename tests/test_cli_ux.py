"""The ``orthoglide`` command as a user meets it: version, help, pipes, bounds, JSON."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
from conftest import command_here

import calibrators.cli
from calibrators.cli import COMMANDS, build_parser, command_module, main
from calibrators.cli.common import print_json

CLI = [sys.executable, "-m", "calibrators.cli"]


@pytest.fixture
def machine_file(tmp_path) -> str:
    path = tmp_path / "machine.json"
    path.write_text('{"drho": [1.0, -0.5, 0.2]}')
    return str(path)


def test_version_comes_from_the_package_metadata() -> None:
    proc = subprocess.run([*CLI, "--version"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stderr == ""
    assert proc.stdout == f"orthoglide {metadata.version('orthoglide-workbench')}\n"


def _listed_commands() -> list[str]:
    """The sub-commands ``orthoglide --help`` lists (its ``{pose,render,...}`` line), so a
    command added later is tested without being named here."""
    text = build_parser().format_help()
    listed = re.search(r"\{([\w,-]+)\}", text)
    assert listed, text
    return listed.group(1).split(",")


def test_the_help_lists_every_command_module() -> None:
    """Every module of the package whose ``add`` makes a command (sets ``func``) is listed,
    and every listed command has one."""
    package = Path(calibrators.cli.__file__).parent
    modules = set()
    for path in package.glob("[!_]*.py"):
        module = command_module(path.stem)
        parser = argparse.ArgumentParser()
        if hasattr(module, "add"):
            module.add(parser)
            if parser.get_default("func") is not None:
                modules.add(path.stem)
    assert set(_listed_commands()) == set(COMMANDS) == modules


@pytest.mark.parametrize("command", _listed_commands())
def test_every_command_has_a_working_help(command: str, capsys) -> None:
    with pytest.raises(SystemExit) as ended:
        main([command, "--help"])
    assert ended.value.code == 0
    out = capsys.readouterr()
    assert out.err == "" and out.out.startswith(f"usage: orthoglide {command}")
    # Every option the parser knows is explained in the text the user reads.
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for action in sub.choices[command]._actions:
        for option in action.option_strings:
            assert option in out.out, (command, option)


@pytest.mark.parametrize(("argv", "status"), [
    # argparse prints help and version itself and ignores a failed write to stdout.
    (["--help"], 0), (["--version"], 0),
    # Python's documented status for a broken pipe.
    (["urdf", "--machine", "MACHINE", "-o", "-"], 1),
    (["calibrate", "--backend", "exact", "--seed", "1", "--noise-free", "--json"], 1),
])
def test_a_reader_gone_early_ends_the_command_quietly(argv: list[str], status: int,
                                                      machine_file: str) -> None:
    # A pipe whose reading end is closed before the command writes: what `| head` does
    # to the rest of a long output.
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run([*CLI, *(machine_file if a == "MACHINE" else a for a in argv)],
                              stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert proc.stderr == ""
    assert proc.returncode == status


#: Options out of range and the words of their refusal.
OUT_OF_RANGE = [
    (["pose", "--machine", "MACHINE", "--rho", "0", "0", "0", "--sigma", "1e308"],
     "--sigma 1e+308 mm is out of range"),
    (["pose", "--machine", "MACHINE", "--rho", "0", "0", "0", "--sigma", "0.3"],
     "[0, travel/50] = [0, 0.2] mm"),
    (["pose", "--machine", "MACHINE", "--rho", "0", "0", "0", "--resolution", "1e-320"],
     "finer than any dial gauge"),
    (["calibrate", "--backend", "exact", "--sigma", "0.5"], "--sigma 0.5 mm is out of range"),
    (["urdf", "--machine", "MACHINE", "-o", "."], "is a directory"),
]


@pytest.mark.parametrize(("argv", "fragment"), OUT_OF_RANGE)
def test_out_of_range_options_are_refused_in_one_line(argv: list[str], fragment: str,
                                                      machine_file: str) -> None:
    """The first refusal as the command's child process, the others in this process
    (``command_here``)."""
    resolved = [machine_file if a == "MACHINE" else a for a in argv]
    proc = (subprocess.run([*CLI, *resolved], capture_output=True, text=True, timeout=120)
            if argv == OUT_OF_RANGE[0][0] else command_here(resolved))
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and fragment in lines[0], proc.stderr


def test_the_largest_sigma_still_gives_strict_json(capsys, machine_file: str) -> None:
    assert main(["pose", "--machine", machine_file, "--rho", "0", "0", "0", "--sigma", "0.2",
                 "--seed", "1", "--json"]) == 0

    def refuse(token: str) -> None:
        raise AssertionError(f"{token} is not JSON")

    report = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert all(g["reading"] is None or abs(g["reading"]) < 10 for g in report["gauges"])


def test_json_output_refuses_numbers_json_cannot_carry(capsys) -> None:
    for value in (float("nan"), float("inf")):
        with pytest.raises(RuntimeError, match="JSON cannot carry"):
            print_json({"tcp": [0.0, value, 0.0]})
    assert capsys.readouterr().out == ""  # nothing half-written


def _options(command: str) -> list[argparse.Action]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return [a for a in sub.choices[command]._actions if a.option_strings and a.dest != "help"]


@pytest.mark.parametrize("command", ["pose", "render", "urdf"])
def test_every_option_explains_unit_and_default(command: str) -> None:
    assert command in COMMANDS
    for action in _options(command):
        text = action.help % {"default": action.default}
        assert len(text) > 20, action.dest
        if isinstance(action, argparse._StoreTrueAction):
            continue  # a switch: off unless given
        assert "required" in text or re.search(r"default:? \S", text), (action.dest, text)
        if action.type in (float,):
            assert "mm" in text, (action.dest, text)
        if action.metavar == "FILE":
            assert "file" in text.lower(), (action.dest, text)
