"""``benchmarks/headline.py`` tables folders that ran different agents side by side.

A pair the issue asks for (a reference procedure with ``active``) runs in its own folder,
so the headline's folders often hold different agents: each row is an agent any folder
ran, and a folder that did not run it shows a dash instead of stopping.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import command_here

ROOT = Path(__file__).resolve().parent.parent


def run(*args: str) -> subprocess.CompletedProcess:
    """A command from the top of the tree, as a user runs it."""
    return subprocess.run([sys.executable, *args], capture_output=True, text=True,
                          timeout=300, cwd=ROOT)


def test_folders_of_different_agents_and_budgets_share_one_table(tmp_path: Path) -> None:
    # The folders are made in this process (``command_here``); the script is what is
    # tested, as a user runs it.
    for agent, budget in (("paper", "3600"), ("random", "330")):
        done = command_here(["compare", "--machines", "2", "--seed", "1", "--agents", agent,
                             "--estimators", "paper6", "--budget", budget, "--conditions",
                             "ideal", "--jobs", "1", "--quiet", "--out", str(tmp_path / agent)])
        assert done.returncode == 0, done.stderr
    done = run("benchmarks/headline.py", str(tmp_path / "paper"), str(tmp_path / "random"))
    assert done.returncode == 0, done.stderr
    header, _, *rows = done.stdout.splitlines()
    assert "ideal 1 h:" in header and "ideal 330 s:" in header
    cells = {row.split(" | ")[0].strip("| `"): row.split(" | ")[2:] for row in rows}
    assert set(cells) == {"paper", "random"}
    # Each agent ran in one folder only: its other cell is the dash, never a number.
    assert cells["paper"][1].startswith("–") and not cells["paper"][0].startswith("–")
    assert cells["random"][0].startswith("–") and not cells["random"][1].startswith("–")
