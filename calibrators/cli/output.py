"""How ``calibrate`` and ``fit`` show an estimate: a JSON object or a table.

The JSON object's keys are a contract that scripts rely on: ``estimate`` and ``std``
(parameter values and standard deviations in the machine-file schema, gauge stands under
``stands``), ``chi2_dof``, ``warnings``, ``residuals`` (one object per reading: ``posture``,
``gauge``, ``residual_mm`` (a left-out reading's against the fit without it), ``outlier``,
``cause`` for a flagged reading (``reading``: unlike its repetitions, mistyped or misread;
``unrepeated``: none to tell; ``model``: its repetitions read the same, so the model is
wrong there and the reading is kept), and ``line`` when read from a file),
``identifiable``, ``considered`` (the lab's effects the fit put into its error bars without
fitting them), ``predicted_tcp_error_mm``, and for virtual machines ``truth``,
``tcp_error_before_mm`` and ``tcp_error_after_mm``; each TCP error is
``{"raw": {"rms", "max"}, "translation": {...}, "rigid": {...}}`` in mm.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from calibrators.cli.common import UsageError, print_json
from calibrators.estimators.base import Estimate
from calibrators.estimators.gauss_newton import CAUSE_WORDS
from calibrators.estimators.prediction import predicted_correction, predicted_tcp_error
from calibrators.workflow.compensate import write_estimate
from orthoglide_env.model.compensation import PitchTable
from orthoglide_env.model.errors import (
    AXIS_NAMES,
    ERROR_GROUPS,
    ERROR_NAMES,
    MachineParams,
    error_group,
)
from orthoglide_env.scoring import FRAMES, score
from orthoglide_env.world.machine_file import machine_dict
from orthoglide_env.world.truth import World

#: How many combinations a table lists before it only counts them (JSON lists all).
LISTED: int = 6


def _residuals(est: Estimate) -> list[dict[str, Any]]:
    """One object per reading (exact-model fits) or per difference (the paper's fit)."""
    outliers = dict(zip(est.outliers, zip(est.outlier_causes, est.outlier_residuals,
                                          strict=True), strict=True))
    misfits = set(est.misfits)
    out = []
    if len(est.residuals) == len(est.readings):
        for k, (m, r) in enumerate(zip(est.readings.items, est.residuals, strict=True)):
            cause, left_out = outliers.get(k, (None, r))
            item = {"posture": m.posture, "gauge": m.gauge.slot,
                    "repetition": m.repetition,
                    "residual_mm": None if not np.isfinite(left_out) else float(left_out),
                    "outlier": k in outliers}
            if cause is not None or k in misfits:
                item["cause"] = "model" if k in misfits else cause
            if m.line is not None:
                item["line"] = m.line
            out.append(item)
        return out
    from calibrators.estimators.differences import differences

    rows = differences(est.readings)
    return [{"posture": p, "gauge": g.slot, "residual_mm": float(r),
             "outlier": False}
            for g, p, r in zip(rows.gauges, rows.postures, est.residuals, strict=True)]


def report(est: Estimate, truth: MachineParams | None,
           z_rms: float | None = None, world: World | None = None) -> dict[str, Any]:
    """The JSON-ready report of an estimate (and of its score, when the truth is known, in
    its ``world`` when there is one)."""
    data: dict[str, Any] = {
        "strategy": est.strategy,
        "params": est.params,
        "prior": est.prior,
        "free": est.names,
        "estimate": est.estimate,
        "std": est.std,
        "chi2": est.chi2,
        "dof": est.dof,
        "chi2_dof": est.chi2 / est.dof if est.chi2 is not None and est.dof else None,
        "covariance_scale": est.covariance_scale,
        "warnings": est.warnings,
        "considered": est.considered,
        "identifiable": est.identifiable,
        "unidentifiable": est.unidentifiable,
        "residuals": _residuals(est),
        "residual_rms_mm": est.residual_rms_mm,
        "verification_rms_mm": est.verification_rms_mm,
        "holdout_rms_mm": est.holdout_rms_mm,
        "experiment_time_s": est.experiment_time_s,
        "n_readings": est.n_readings,
        "singular_values": est.singular_values.tolist(),
        # Infinite when some combination is not seen at all (see ``unidentifiable``).
        "condition_number": est.condition_number if np.isfinite(est.condition_number)
        else None,
        "iterations": est.iterations,
        "predicted_correction_mm": predicted_correction(est).to_dict(),
        "predicted_tcp_error_mm": predicted_tcp_error(est).to_dict(),
    }
    table = est.pitch_table
    if table is not None:
        data["pitch_table"] = table.to_dict()
    if est.backlash is not None:
        data["backlash_mm"] = est.backlash
    if truth is not None:
        scored = score(est.machine, truth, world=world,
                       correction=est.lead_correction if est.fits_lead else None)
        # A machine file's object: the truth can be replayed with ``calibrate --machine``.
        data["truth"] = machine_dict(truth, world)
        data["tcp_error_before_mm"] = scored.tcp_before.to_dict()
        data["tcp_error_after_mm"] = scored.tcp_after.to_dict()
        data["z_rms"] = z_rms
    return data


def _flat(schema: dict[str, Any], key: str) -> list:
    return list(np.ravel(np.array(schema[key], dtype=object)))


def print_table(data: dict[str, Any]) -> None:
    print(f"strategy {data['strategy']}, parameters {data['params']}, prior {data['prior']}")
    free = set(data["free"])
    print(f"{'':16}{'estimate':>10}{'std':>9}" + (f"{'truth':>10}{'error':>10}"
                                                   if "truth" in data else ""))
    for group in ERROR_GROUPS:
        names = [n for n in ERROR_NAMES if error_group(n) == group]
        if not free & set(names) and group not in ("drho", "dL"):
            continue
        values, stds = _flat(data["estimate"], group), _flat(data["std"], group)
        truths = _flat(data["truth"], group) if "truth" in data else None
        for k, name in enumerate(names):
            shown = f"{stds[k]:9.4f}" if stds[k] is not None else "    fixed"
            line = f"{name:16}{values[k]:10.4f}{shown}"
            if truths is not None:
                line += f"{truths[k]:10.4f}{values[k] - truths[k]:10.4f}"
            print(line)
    if "stands" in data["estimate"]:
        print(f"gauge stands: {len(data['estimate']['stands'])} mountings estimated "
              "(see --json)")
    if data["chi2_dof"] is not None:
        print(f"chi2/dof {data['chi2_dof']:.2f} ({data['dof']} degrees of freedom)")
    if data["considered"]:
        print(f"in the error bars, not fitted: {', '.join(data['considered'])}")
    if "backlash_mm" in data:
        print("backlash (lost motion per axis, um, +- std): " + ", ".join(
            f"{axis} {v['value'] * 1e3:.1f} +- {v['sigma'] * 1e3:.1f}"
            for axis, v in data["backlash_mm"].items()))
    if "pitch_table" in data:
        table = PitchTable.from_dict(data["pitch_table"])
        print(f"pitch-error tables (um, +- std; {table.spacing:g} mm spacing from "
              f"{table.start:g} mm):")
        print(f"{'':6}" + "".join(f"{rho:>11.0f}" for rho in table.nodes))
        for a, axis in enumerate(AXIS_NAMES):
            print(f"{axis:6}" + "".join(f"{v * 1e3:6.1f}+-{s * 1e3:<3.1f}"
                                        for v, s in zip(table.values[a], table.sigma[a],
                                                        strict=True)))
    print(f"residual RMS {data['residual_rms_mm']:.4f} mm over {data['n_readings']} readings"
          + (f"; held-out repetitions {data['verification_rms_mm']:.4f} mm"
             if data["verification_rms_mm"] is not None else "")
          + (f"; held-out readings {data['holdout_rms_mm']:.4f} mm"
             if data["holdout_rms_mm"] is not None else ""))
    for label, key in (("identified", "identifiable"), ("not identified", "unidentifiable")):
        combos = data[key]
        if combos:
            print(f"{label} by these readings ({len(combos)} combinations):")
            for text in combos[:LISTED]:
                print(f"  {text}")
            if len(combos) > LISTED:
                print(f"  ... and {len(combos) - LISTED} more (see --json)")
    for r in data["residuals"]:
        if "cause" in r:
            where = f"line {r['line']}" if "line" in r else r["gauge"]
            print(f"{'outlier' if r['outlier'] else 'misfit'}: {where} ({r['gauge']}, "
                  f"{r['posture']}): residual {r['residual_mm']:+.4f} mm, "
                  f"{CAUSE_WORDS[r['cause']]}")
    print(f"experiment time {data['experiment_time_s']:.0f} s")
    print("TCP error over the workspace (mm, RMS / max): raw = world frame, then after the "
          "best-fit translation and rigid motion (the headline: what a user who touches off "
          "the workpiece sees)")
    print(f"{'':24}" + "".join(f"{frame:>19}" for frame in FRAMES))
    rows = [("predicted correction", "predicted_correction_mm"),
            ("predicted error after", "predicted_tcp_error_mm"),
            ("before calibration", "tcp_error_before_mm"),
            ("after calibration", "tcp_error_after_mm")]
    for label, key in rows:
        if key in data:
            print(f"{label:24}" + "".join(
                f"{data[key][f]['rms']:10.4f} /{data[key][f]['max']:7.4f}" for f in FRAMES))
    if data.get("z_rms") is not None:
        print(f"z-RMS of the identifiable combinations against the truth: {data['z_rms']:.2f}")
    for event in data.get("faults", ()):
        where = (f"stand {event['mounting']}" if event["stand"] >= 0 else
                 f"joint {event['joint']}" if event["joint"] >= 0 else "the room")
        print(f"fault (the truth): {event['kind']} at step {event['step']} "
              f"({event['time_s']:.0f} s), {where}, size {event['size']:+.4g}")
    # Last, where a reader's eye ends: what the fit says against itself.
    for warning in data["warnings"]:
        print(f"warning: {warning}")


def save(est: Estimate, args: Any) -> None:
    """Write what ``--save-estimate`` and ``--save-pitch-table`` ask for; a usage error
    when the fit has no pitch-error table to write."""
    if args.save_estimate:
        write_estimate(args.save_estimate, est)
    path = args.save_pitch_table
    if not path:
        return
    table = est.pitch_table
    if table is None:
        raise UsageError("--save-pitch-table: this fit has no pitch-error table (fit the "
                         "lead error with --params full or --node-spacing under --conditions "
                         "lab or workshop)")
    Path(path).write_text(table.to_csv())


def emit(data: dict[str, Any], as_json: bool) -> None:
    """Print the report; JSON output never holds NaN or Infinity (not JSON)."""
    if as_json:
        print_json(data)
    else:
        print_table(data)
