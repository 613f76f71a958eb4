"""The documentation site builds with warnings as errors (a broken link, a page left out
of the toctree, a bad directive all fail it), and the README's Python example runs."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_the_site_builds_without_a_warning(tmp_path: Path) -> None:
    pytest.importorskip("myst_parser", reason="the extra 'docs' is not installed")
    pytest.importorskip("furo", reason="the extra 'docs' is not installed")
    built = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(tmp_path / "html")],
        capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr
    index = (tmp_path / "html" / "index.html").read_text(encoding="utf-8")
    # Every page is reached from the front page, and the CLI reference holds every command.
    for page in sorted((ROOT / "docs").glob("*.md")):
        assert page.stem == "index" or f'href="{page.stem}.html"' in index, page.name
    from calibrators.cli import COMMANDS

    reference = (tmp_path / "html" / "reference.html").read_text(encoding="utf-8")
    for command in COMMANDS:
        assert f"usage: orthoglide {command}" in reference, command


def test_the_readmes_example_runs() -> None:
    """The README's one Python block: a lab in the default (real) world takes a move, and
    the six dial gauges of the paper read it, in mm, a fraction of their travel."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1
    scope: dict = {"__name__": "readme"}
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(blocks[0], "README.md", "exec"), scope)
    env = scope["env"]
    assert env.unwrapped.conditions.name == "lab"
    # A 20 mm drive at 20 mm/s and 5 s to settle and read (the time table).
    assert scope["reward"] == pytest.approx(-6.0)
    gauges = scope["obs"]["gauges"]
    assert gauges.shape == (6,) and abs(gauges).max() < env.unwrapped.travel
