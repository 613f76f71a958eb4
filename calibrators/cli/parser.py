"""The command line's parser and its one kind of user error, light to import: ``--help``
and ``--version`` need nothing else."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import NoReturn


class UsageError(Exception):
    """Bad input from the user: reported in one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """Reports a bad command line in one line (argparse adds a usage block; ``-h`` has it)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


class Listed:
    """The names a help text lists as ``%(listed)s``, asked for when the help is shown: a
    registry lists its names by importing every module of its package (each agent's
    planner and SciPy's linear algebra), which a command that runs does not need."""

    def __init__(self, names: Callable[[], list[str]]) -> None:
        self.names = names

    def __str__(self) -> str:
        return ", ".join(self.names())


def listing(action: argparse.Action, names: Callable[[], list[str]]) -> None:
    """Let the help of ``action`` list ``names()`` where it says ``%(listed)s``."""
    # argparse fills a help's %(...)s from the action's attributes, when it formats it.
    action.listed = Listed(names)  # type: ignore[attr-defined]
