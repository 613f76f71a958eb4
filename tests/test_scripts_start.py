"""Every benchmark and example script starts: its ``--help`` exits 0 with a usage line.

Run as a user runs them (``python benchmarks/x.py``), so the script's own folder comes
first on ``sys.path``: a module there named like a standard-library one
(``benchmarks/statistics.py``) must not break an import deep in the package.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import script_help

ROOT = Path(__file__).resolve().parent.parent
#: The scripts: the files there with a ``__main__`` block (the rest are their modules).
SCRIPTS = sorted(p for p in [*ROOT.glob("benchmarks/*.py"), *ROOT.glob("examples/*.py")]
                 if 'if __name__ == "__main__"' in p.read_text())


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_a_script_starts(script: Path) -> None:
    done = script_help(script.relative_to(ROOT).as_posix())
    assert done.returncode == 0, done.stderr.splitlines()[-1:]
    assert "usage:" in done.stdout
