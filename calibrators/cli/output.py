"""How ``calibrate`` and ``fit`` show an estimate: a JSON object or a table."""

from __future__ import annotations

import json

from orthoglide_env.geometry import MachineParams
from orthoglide_env.scoring import FRAMES, score

from ..base import Estimate
from ..prediction import predicted_correction, predicted_tcp_error


def report(est: Estimate, truth: MachineParams | None) -> dict:
    data = {
        "strategy": est.strategy,
        "params": est.params,
        "estimate": {"drho": est.drho.tolist(), "dL": est.dL.tolist()},
        "std": est.std,
        "residual_rms_mm": est.residual_rms_mm,
        "verification_rms_mm": est.verification_rms_mm,
        "experiment_time_s": est.experiment_time_s,
        "n_readings": est.n_readings,
        "singular_values": est.singular_values.tolist(),
        "condition_number": est.condition_number,
        "crlb": est.crlb.tolist(),
        "weak_directions": est.weak_directions,
        "iterations": est.iterations,
        "predicted_correction_mm": predicted_correction(est).to_dict(),
        "predicted_tcp_std_after_mm": predicted_tcp_error(est).to_dict(),
    }
    if truth is not None:
        report = score(est.machine, truth)
        data["truth"] = {"drho": truth.drho.tolist(), "dL": truth.dL.tolist()}
        data["tcp_error_before_mm"] = report.tcp_before.to_dict()
        data["tcp_error_after_mm"] = report.tcp_after.to_dict()
    return data


def print_table(data: dict) -> None:
    print(f"strategy {data['strategy']}, parameters {data['params']}")
    print(f"{'':8}{'estimate':>10}{'std':>9}" + (f"{'truth':>10}{'error':>10}" if "truth" in data
                                                   else ""))
    for group in ("drho", "dL"):
        for k, axis in enumerate("xyz"):
            est = data["estimate"][group][k]
            std = data["std"][group][k]
            shown = f"{std:9.4f}" if std is not None else "    fixed"
            line = f"{group}_{axis:<4}{est:10.4f}{shown}"
            if "truth" in data:
                true = data["truth"][group][k]
                line += f"{true:10.4f}{est - true:10.4f}"
            print(line)
    print(f"residual RMS {data['residual_rms_mm']:.4f} mm over {data['n_readings']} readings"
          + (f"; held-out repetitions {data['verification_rms_mm']:.4f} mm"
             if data["verification_rms_mm"] is not None else ""))
    print("singular values " + ", ".join(f"{s:.4g}" for s in data["singular_values"])
          + f" (condition {data['condition_number']:.1f})")
    print("Cramér-Rao bound (mm) " + ", ".join(f"{c:.4f}" for c in data["crlb"]))
    for weak in data["weak_directions"]:
        print("weakly identified: " + " ".join(f"{v:+.2f} {k}" for k, v in weak.items()))
    print(f"experiment time {data['experiment_time_s']:.0f} s")
    print("TCP error over the workspace (mm, RMS / max): raw = world frame, then after the "
          "best-fit translation and rigid motion")
    print(f"{'':22}" + "".join(f"{frame:>19}" for frame in FRAMES))
    rows = [("predicted correction", "predicted_correction_mm"),
            ("predicted after (std)", "predicted_tcp_std_after_mm"),
            ("before", "tcp_error_before_mm"), ("after", "tcp_error_after_mm")]
    for label, key in rows:
        if key in data:
            print(f"{label:22}" + "".join(f"{data[key][f]['rms']:10.4f} /{data[key][f]['max']:7.4f}"
                                          for f in FRAMES))


def emit(data: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(data, indent=2))
    else:
        print_table(data)
