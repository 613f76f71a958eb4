"""``benchmarks/buyer.py`` runs the part of the buyer's table it is asked for, and only it.

The whole table is 20 compare runs of every set's agents; ``--agents``, ``--sets`` and
``--budgets`` cut it down.  ``--dry-run`` prints the runs without running them, so these
tests read the commands; the refusals happen before any run.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def buyer(*args: str) -> subprocess.CompletedProcess:
    """``python benchmarks/buyer.py ARGS`` from the top, as a user runs it."""
    return subprocess.run([sys.executable, "benchmarks/buyer.py", *args], capture_output=True,
                          text=True, timeout=120, cwd=ROOT)


def test_a_reduced_table_runs_only_its_cells(tmp_path: Path) -> None:
    done = buyer("--out", str(tmp_path), "--dry-run", "--agents", "optimal", "--sets", "dial",
                 "--budgets", "1", "--machines", "20")
    assert done.returncode == 0, done.stderr
    runs = done.stdout.splitlines()
    # The dial set's rows: dial or digital indicators, on screws or on scales.
    assert len(runs) == 4
    assert {(r.split("--indicator ")[1].split()[0], r.split("--drives ")[1].split()[0])
            for r in runs} == {(i, d) for i in ("dial", "digital") for d in ("screw", "scales")}
    for run in runs:
        assert " --agents optimal " in run and " --instruments dial " in run
        assert " --budget 3600 " in run and " --machines 20 " in run
        # A digital indicator is read as one, not at the dial gauge's scatter and 10 um.
        noise = ("--sigma 0.002 --resolution 0.001" if "--indicator digital" in run
                 else "--sigma 0.02 --resolution 0.01")
        assert noise in run


def test_the_whole_table_runs_every_set_agent(tmp_path: Path) -> None:
    runs = buyer("--out", str(tmp_path), "--dry-run").stdout.splitlines()
    assert len(runs) == 20
    assert sum(" --agents optimal,active,iso230-2,ballbar,tracker " in r for r in runs) == 4


def test_bad_parts_are_refused_in_one_line(tmp_path: Path) -> None:
    for args in (("--sets", "dial,laser"), ("--agents", "iso230-2"), ("--budgets", "1,-3"),
                 ("--budgets", "one")):
        done = buyer("--out", str(tmp_path), "--dry-run", *args)
        assert done.returncode == 2, args
        assert done.stderr.splitlines()[-1].startswith("buyer.py: error: "), args


def test_a_kept_run_of_other_agents_is_not_read_as_the_cell(tmp_path: Path) -> None:
    folder = tmp_path / "dial-dial-screw-1h"
    folder.mkdir()
    (folder / "config.json").write_text(json.dumps({"agents": ["optimal", "active"],
                                                    "machines": 20, "sigma": 0.02,
                                                    "resolution": 0.01}))
    done = buyer("--out", str(tmp_path), "--agents", "optimal", "--sets", "dial",
                 "--budgets", "1", "--machines", "20")
    assert done.returncode == 2
    assert "holds a run of optimal,active on 20 machines" in done.stderr
    # A digital indicator's cell kept from a run at the dial gauge's noise is not read either.
    folder.rename(tmp_path / "dial-digital-screw-1h")
    (tmp_path / "dial-digital-screw-1h" / "config.json").write_text(json.dumps(
        {"agents": ["optimal"], "machines": 20, "sigma": 0.02, "resolution": 0.01}))
    done = buyer("--out", str(tmp_path), "--agents", "optimal", "--sets", "dial",
                 "--budgets", "1", "--machines", "20")
    assert done.returncode == 2
    assert "sigma, resolution 0.02, 0.01 mm" in done.stderr


def test_each_run_is_cut_in_chunks_so_a_resume_loses_little(tmp_path: Path) -> None:
    runs = buyer("--out", str(tmp_path), "--dry-run", "--chunk", "5").stdout.splitlines()
    assert len(runs) == 20 and all(" --chunk 5 " in r for r in runs)
    done = buyer("--out", str(tmp_path), "--dry-run", "--chunk", "0")
    assert done.returncode == 2
    assert "--chunk must be at least 1" in done.stderr


def test_the_table_marks_cells_not_run_and_runs_nothing(tmp_path: Path) -> None:
    # A run cut short (its config kept, no summary) is a cell not run, not read.
    (tmp_path / "dial-dial-screw-1h").mkdir()
    (tmp_path / "dial-dial-screw-1h" / "config.json").write_text(json.dumps(
        {"agents": ["optimal", "active"], "machines": 50, "sigma": 0.02, "resolution": 0.01}))
    done = buyer("--out", str(tmp_path), "--table", "--agents", "optimal,active", "--sets",
                 "dial", "--machines", "50")
    assert done.returncode == 0, done.stderr
    rows = [line for line in done.stdout.splitlines() if line.startswith("| dial |")]
    # The dial set's four rows, each with its 1 h and 3 h cell.
    assert len(rows) == 4 and all(r.count("not run") == 2 for r in rows)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dial-dial-screw-1h"]
    assert not (tmp_path / "dial-dial-screw-1h" / "trials.jsonl").exists()
