"""The ``orthoglide`` command: outputs, JSON keys, and one-line errors on bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from calibrators.cli import main

TABLE1 = '{"drho": [4.66, -5.36, 1.46], "dL": [5.20, -5.96, 3.16]}'


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


def test_calibrate_json_keys_and_exact_recovery(capsys, machine_file) -> None:
    out = run_json(capsys, ["calibrate", "--strategy", "gauss-newton", "--machine", machine_file,
                            "--errors", "paper", "--noise-free", "--backend", "exact", "--json"])
    assert set(out) >= {"strategy", "params", "estimate", "std", "truth", "residual_rms_mm",
                        "tcp_error_before_mm", "tcp_error_after_mm", "experiment_time_s",
                        "n_readings", "singular_values"}
    assert out["estimate"]["drho"] == pytest.approx(out["truth"]["drho"], abs=1e-3)
    assert out["tcp_error_after_mm"]["max"] < 1e-3 < out["tcp_error_before_mm"]["rms"]


def test_calibrate_table_and_fixed_params(capsys) -> None:
    assert main(["calibrate", "--seed", "3", "--params", "drho", "--backend", "exact"]) == 0
    text = capsys.readouterr().out
    assert "fixed" in text and "TCP error over the workspace" in text


def test_fit_from_a_measurement_file(tmp_path, capsys) -> None:
    import gymnasium as gym

    import orthoglide_env
    from calibrators.base import get_strategy

    env = gym.make(orthoglide_env.ENV_ID, backend="exact", errors="paper")
    env.reset(seed=0, options={"machine": json.loads(TABLE1)})
    path = tmp_path / "readings.csv"
    get_strategy("paper").collect(env).to_csv(path)
    env.close()
    out = run_json(capsys, ["fit", str(path), "--json"])
    assert "truth" not in out and "tcp_error_after_mm" not in out and out["n_readings"] == 60
    # Instead of errors against a truth: what the compensation will change, and how sure.
    assert out["predicted_correction_mm"]["rms"] > 1.0
    assert 0 < out["predicted_tcp_std_after_mm"]["rms"] < 0.2
    # Within 5 reported standard deviations of the truth.
    for group in ("drho", "dL"):
        for est, std, true in zip(out["estimate"][group], out["std"][group],
                                  json.loads(TABLE1)[group], strict=True):
            assert abs(est - true) < 5 * std


def test_compare_writes_table_csv_and_plot(tmp_path, capsys) -> None:
    assert main(["compare", "--machines", "4", "--backend", "exact", "--errors", "paper",
                 "--jobs", "1", "--quiet", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "gauss-newton" in text and "paper" in text
    for name in ("trials.csv", "summary.csv", "compare.png"):
        assert (tmp_path / name).stat().st_size > 0


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
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
        (["calibrate", "--params", "all"], "invalid choice"),
        (["fit", "MISSING"], "not found"),
        (["fit", "BAD_CSV"], "column 5"),
        (["compare", "--strategies", "paper,oracle"], "unknown strategy"),
        (["compare", "--machines", "0"], "--machines"),
    ],
)
def test_bad_input_gives_one_line_and_status_2(tmp_path, argv, fragment: str) -> None:
    files = {
        "MISSING": tmp_path / "missing.json",
        "BAD_KEY": '{"drho": [0, 0, 0], "speed": 3}',
        "NOT_NUMBER": '{"drho": [0, "x", 0]}',
        "UNASSEMBLABLE": '{"dL": [-200, -200, -200]}',
        "GOOD": "{}",
        "BAD_CSV": "leg,axis,posture,repetition,reading_mm\nx,y,XMax,1,abc\n",
    }
    resolved = []
    for arg in argv:
        if arg in files and isinstance(files[arg], str):
            path = tmp_path / f"{arg}.txt"
            path.write_text(files[arg])
            resolved.append(str(path))
        elif arg in files:
            resolved.append(str(files[arg]))
        else:
            resolved.append(arg)
    proc = subprocess.run([sys.executable, "-m", "calibrators.cli", *resolved],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("orthoglide") and fragment in lines[0], lines
