"""The command lines of the README and ``docs/*.md`` parse, and those that can run here run
on a tiny case, so that the documentation cannot go stale silently.

Every ``orthoglide ...`` line of a fenced code block is taken (a trailing ``\\`` or an
indented ``[`` line continues it), and every inline code span that gives a command with
options. A synopsis is expanded: the line without its optional ``[...]`` groups, then
with each group (each ``A | B`` alternative of a group, each ``a|b`` value) in turn.
Each variant must parse, and every value a synopsis offers for an option must be one the
option's ``--help`` names. A line with a placeholder (``FILE``, ``MM``, ``...``) is a
synopsis, only parsed; each variant of a concrete line of a code block is run, with at
most one machine, one job and ten minutes of lab time, in a fresh folder holding the
``m.json`` and ``r.csv`` the documents use (a command that several lines give alike, for
the first of them). Inline spans are the measured runs behind the tables (minutes): parsed
only.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json
import re
import shlex
import shutil
from pathlib import Path
from typing import Any

import pytest
from conftest import TABLE1 as TABLE1_ERRORS
from conftest import script_help

from calibrators.agents.names import POLICY_PREFIX
from calibrators.cli import build_parser, main
from calibrators.study.engines import ray_available

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: The paper's Table 1 machine: the documents' ``m.json``.
TABLE1 = json.dumps(TABLE1_ERRORS)
#: Options whose value is cut down to keep each run small.  The lab time is given where a
#: command takes it and a line leaves it at its default hour: a planning agent's plan and a
#: random agent's play grow with it (the documents' one-hour lines took 12 to 42 CPU-s, a
#: quarter hour 4 to 15, ten minutes 23 CPU-s for all of them where a quarter hour took
#: 28), while the options and the paths a command takes are those of any budget.
#: Hour-long plans are played in tests/test_plan.py and tests/test_design.py.
TINY = {"--machines": "1", "--jobs": "1", "--budget": "600"}
PLACEHOLDER = re.compile(r"\.\.\.|\b[A-Z][A-Z_]*\b")


def _fenced_lines(text: str) -> list[tuple[int, str]]:
    """``(line number, command)`` of every ``orthoglide`` line in a fenced code block."""
    out: list[tuple[int, str]] = []
    fence = False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.rstrip()
        if line.lstrip().startswith("```"):
            fence = not fence
            continue
        if not fence:
            continue
        continued = out and (out[-1][1].endswith("\\") or (
            line.startswith(" ") and line.lstrip().startswith("[")))
        if continued:
            out[-1] = (out[-1][0], out[-1][1].removesuffix("\\").rstrip() + " " + line.strip())
        elif line.startswith("orthoglide "):
            out.append((number, line))
    return out


def _inline_commands(text: str) -> list[tuple[int, str]]:
    """``(line number, command)`` of inline code spans that give a command with options."""
    commands = _commands()
    out = []
    for match in re.finditer(r"(?<!`)`(orthoglide [^`]+)`(?!`)", text):
        words = match.group(1).split()
        if len(words) > 2 and words[1] in commands and "--" in match.group(1):
            out.append((text.count("\n", 0, match.start()) + 1, " ".join(words)))
    return out


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


@functools.cache
def _parser() -> argparse.ArgumentParser:
    """The command line's parser, built once per process: parsing reads it and changes
    nothing, and each case asked for it three times (4 ms a build)."""
    return build_parser()


def _commands() -> dict[str, argparse.ArgumentParser]:
    return dict(_subparsers(_parser()).choices)


def _without_code_blocks(text: str) -> str:
    """``text`` with each fenced block's lines blanked (line numbers kept)."""
    return re.sub(r"^```.*?^```", lambda m: "\n" * m.group(0).count("\n"), text,
                  flags=re.S | re.M)


def _variants(line: str) -> list[list[str]]:
    """The concrete argument lists a (synopsis) line stands for, ``orthoglide`` left out."""
    words = shlex.split(line, comments=True)[1:]
    base: list[str] = []
    groups: list[list[list[str]]] = []  # each group: its alternatives
    group: list[str] | None = None
    for word in words:
        if group is None and word.startswith("["):
            group, word = [], word[1:]
        if group is None:
            base.append(word)
            continue
        closed = word.endswith("]")
        group.append(word.removesuffix("]"))
        if closed:
            alternatives, current = [], []
            for w in group:
                if w == "|":
                    alternatives.append(current)
                    current = []
                elif w:
                    current.append(w)
            groups.append([*alternatives, current])
            group = None
    assert group is None, f"unclosed [ in {line!r}"
    out = _values(base)
    for alternatives in groups:
        for words_ in alternatives:
            out += [out[0] + variant for variant in _values(words_)]
    return out


def _values(words: list[str]) -> list[list[str]]:
    """``words`` once with the first value of every ``a|b`` word, then once per further
    value of each such word."""
    first = [w.split("|")[0] if "|" in w else w for w in words]
    out = [first]
    for k, word in enumerate(words):
        for value in word.split("|")[1:] if "|" in word else []:
            out.append([*first[:k], value, *first[k + 1:]])
    return out


def _option_of(parser: argparse.ArgumentParser, argv: list[str], k: int
               ) -> argparse.Action | None:
    """The option whose value ``argv[k]`` is, if any (``-20`` is a number, not an option)."""
    for j in range(k - 1, -1, -1):
        if argv[j].startswith("-") and not re.fullmatch(r"-\d.*", argv[j]):
            action = parser._option_string_actions.get(argv[j])
            if action is None or action.nargs == 0:
                return None
            if action.nargs in ("*", "+"):
                return action
            takes = action.nargs if isinstance(action.nargs, int) else 1
            return action if k - j <= takes else None
    return None


def _cases() -> list[tuple[str, str, list[str], bool]]:
    cases = []
    for document in DOCUMENTS:
        text = document.read_text()
        name = document.relative_to(ROOT).as_posix()
        for runnable, found in ((True, _fenced_lines(text)),
                                (False, _inline_commands(_without_code_blocks(text)))):
            for number, line in found:
                for k, argv in enumerate(_variants(line)):
                    cases.append((f"{name}:{number}#{k}", line, argv, runnable))
    return cases


CASES = _cases()


def test_the_documents_give_commands_of_every_kind() -> None:
    # The collection itself works: a change of the documents' layout that hid their
    # commands would otherwise pass as "nothing to check".
    seen = {argv[0] for _, _, argv, _ in CASES}
    assert {"pose", "render", "urdf", "calibrate", "fit", "compare", "--version"} <= seen
    assert any(not runnable for *_, runnable in CASES)


def _check_offered_values(parser: argparse.ArgumentParser, line: str, argv: list[str]
                          ) -> None:
    """Every value the line offers as ``a|b`` for an option is one its help names."""
    words = shlex.split(line, comments=True)[1:]
    flat = [w.strip("[]") for w in words if w.strip("[]") not in ("", "|")]
    for k, word in enumerate(flat):
        if "|" not in word:
            continue
        action = _option_of(parser, flat, k)
        assert action is not None, f"{word!r} in {line!r} is no option's value"
        help_text = (action.help or "") % {"default": action.default}
        for value in word.split("|"):
            if action.choices is not None:
                assert value in action.choices, f"{action.option_strings[0]} {value}"
            elif not PLACEHOLDER.search(value) or value.startswith(POLICY_PREFIX):
                # A name, not part of a longer one ("optimal" is not "optimal-d").
                named = re.search(rf"(?<![\w-]){re.escape(value)}(?![\w-])", help_text)
                assert named, f"{action.option_strings[0]} {value}: not in its help"


def _parse_only(argv: list[str]) -> None:
    """Parse ``argv`` with every placeholder replaced by a value its option accepts."""
    parser = _parser()
    sub = _commands().get(argv[0])
    filled = []
    for k, word in enumerate(argv):
        if k and PLACEHOLDER.search(word):
            action = _option_of(sub, argv, k) if sub else None
            choices = action.choices if action is not None else None
            word = str(next(iter(choices))) if choices else "1"
        filled.append(word)
    try:
        parser.parse_args(filled)
    except SystemExit as ended:
        assert ended.code == 0, f"orthoglide {' '.join(filled)} does not parse"


def _cannot_run_here(argv: list[str]) -> str:
    """Why a concrete command cannot run in a test here ("" if it can)."""
    if "--engine" in argv and argv[argv.index("--engine") + 1] == "ray" and not (
            ray_available()):
        return "the extra 'ray' is not installed"
    for option in ("--agents", "--agent"):
        if option in argv:
            for agent in argv[argv.index(option) + 1].split(","):
                if agent.startswith(POLICY_PREFIX) and not (
                        (ROOT / agent[len(POLICY_PREFIX):]).exists()
                        and importlib.util.find_spec("stable_baselines3")):
                    return f"{agent} needs its file and the extra 'rl'"
    return ""


def _tiny(argv: list[str]) -> list[str]:
    """``argv`` cut down (:data:`TINY`); a policy or example file (the documents give
    paths from the repository's top) found from the repository."""
    out = [str(ROOT / w) if "/" in w and (ROOT / w).is_file() else w for w in argv]
    for k, word in enumerate(argv[:-1]):
        if word in TINY and float(argv[k + 1]) > float(TINY[word]):
            out[k + 1] = TINY[word]
        if word in ("--agents", "--agent"):
            out[k + 1] = ",".join(
                POLICY_PREFIX + str(ROOT / a[len(POLICY_PREFIX):])
                if a.startswith(POLICY_PREFIX) else a for a in argv[k + 1].split(","))
    command = _commands().get(argv[0])
    if command is not None and "--budget" in command._option_string_actions and (
            "--budget" not in argv):
        out += ["--budget", TINY["--budget"]]
    return out


@pytest.fixture(scope="session")
def documents_folder(tmp_path_factory) -> Path:
    """The files the documents' commands read: ``m.json`` and a measurement file
    ``r.csv``."""
    folder = tmp_path_factory.mktemp("documents")
    (folder / "m.json").write_text(TABLE1)
    assert main(["calibrate", "--backend", "exact", "--machine", str(folder / "m.json"),
                 "--sigma", "0.01", "--save-measurements", str(folder / "r.csv")]) == 0
    return folder


def _runs(line: str, runnable: bool) -> bool:
    """Whether the test runs the line's variants: a line of a code block with no
    placeholder anywhere (one with a placeholder is a synopsis, only parsed)."""
    return runnable and not any(PLACEHOLDER.search(w) for w in shlex.split(line, comments=True))


def _first_runs(cases: list[tuple[str, str, list[str], bool]]) -> dict[tuple[str, ...], str]:
    """Each distinct command the documents run here, as :func:`_tiny` cuts it, with the
    case that gives it first.  A later line of the same words, run in a fresh folder of the
    same files, would repeat that run (``plan --agent paper --out plan --pdf`` is on two
    pages, 3 to 4 CPU-s a run), so it is parsed and checked only."""
    first: dict[tuple[str, ...], str] = {}
    for where, line, argv, runnable in cases:
        if _runs(line, runnable) and not _cannot_run_here(argv):
            first.setdefault(tuple(_tiny(argv)), where)
    return first


FIRST_RUN = _first_runs(CASES)


def _executes(where: str, line: str, argv: list[str], runnable: bool) -> bool:
    """Whether the test runs the case's command: a line it runs (:func:`_runs`) that can
    run here, the first to give its command (:data:`FIRST_RUN`)."""
    return (_runs(line, runnable) and not _cannot_run_here(argv)
            and FIRST_RUN[tuple(_tiny(argv))] == where)


#: Agents that design their experiment before the first reading: a line that plays one
#: costs a plan of up to half a CPU-minute, whatever its command.
PLANNING = ("optimal", "active")


def _plans(argv: list[str]) -> bool:
    """Whether ``argv`` runs a comparison or an agent of :data:`PLANNING`."""
    agents = [a for option in ("--agents", "--agent") if option in argv
              for a in argv[argv.index(option) + 1].split(",")]
    return argv[0] == "compare" or any(a.startswith(PLANNING) for a in agents)


def _scheduled(case: tuple[str, str, list[str], bool]) -> Any:
    """``case`` as a parameter; a comparison or a planning agent it runs is marked
    ``slow`` (scheduled first: a calibration with ``optimal`` alone took 55 s of a loaded
    suite's wall time, and handed out among the last short tests such a line would keep one
    worker busy while the other idles)."""
    slow = _plans(case[2]) and _executes(*case)
    return pytest.param(*case, id=case[0], marks=[pytest.mark.slow] if slow else [])


@pytest.mark.parametrize(("where", "line", "argv", "runnable"), map(_scheduled, CASES))
def test_a_documented_command_works(where: str, line: str, argv: list[str], runnable: bool,
                                    documents_folder: Path, tmp_path: Path,
                                    monkeypatch, capsys) -> None:
    commands = _commands()
    assert argv[0] in commands or argv[0].startswith("-"), f"{where}: no command {argv[0]}"
    if argv[0] in commands:
        _check_offered_values(commands[argv[0]], line, argv)
    _parse_only(argv)
    if not _executes(where, line, argv, runnable):
        return
    for name in ("m.json", "r.csv"):
        shutil.copy(documents_folder / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    try:
        status = main(_tiny(argv))
    except SystemExit as ended:  # --version and --help end in argparse
        status = ended.code
    out = capsys.readouterr()
    assert status == 0, f"{where}: orthoglide {' '.join(argv)}: {out.err}"


#: The repository's folders (the README's layout): a documented path that starts with one
#: names a file of the repository.  Others (``results/``) are what commands write.
FOLDERS = ("orthoglide_env", "calibrators", "tests", "benchmarks", "examples", "docs", "urdf")


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_every_repository_path_a_document_names_exists(document: Path) -> None:
    text = document.read_text()
    spans = re.findall(r"`([\w./-]+)`", text) + re.findall(r"\]\(([^)#\s]+)", text)
    named = {p for p in spans if p.split("/")[0] in FOLDERS and "/" in p}
    assert named, document  # the pattern still finds the document's paths
    missing = sorted(p for p in named if not (document.parent / p).exists()
                     and not (ROOT / p).exists())
    assert not missing, f"{document.name} names files that do not exist: {missing}"


def _script_lines() -> list[tuple[str, str]]:
    """``(where, command)`` of every ``python examples/...`` or ``python benchmarks/...``
    line of a fenced block and inline span of the documents."""
    out = []
    for document in DOCUMENTS:
        text = document.read_text()
        name = document.relative_to(ROOT).as_posix()
        for number, raw in enumerate(text.splitlines(), start=1):
            if re.match(r"python (examples|benchmarks)/", raw):
                out.append((f"{name}:{number}", raw))
        for match in re.finditer(r"(?<!`)`(python (?:examples|benchmarks)/[^`]+)`(?!`)",
                                 _without_code_blocks(text)):
            out.append((f"{name}:{text.count(chr(10), 0, match.start()) + 1}",
                        " ".join(match.group(1).split())))
    return out


SCRIPT_LINES = _script_lines()


@pytest.mark.parametrize(("where", "line"), SCRIPT_LINES, ids=[w for w, _ in SCRIPT_LINES])
def test_a_documented_script_takes_its_options(where: str, line: str) -> None:
    """A script a document runs exists, and every option the line gives is one its
    ``--help`` lists (the scripts run for minutes: tests/test_scripts_start.py starts
    each one)."""
    words = shlex.split(line, comments=True)
    script = words[1]
    assert (ROOT / script).is_file(), f"{where}: no script {script}"
    done = script_help(script)
    assert done.returncode == 0, f"{script} --help: {done.stderr.splitlines()[-1:]}"
    help_text = done.stdout
    for word in words[2:]:
        option = word.split("=")[0]
        if option.startswith("--"):
            assert re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", help_text), \
                f"{where}: {script} has no option {option}"


def test_the_documents_run_scripts() -> None:
    # The collection itself works: the documents name scripts of both folders.
    assert {line.split()[1].split("/")[0] for _, line in SCRIPT_LINES} == {
        "examples", "benchmarks"}
