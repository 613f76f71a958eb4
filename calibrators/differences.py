"""Gauge differences (reading at a posture minus reading at Zero) and their models.

The paper works with differences because a dial gauge's zero is only as good as one
reading: differencing against the Zero readings removes it.  Averaging repetitions makes
the differences of one gauge correlated (they share the mean Zero reading); the exact
covariance is kept so that estimators can weigh them properly and the Cramér-Rao bound
is the one of the data actually used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.gauges import GaugeSpec, model_gauges, model_readings
from orthoglide_env.geometry import L_NOMINAL, RHO_MAX, RHO_MIN, MachineParams
from orthoglide_env.kinematics import paper_posture

from .base import Measurements


@dataclass(frozen=True)
class Differences:
    """Averaged differences, one row per (gauge, non-Zero posture)."""

    gauges: tuple[GaugeSpec, ...]
    postures: tuple[str, ...]
    values: np.ndarray  # mm
    cov_unit: np.ndarray  # covariance of ``values`` for readings of unit variance

    def __len__(self) -> int:
        return len(self.values)


def differences(data: Measurements, repetitions: set[int] | None = None) -> Differences:
    """Average each gauge's readings per posture and subtract its mean Zero reading.

    ``repetitions`` keeps only those repetitions (a Zero reading belongs to the
    repetition it opens).  Rows whose gauge has no Zero reading are dropped.
    """
    groups: dict[tuple[GaugeSpec, str], list[float]] = {}
    for m in data.items:
        if repetitions is None or m.repetition in repetitions:
            groups.setdefault((m.gauge, m.posture), []).append(m.reading)
    keys = sorted((k for k in groups if k[1] != "Zero" and (k[0], "Zero") in groups),
                  key=lambda k: (k[0].leg, k[0].axis, k[0].at, k[1]))
    values = np.array([np.mean(groups[k]) - np.mean(groups[(k[0], "Zero")]) for k in keys])
    cov = np.zeros((len(keys), len(keys)))
    for a, (ga, pa) in enumerate(keys):
        for b, (gb, pb) in enumerate(keys):
            if ga == gb:
                cov[a, b] = 1 / len(groups[(ga, "Zero")]) + (1 / len(groups[(ga, pa)])
                                                             if pa == pb else 0.0)
    return Differences(tuple(k[0] for k in keys), tuple(k[1] for k in keys), values, cov)


def model_differences(theta: np.ndarray, rows: Differences) -> np.ndarray:
    """The exact model's differences for paper parameters ``theta`` (drho, dL), with ideal
    gauges installed and zeroed on that machine (installation errors are unknowable)."""
    machine = MachineParams(drho=theta[:3], dL=theta[3:])
    specs = sorted(set(rows.gauges), key=lambda g: (g.leg, g.axis, g.at))
    gauges = model_gauges(machine, specs)
    postures = sorted(set(rows.postures))
    rho = np.array([paper_posture(p) for p in ("Zero", *postures)])
    readings = model_readings(machine, gauges, rho)  # (postures, gauges)
    zero = readings[0]
    col = {g: k for k, g in enumerate(specs)}
    row = {p: k + 1 for k, p in enumerate(postures)}
    return np.array([readings[row[p], col[g]] - zero[col[g]]
                     for g, p in zip(rows.gauges, rows.postures, strict=True)])


def paper_matrix(rows: Differences) -> np.ndarray:
    """Eq. (10)'s rows for these differences: leg ``k`` measured along axis ``m`` at the
    leg's Max (or Min) posture reads ``b drho_k + a drho_m - b dL_k - c dL_m`` with
    ``a = sin(alpha)``, ``b = (1/2 + a) tan(alpha)``, ``c = (1/2 + a) / cos(alpha) - 1/2``."""
    out = np.zeros((len(rows), 6))
    for r, (g, posture) in enumerate(zip(rows.gauges, rows.postures, strict=True)):
        if posture[0] != "XYZ"[g.leg]:
            raise ValueError(f"eq. (10) has no row for gauge {g.name} at posture {posture}")
        limit = RHO_MAX if posture.endswith("Max") else RHO_MIN
        alpha = np.arcsin(limit / L_NOMINAL)
        a = np.sin(alpha)
        b = (0.5 + a) * np.tan(alpha)
        c = (0.5 + a) / np.cos(alpha) - 0.5
        out[r, [g.leg, g.axis, 3 + g.leg, 3 + g.axis]] = (b, a, -b, -c)
    return out
