"""From an estimate to the controller: compensated commands, joint offsets, pitch-error
tables, backlash values and the calibrated machine.

An *estimate file* (``calibrate``/``fit --save-estimate``) is a machine file of the
estimated machine (``pose --machine est.json`` reads it) whose key ``"calibration"``
holds the fit (:meth:`~calibrators.estimators.base.Estimate.to_dict`: covariance,
readings, gauge stands, the lab's fitted terms), which the compensation needs for its
predicted errors.

The compensated command of a target is the estimated machine's inverse kinematics, less
the fitted lead error at that command when the fit has a pitch-error table (the
controller's pitch-error compensation, :mod:`orthoglide_env.model.compensation`).  Its
predicted error is the estimate's covariance carried to the target
(:func:`~orthoglide_env.scoring.predicted_target_errors`), in the three frames over the
targets given.

:class:`Compensate` (the estimate, and the targets if any) makes the :class:`Controller`:
the joint offsets, the compensation of the targets, and the files a controller takes
(:meth:`Controller.write`).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibrators.estimators.base import Estimate, strict
from orthoglide_env.model.errors import AXIS_NAMES, ERROR_NAMES, MachineFileError, check_validity
from orthoglide_env.scoring import FRAMES, commands, predicted_target_errors
from orthoglide_env.sim.urdf import write_urdf
from orthoglide_env.world.machine_file import CALIBRATION_KEY, machine_dict

#: The columns of a targets file, in mm in the world frame.
TARGET_COLUMNS: tuple[str, ...] = ("x", "y", "z")
#: The targets' columns as commands.csv names them, also read.
TARGET_MM_COLUMNS: tuple[str, ...] = ("x_mm", "y_mm", "z_mm")


def write_estimate(path: str | Path, est: Estimate) -> None:
    """Write the estimate file of ``est`` (strict JSON)."""
    data = {**machine_dict(est.machine, None), CALIBRATION_KEY: strict(est.to_dict())}
    Path(path).write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")


def read_estimate(path: str | Path) -> Estimate:
    """The estimate of an estimate file; ``ValueError`` naming the file when it is none."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: not found") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc.msg}, line {exc.lineno})") from None
    if not isinstance(data, dict) or not isinstance(data.get(CALIBRATION_KEY), dict):
        raise ValueError(f"{path}: not an estimate file (a machine file with the fit under "
                         f"'{CALIBRATION_KEY}', as calibrate or fit --save-estimate writes)")
    return Estimate.from_dict(data[CALIBRATION_KEY])


def read_targets(path: str | Path) -> np.ndarray:
    """The targets (n, 3), mm, of a CSV file with the columns :data:`TARGET_COLUMNS` (or
    :data:`TARGET_MM_COLUMNS`, as commands.csv writes them);
    ``ValueError`` naming the file, line and column of the first fault."""
    try:
        handle = Path(path).open(newline="", encoding="utf-8-sig")
    except FileNotFoundError:
        raise ValueError(f"{path}: not found") from None
    with handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        columns = (TARGET_MM_COLUMNS if set(TARGET_MM_COLUMNS) <= set(header)
                   and not set(TARGET_COLUMNS) & set(header) else TARGET_COLUMNS)
        missing = [c for c in columns if c not in header]
        if missing:
            raise ValueError(f"{path}: the header needs the columns {', '.join(TARGET_COLUMNS)}"
                             f" (or {', '.join(TARGET_MM_COLUMNS)}; missing "
                             f"{', '.join(missing)})")
        out = []
        for row in reader:
            values = []
            for column in columns:
                try:
                    value = float(row[column])
                except (TypeError, ValueError):
                    value = float("nan")
                if not np.isfinite(value):
                    raise ValueError(f"{path}:{reader.line_num}: {column} must be a finite "
                                     f"number, got {row[column]!r}")
                values.append(value)
            out.append(values)
    if not out:
        raise ValueError(f"{path}: no target")
    return np.array(out)


def check_usable(est: Estimate) -> None:
    """``ValueError`` for an estimate outside the validity range: a controller must not
    take it."""
    try:
        check_validity(est.machine)
    except MachineFileError as exc:
        raise ValueError(f"the estimate is outside the validity range: "
                         f"{str(exc).replace('machine key', 'estimate key')}") from None


@dataclass
class Compensation:
    """Each target's compensated command ``rho`` (n, 3), mm, and its predicted error (mm,
    RMS expectation) per frame of :data:`~orthoglide_env.scoring.FRAMES` (n,)."""

    targets: np.ndarray
    commands: np.ndarray
    predicted: dict[str, np.ndarray]


def compensated_commands(est: Estimate, targets: np.ndarray) -> np.ndarray:
    """The commands (n, 3) that put the tool of the machine ``est`` estimates on
    ``targets`` (n, 3), NaN rows where it cannot within its control limits: the estimated
    machine's inverse kinematics, less the pitch-error table's value when the fit has one;
    ``ValueError`` for an estimate outside the validity range."""
    check_usable(est)
    rho = commands(est.machine, np.asarray(targets, dtype=float))
    reached = np.isfinite(rho).all(axis=-1)
    if est.fits_lead and reached.any():
        rho[reached] -= est.lead_correction(rho[reached])
    return rho


def compensate(est: Estimate, targets: np.ndarray) -> Compensation:
    """:func:`compensated_commands` for ``targets`` (n, 3) with each one's predicted error;
    ``ValueError`` naming the first target the estimated machine cannot reach within its
    control limits."""
    targets = np.asarray(targets, dtype=float)
    rho = compensated_commands(est, targets)
    outside = np.flatnonzero(~np.isfinite(rho).all(axis=-1))
    if outside.size:
        k = int(outside[0])
        raise ValueError(f"target {k + 1} (line {k + 2} of a targets file: "
                         f"{', '.join(f'{v:g}' for v in targets[k])}) mm is "
                         "outside the estimated machine's control limits")
    n = len(ERROR_NAMES)
    covariance = est.lead_covariance if est.lead_terms else est.error_covariance[:n, :n]
    predicted = predicted_target_errors(est.machine, covariance, targets,
                                        est.lead_patterns if est.lead_terms else None)
    return Compensation(targets, rho, predicted)


def write_controller_files(est: Estimate, folder: str | Path,
                           compensation: Compensation | None = None) -> list[Path]:
    """Write what a controller takes into ``folder``: ``joint_offsets.csv`` (the encoder
    offsets ``drho``, as the paper put them into its control software), ``pitch_table.csv``
    and ``backlash.csv`` when the fit has them, the calibrated ``machine.json`` and
    ``machine.urdf``, and with a compensation ``commands.csv``.  The paths written;
    nothing for an estimate outside the validity range (``ValueError``)."""
    check_usable(est)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []

    def write(name: str, text: str) -> None:
        path = folder / name
        path.write_text(text)
        written.append(path)

    sigma = np.sqrt(np.clip(np.diag(est.error_covariance)[:3], 0.0, None))
    write("joint_offsets.csv", "axis,drho_mm,sigma_mm\n" + "".join(
        f"{axis},{est.theta[a]:.9f},{sigma[a]:.9f}\n" for a, axis in enumerate(AXIS_NAMES)))
    table = est.pitch_table
    if table is not None:
        write("pitch_table.csv", table.to_csv())
    backlash = est.backlash
    if backlash is not None:
        write("backlash.csv", "axis,lost_motion_mm,sigma_mm\n" + "".join(
            f"{axis},{v['value']:.9f},{v['sigma']:.9f}\n" for axis, v in backlash.items()))
    write("machine.json", json.dumps(machine_dict(est.machine, None), indent=2) + "\n")
    write("machine.urdf", write_urdf(est.machine))
    if compensation is not None:
        header = [*TARGET_MM_COLUMNS, "rho_x_mm", "rho_y_mm", "rho_z_mm",
                  *(f"predicted_{frame}_mm" for frame in FRAMES)]
        rows = [",".join(header)]
        for k, target in enumerate(compensation.targets):
            cells = [*target, *compensation.commands[k],
                     *(compensation.predicted[frame][k] for frame in FRAMES)]
            rows.append(",".join(f"{v:.9f}" for v in cells))
        write("commands.csv", "\n".join(rows) + "\n")
    return written


class Compensate:
    """The compensation, configured: the estimate ``estimate`` and the tool ``targets``
    (n, 3), mm, whose commands to compensate (None: none).  ``ValueError`` at
    construction for an estimate outside the validity range or targets that are not a
    finite (n, 3) array; :meth:`run` makes the :class:`Controller`."""

    def __init__(self, estimate: Estimate, targets: np.ndarray | None = None) -> None:
        check_usable(estimate)
        if targets is not None:
            targets = np.asarray(targets, dtype=float)
            if targets.ndim != 2 or targets.shape[1:] != (3,) or not len(targets):
                raise ValueError(f"targets must be an (n, 3) array of mm, got the shape "
                                 f"{targets.shape}")
            if not np.isfinite(targets).all():
                raise ValueError("targets must be finite numbers of mm")
        self.estimate, self.targets = estimate, targets

    def run(self) -> Controller:
        """The controller's values; ``ValueError`` naming the first target the estimated
        machine cannot reach within its control limits."""
        return Controller(self.estimate, None if self.targets is None
                          else compensate(self.estimate, self.targets))


@dataclass
class Controller:
    """What a controller takes from the estimate ``estimate``: its joint offsets, and the
    ``compensation`` of the targets (None: none were given)."""

    estimate: Estimate
    compensation: Compensation | None = None

    def joint_offsets(self) -> list[dict[str, Any]]:
        """Per axis the encoder offset ``drho_mm`` and its ``sigma_mm``."""
        est = self.estimate
        sigma = np.sqrt(np.clip(np.diag(est.error_covariance)[:3], 0.0, None))
        return [{"axis": axis, "drho_mm": float(est.theta[a]), "sigma_mm": float(sigma[a])}
                for a, axis in enumerate(AXIS_NAMES)]

    def targets(self) -> list[dict[str, Any]]:
        """Per target its ``target``, compensated ``command`` and predicted error per
        frame (``predicted_FRAME_mm``)."""
        c = self.compensation
        return [] if c is None else [
            {"target": t.tolist(), "command": rho.tolist(),
             **{f"predicted_{frame}_mm": float(c.predicted[frame][k]) for frame in c.predicted}}
            for k, (t, rho) in enumerate(zip(c.targets, c.commands, strict=True))]

    def to_dict(self) -> dict[str, Any]:
        """The joint offsets and targets (``compensate --json``'s keys) and the estimate."""
        return {"joint_offsets": self.joint_offsets(), "targets": self.targets(),
                "estimate": strict(self.estimate.to_dict())}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Controller:
        """The controller's values :meth:`to_dict` wrote (``ValueError`` if they are not)."""
        try:
            est = Estimate.from_dict(data["estimate"])
            rows = data["targets"]
            compensation = None if not rows else Compensation(
                np.array([r["target"] for r in rows], dtype=float),
                np.array([r["command"] for r in rows], dtype=float),
                {frame: np.array([r[f"predicted_{frame}_mm"] for r in rows], dtype=float)
                 for frame in FRAMES})
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a controller's values: {exc}") from None
        return cls(est, compensation)

    def write(self, folder: str | Path) -> list[Path]:
        """:func:`write_controller_files` into ``folder``; the paths written."""
        return write_controller_files(self.estimate, folder, self.compensation)
