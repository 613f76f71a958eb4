"""The command line's parser and its one kind of user error, light to import: ``--help``
and ``--version`` need nothing else."""

from __future__ import annotations

import argparse
from typing import NoReturn


class UsageError(Exception):
    """Bad input from the user: reported in one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """Reports a bad command line in one line (argparse adds a usage block; ``-h`` has it)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")
