"""The ``orthoglide`` command: outputs, JSON keys, and one-line errors on bad input."""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import TABLE1 as TABLE1_ERRORS
from conftest import command_here

from calibrators.cli import build_parser, main
from calibrators.study.compare import Trial
from orthoglide_env.model.errors import ERROR_NAMES, error_group

TABLE1 = json.dumps(TABLE1_ERRORS)


@pytest.fixture
def machine_file(tmp_path):
    path = tmp_path / "machine.json"
    path.write_text(TABLE1)
    return str(path)


def run_json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_pose_json(capsys, machine_file) -> None:
    out = run_json(capsys, ["pose", "--machine", machine_file, "--rho", "5", "-5", "0",
                            "--noise-free", "--json"])
    assert set(out) >= {"tcp", "tcp_model", "loop_residual_mm", "gauges"}
    assert max(abs(a - b) for a, b in zip(out["tcp"], out["tcp_model"], strict=True)) < 1e-3
    assert [(g["leg"], g["axis"]) for g in out["gauges"]] == [
        ("x", "y"), ("x", "z"), ("y", "x"), ("y", "z"), ("z", "x"), ("z", "y")]
    assert all(set(g) >= {"leg", "axis", "reading", "valid"} for g in out["gauges"])


def test_pose_json_stdout_is_pure_json(machine_file) -> None:
    # PyBullet's C code prints banners on import and connect; none may reach stdout.
    proc = subprocess.run([sys.executable, "-m", "calibrators.cli", "pose", "--machine",
                           machine_file, "--rho", "0", "0", "0", "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0
    assert json.loads(proc.stdout)["loop_residual_mm"] < 1e-3


def test_render_writes_a_png(tmp_path, machine_file, capsys) -> None:
    out = tmp_path / "m.png"
    assert main(["render", "--machine", machine_file, "--rho", "0", "0", "0", "--out",
                 str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


FRAME_SHAPE = {"raw": {"rms", "max"}, "translation": {"rms", "max"},
               "rigid": {"rms", "max"}}


@pytest.mark.parametrize("solver", ["gauss-newton", "scipy"])
def test_calibrate_json_contract_and_exact_recovery(capsys, machine_file, solver) -> None:
    """A machine file defines every true error: no installation error, no noise unless
    asked, so an exact-model fit of the paper's six parameters recovers Table 1 to the
    issue's 1e-6 mm (the default frees every error, which 66 readings cannot all tell)."""
    out = run_json(capsys, ["calibrate", "--machine", machine_file, "--backend", "exact",
                            "--solver", solver, "--params", "paper6", "--conditions", "ideal",
                            "--json"])
    assert set(out) >= {"estimate", "std", "chi2_dof", "warnings", "residuals", "identifiable",
                        "predicted_tcp_error_mm", "truth", "tcp_error_before_mm",
                        "tcp_error_after_mm"}
    for group in ("drho", "dL"):
        assert np.abs(np.subtract(out["estimate"][group], out["truth"][group])).max() < 1e-6
    assert set(out["truth"]) == {"drho", "dL", "axis_tilt", "axis_offset", "attach"}
    for key in ("tcp_error_before_mm", "tcp_error_after_mm", "predicted_correction_mm",
                "predicted_tcp_error_mm"):
        assert {f: set(v) for f, v in out[key].items()} == FRAME_SHAPE
    for frame in ("raw", "translation", "rigid"):
        assert out["tcp_error_after_mm"][frame]["max"] < 1e-5
        assert out["tcp_error_before_mm"][frame]["rms"] > 1e-3
    assert out["warnings"] == [] and len(out["identifiable"]) == 6
    assert len(out["residuals"]) == 66  # the lab reads every gauge at reset, then the 60
    assert all(set(r) >= {"posture", "gauge", "residual_mm", "outlier"}
               for r in out["residuals"])


def test_the_default_fit_frees_every_error(capsys) -> None:
    """Without --params the exact-model fit is ``full``: under ideal conditions every
    error of ``extended`` and nothing more, so the same numbers; the paper's linear fit
    keeps its six."""
    base = ["calibrate", "--seed", "3", "--backend", "exact", "--conditions", "ideal", "--json"]
    default = run_json(capsys, base)
    extended = run_json(capsys, [*base, "--params", "extended"])
    assert default["params"] == "full" and default["free"] == extended["free"]
    assert default["estimate"] == extended["estimate"] and default["std"] == extended["std"]
    assert run_json(capsys, [*base, "--strategy", "paper"])["params"] == "paper6"


def test_calibrate_table_and_fixed_params(capsys) -> None:
    assert main(["calibrate", "--seed", "3", "--params", "drho", "--backend", "exact"]) == 0
    text = capsys.readouterr().out
    assert "fixed" in text and "TCP error over the workspace" in text
    # The paper6 fit of a realistic machine is rejected by the chi-square test, and says
    # so in the table as in JSON.
    paper6 = ["calibrate", "--seed", "3", "--backend", "exact", "--params", "paper6"]
    assert main(paper6) == 0
    text = capsys.readouterr().out
    out = run_json(capsys, [*paper6, "--json"])
    assert out["chi2_dof"] > 5 and "try --params extended" in out["warnings"][0]
    assert f"warning: {out['warnings'][0]}" in text.splitlines()


def test_saved_measurements_fit_to_the_same_estimate(tmp_path, capsys) -> None:
    """`calibrate --save-measurements` writes what `fit` reads: the same readings give the
    same estimate, and a fit of a file has no truth to score against."""
    path = tmp_path / "readings.csv"
    cal = run_json(capsys, ["calibrate", "--seed", "4", "--backend", "exact", "--params",
                            "extended", "--save-measurements", str(path), "--json"])
    # The lab's notebook keeps when each reading was taken.
    assert path.read_text().splitlines()[0].split(",")[-2:] == ["reading_mm", "time_s"]
    sigma = ["--sigma", "0.02", "--resolution", "0.01"]
    out = run_json(capsys, ["fit", str(path), "--params", "extended", *sigma, "--json"])
    assert "truth" not in out and "tcp_error_after_mm" not in out and out["n_readings"] == 66
    for group in ("drho", "dL", "attach"):
        np.testing.assert_allclose(out["estimate"][group], cal["estimate"][group], atol=1e-9)
    # Instead of errors against a truth: what the compensation will change, and how sure.
    assert out["predicted_correction_mm"]["rigid"]["rms"] > 0.1
    assert 0 < out["predicted_tcp_error_mm"]["rigid"]["rms"] < 0.2
    assert all("line" in r for r in out["residuals"])
    # A slip of the pen on line 20: named by its line and cause, with its residual against
    # the fit without it, in JSON and in the table.
    lines = path.read_text().splitlines()
    cells = lines[19].split(",")
    cells[9] = repr(float(cells[9]) + 0.5)
    lines[19] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    out = run_json(capsys, ["fit", str(path), "--params", "extended", *sigma, "--json"])
    flagged = [r for r in out["residuals"] if r["outlier"]]
    assert [(r["line"], r["cause"]) for r in flagged] == [(20, "reading")]
    assert 0.45 < flagged[0]["residual_mm"] < 0.55
    assert main(["fit", str(path), "--params", "extended", *sigma]) == 0
    text = capsys.readouterr().out
    assert "outlier: line 20" in text and "mistyped or misread" in text and "None" not in text


def strict_json(text: str) -> object:
    """``text`` parsed as strict JSON: ``NaN`` and ``Infinity`` are refused."""
    def refuse(token: str) -> None:
        raise AssertionError(f"{token} is not JSON")

    return json.loads(text, parse_constant=refuse)


def options_of(command: str) -> set[str]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {o for a in sub.choices[command]._actions for o in a.option_strings}


def test_compare_writes_table_csv_and_plots(tmp_path, capsys) -> None:
    assert main(["compare", "--machines", "2", "--agents", "paper,tracker", "--estimators",
                 "paper,paper6,extended", "--conditions", "ideal", "--quiet", "--out",
                 str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "TCP after (rigid) med" in text and "tracker x paper: 2 of 2 failed" in text
    # What a failure suggests exists.
    named = set(re.findall(r"--[a-z][\w-]*", text))
    assert "--estimators" in named and named <= options_of("compare"), named
    for name in ("trials.jsonl", "summary.csv", "accuracy_vs_time.png", "boxes.png"):
        assert (tmp_path / name).stat().st_size > 0
    # Every row of the summary names the world its numbers hold in, as the table does.
    world = "realistic errors, ideal conditions, gauge sigma 0.02 mm, budget 3600 s, exact backend"
    assert f"2 machines ({world})" in text
    with (tmp_path / "summary.csv").open() as handle:
        summary_rows = list(csv.DictReader(handle))
    assert len(summary_rows) == 2 * 3 and {r["world"] for r in summary_rows} == {world}
    lines = (tmp_path / "trials.jsonl").read_text().splitlines()
    assert len(lines) == 2 * 2 * 3
    for line in lines:
        trial = strict_json(line)
        if trial["failed"]:
            assert trial["names"] == trial["error"] == trial["std"] == []
            assert trial["predicted_rigid_mm"] is None
            continue
        assert trial["names"] == list(ERROR_NAMES)
        assert len(trial["error"]) == len(trial["std"]) == len(ERROR_NAMES)
        # The paper's six-parameter fits hold every other error fixed: no std, null.
        fixed = [n for n, std in zip(trial["names"], trial["std"], strict=True) if std is None]
        if trial["estimator"] in ("paper", "paper6"):
            assert fixed == [n for n in ERROR_NAMES if error_group(n) not in ("drho", "dL")]
        else:
            assert fixed == []
        # Each best fit includes the one before it (a translation is a rigid motion), up
        # to the fits' round-off (~1e-13 mm, tests/test_scoring.py).
        for when in ("tcp_before", "tcp_after"):
            raw, translation, rigid = (trial[when][f] for f in ("raw", "translation", "rigid"))
            assert rigid <= translation + 1e-11 and translation <= raw + 1e-11


def test_a_trial_line_reads_back_and_earlier_lines_still_read() -> None:
    nan = float("nan")
    trial = Trial("paper", "paper6", 3, time_s=330.0, readings=66,
                  tcp_before={"rigid": 0.6}, tcp_after={"rigid": 0.02},
                  predicted_rigid_mm=0.03, z=[0.5, -1.2], error=[0.1] * len(ERROR_NAMES),
                  std=[0.2] * 6 + [nan] * (len(ERROR_NAMES) - 6), curve=[[82.5, 0.1]])
    line = trial.to_json()
    assert strict_json(line)["std"][6] is None
    assert Trial.from_json(line).to_json() == line
    assert np.isnan(Trial.from_json(line).std[6])
    # Lines written before the names and nulls: NaN tokens, no names.
    earlier = json.dumps(dataclasses.asdict(trial), allow_nan=True)
    assert "NaN" in earlier and Trial.from_json(earlier).to_json() == line
    failed = Trial("tracker", "paper", 3, failed="reads dial gauges only", time_s=330.0)
    assert strict_json(failed.to_json())["predicted_rigid_mm"] is None
    assert Trial.from_json(failed.to_json()).to_json() == failed.to_json()
    with pytest.raises(ValueError, match="error names"):
        Trial.from_json(line.replace('"drho_x"', '"drho_q"'))


def test_resume_refuses_a_trial_of_other_error_names_in_one_line(tmp_path, capsys) -> None:
    argv = ["compare", "--machines", "2", "--agents", "paper", "--estimators", "paper6",
            "--quiet", "--out", str(tmp_path)]
    assert main(argv) == 0
    trials = tmp_path / "trials.jsonl"
    lines = trials.read_text().splitlines()
    trials.write_text("\n".join([lines[0].replace('"drho_x"', '"drho_q"'), *lines[1:]]) + "\n")
    capsys.readouterr()
    assert main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"{trials}:1: not a trial (the trial's error names" in err[0], err


#: Bad command lines (a capitalised word: a file the test writes) and the words of
#: their refusal.
BAD_INPUT = [
    (["pose", "--machine", "MISSING", "--rho", "0", "0", "0"], "not found"),
    (["pose", "--machine", "BAD_KEY", "--rho", "0", "0", "0"], "unknown machine key"),
    (["pose", "--machine", "NOT_NUMBER", "--rho", "0", "0", "0"], "must hold numbers"),
    (["pose", "--machine", "UNASSEMBLABLE", "--rho", "0", "0", "0"], "validity range"),
    (["pose", "--machine", "GOOD", "--rho", "0", "0", "75"], "joint limits"),
    (["render", "--machine", "GOOD", "--rho", "0", "0", "0", "--out", "x.jpg"], ".png"),
    (["calibrate", "--strategy", "oracle"], "unknown strategy"),
    (["calibrate", "--machine", "MISSING"], "not found"),
    (["calibrate", "--sigma", "-1"], "--sigma"),
    (["pose", "--machine", "GOOD", "--rho", "0", "0", "0", "--resolution", "nan"],
     "--resolution"),
    (["calibrate", "--params", "all"], "unknown parameter 'all'"),
    (["calibrate", "--prior", "attach=-1", "--params", "extended"], "must be > 0"),
    (["calibrate", "--fix", "drho_x"], "NAME=NUMBER"),
    (["fit", "GOOD_CSV", "--sigma", "1e308"], "--sigma"),
    (["fit", "MISSING"], "not found"),
    (["fit", "BAD_CSV"], "column 5"),
    (["fit", "GOOD"], ".csv or .json"),
    # What only the exact-model fit can do names the option that chooses it.
    (["calibrate", "--strategy", "paper", "--agent", "tracker", "--backend", "exact",
      "--conditions", "ideal"],
     "reads dial gauges only; the exact-model fit reads a tracker's readings too: use an "
     "exact-model estimator, --estimator paper6 or extended"),
    (["fit", "GOOD_CSV", "--strategy", "paper", "--params", "extended"],
     "not 'extended'; the exact-model fit estimates any parameters: use an exact-model "
     "estimator, --estimator paper6"),
    (["fit", "GOOD_CSV", "--estimator", "paper", "--prior", "none"],
     "the paper's linear fit (eq. 10) takes no prior; the exact-model fit does"),
    (["calibrate", "--estimator", "oracle"], "unknown estimator 'oracle'"),
    (["calibrate", "--estimator", "full", "--strategy", "paper"], "give one"),
    (["fit", "GOOD_CSV", "--holdout", "1.5"],
     "--holdout: estimator 'gauss-newton': parameter 'holdout' must be a number in [0, 1)"),
    (["compare", "--agents", "paper,oracle"], "unknown agent 'oracle'"),
    (["compare", "--agents", ","], "--agents needs"),
    (["compare", "--estimators", "oracle"], "unknown estimator"),
    (["compare", "--seed", "-1"], "--seed"),
    (["compare", "--jobs", "0"], "--jobs"),
    (["compare", "--resume"], "--resume"),
    # A bad --out is refused before any machine is run, not after the whole run.
    (["compare", "--out", "GOOD"], "is not a folder"),
    (["compare", "--machines", "0"], "--machines"),
    (["compare", "--success-mm", "0"], "--success-mm must be a positive"),
    (["compare", "--success-mm", "nan"], "--success-mm must be a positive"),
    (["fit", "GOOD_CSV", "--conditions", "lab"], "needs its time (time_s)"),
    (["fit", "GOOD_CSV", "--left-out", "huge"], "--left-out"),
    (["compare", "--address", "auto"], "--engine ray"),
    (["fit", "GOOD_CSV", "--params", "full", "--node-spacing", "0"],
     "--node-spacing: estimator 'gauss-newton': parameter 'node_spacing' must be None or a "
     "number in (0, inf)"),
    (["fit", "GOOD_CSV", "--params", "full", "--node-spacing", "500"],
     "larger than the drives' travel"),
    (["fit", "GOOD_CSV", "--params", "full", "--terms", "lead,heat"],
     "unknown estimator term(s) ['heat']"),
    (["fit", "GOOD_CSV", "--fit-world", "--terms", "lead"], "not both"),
]
#: Each command's first bad command line.
FIRST_REFUSALS = {argv[0]: argv for argv, _ in reversed(BAD_INPUT)}


@pytest.mark.parametrize(("argv", "fragment"), BAD_INPUT)
def test_bad_input_gives_one_line_and_status_2(tmp_path, argv, fragment: str,
                                               monkeypatch) -> None:
    """Each command's first refusal here starts the command as a user does (its process:
    no traceback, the one line); the others run it in this process (``command_here``)."""
    files = {
        "MISSING": tmp_path / "missing.json",
        "BAD_KEY": '{"drho": [0, 0, 0], "speed": 3}',
        "NOT_NUMBER": '{"drho": [0, "x", 0]}',
        "UNASSEMBLABLE": '{"dL": [-200, -200, -200]}',
        "GOOD": "{}",
        "BAD_CSV": "leg,axis,posture,repetition,reading_mm\nx,y,XMax,1,abc\n",
        "GOOD_CSV": "leg,axis,posture,repetition,reading_mm\nx,y,Zero,1,0.0\nx,y,XMax,1,0.1\n",
    }
    resolved = []
    for arg in argv:
        if arg in files and isinstance(files[arg], str):
            path = tmp_path / (f"{arg}.csv" if arg.endswith("CSV") else f"{arg}.txt")
            path.write_text(files[arg])
            resolved.append(str(path))
        elif arg in files:
            resolved.append(str(files[arg]))
        else:
            resolved.append(arg)
    if argv == FIRST_REFUSALS[argv[0]]:
        proc = subprocess.run([sys.executable, "-m", "calibrators.cli", *resolved],
                              capture_output=True, text=True, timeout=120, cwd=tmp_path)
    else:
        monkeypatch.chdir(tmp_path)
        proc = command_here(resolved)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("orthoglide") and fragment in lines[0], lines


def test_calibrates_left_out_preset_follows_the_machines(capsys) -> None:
    """A machine drawn from ``--errors paper`` has none of the errors ``paper6`` leaves
    out: by default the fit's error bars are those of ``--left-out paper``, as
    ``compare``'s are, and narrower than a realistic machine's would be (the left-out
    errors' spread widens them)."""
    def fitted(*extra: str) -> dict:
        assert main(["calibrate", "--errors", "paper", "--params", "paper6", "--seed", "1",
                     "--conditions", "ideal", "--json", *extra]) == 0
        return json.loads(capsys.readouterr().out)

    default, paper, realistic = fitted(), fitted("--left-out", "paper"), fitted(
        "--left-out", "realistic")
    assert default == paper
    for group in ("drho", "dL"):
        assert all(p < r for p, r in zip(paper["std"][group], realistic["std"][group],
                                         strict=True))
