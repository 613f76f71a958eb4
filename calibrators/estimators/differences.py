"""Gauge differences (reading at a posture minus reading at Zero) and their models.

The paper works with differences because a dial gauge's zero is only as good as one
reading: differencing against the Zero readings removes it.  Averaging repetitions makes
the differences of one gauge correlated (they share the mean Zero reading); the exact
covariance is kept so that estimators can weigh them properly and the Cramér-Rao bound
is the one of the data actually used.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

import numpy as np

from calibrators.measurements import ZERO_RHO, Measurement, Measurements, gauge_name
from orthoglide_env.instruments.rays import exact_ray_distances
from orthoglide_env.instruments.slots import GaugeSpec, Part
from orthoglide_env.instruments.stands import install
from orthoglide_env.model.boxes import collision_boxes
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import PAPER_POSTURES, direct, paper_posture

#: Differences share a dense covariance (estimators whiten with its Cholesky factor): this
#: many rows take 130 MB and seconds; a design needs a few hundred (40 mountings of 15
#: postures: 600).
MAX_DIFFERENCES: int = 4096


class MissingZeroError(ValueError):
    """A mounting has readings but none at Zero: its zero is unknown."""


@dataclass(frozen=True)
class Differences:
    """Averaged differences, one row per (mounting, non-Zero posture)."""

    gauges: tuple[GaugeSpec, ...]
    postures: tuple[str, ...]  # labels (paper posture names)
    rho: np.ndarray  # (n, 3) the postures, control coordinates, mm
    values: np.ndarray  # mm
    cov_unit: np.ndarray  # covariance of ``values`` for readings of unit variance
    mountings: tuple[str, ...] = ()
    design: MachineDesign = field(kw_only=True)  # the design of the machine read

    def __len__(self) -> int:
        return len(self.values)


def check_zeros(items: Collection[Measurement]) -> None:
    """Raise :class:`MissingZeroError` for the first gauge mounting of ``items`` with
    readings but none at Zero.  A fit could estimate such a zero as one more unknown, but
    a technician's sheet without it has lost a line, and the paper's procedure and the
    lab's re-mounting both read at Zero first; a tracker's coordinates need no zero."""
    # Whether each (mounting, gauge) was read at Zero yet, in the order of their first
    # readings: one lookup per reading once it was (a sweep checks tens of thousands).
    zeroed: dict[tuple[str, GaugeSpec], bool] = {}
    for m in items:
        if isinstance(m.gauge, GaugeSpec):
            key = (m.mounting, m.gauge)
            if not zeroed.get(key, False):
                zeroed[key] = m.rho == ZERO_RHO
    for (mounting, gauge), zero in zeroed.items():
        if not zero:
            m = next(m for m in items if m.mounting == mounting and m.gauge == gauge)
            where = f" (first reading: line {m.line})" if m.line is not None else ""
            raise MissingZeroError(f"gauge {gauge_name(gauge)}, mounting '{mounting}', has "
                                   f"readings but none at Zero{where}: its zero is unknown")


def differences(data: Measurements, repetitions: Collection[int] | None = None) -> Differences:
    """Average each mounting's readings per posture and subtract its mean Zero reading.

    A mounting (``Measurement.mounting``) is one installation of a gauge, with a zero of
    its own.  ``repetitions`` keeps only those repetitions (a Zero reading belongs to the
    repetition it opens).  A mounting with readings but none at Zero raises
    :class:`MissingZeroError` rather than being dropped, which would hide a fault of the
    file; a caller that can do without a subset (the verification's held-out sets)
    catches it.  Linear in the readings.
    """
    groups: dict[tuple[str, GaugeSpec, tuple[float, ...]], list[float]] = {}
    labels: dict[tuple[float, ...], str] = {}
    kept = [m for m in data.items if repetitions is None or m.repetition in repetitions]
    check_zeros(kept)
    for m in kept:
        groups.setdefault((m.mounting, m.gauge, m.rho), []).append(m.reading)
        labels.setdefault(m.rho, m.posture)
    keys = sorted((k for k in groups if k[2] != ZERO_RHO),
                  key=lambda k: (k[1].leg, k[1].axis, k[1].at, k[0], labels[k[2]], k[2]))
    if len(keys) > MAX_DIFFERENCES:
        raise ValueError(f"{len(keys)} (mounting, posture) pairs: more than the "
                         f"{MAX_DIFFERENCES} differences an estimate can weigh")
    zero = [groups[(k[0], k[1], ZERO_RHO)] for k in keys]
    values = np.array([np.mean(groups[k]) - np.mean(z) for k, z in zip(keys, zero, strict=True)])
    # Rows of one mounting share its mean Zero reading; each has its own posture's mean.
    number: dict[tuple[str, GaugeSpec], int] = {}
    mounting = np.array([number.setdefault(k[:2], len(number)) for k in keys], dtype=int)
    shared = mounting[:, None] == mounting[None, :]
    cov = (np.where(shared, np.array([1 / len(z) for z in zero])[:, None], 0.0)
           + np.diag([1 / len(groups[k]) for k in keys]))
    rho = np.array([k[2] for k in keys], dtype=float).reshape(-1, 3)
    return Differences(tuple(k[1] for k in keys), tuple(labels[k[2]] for k in keys), rho,
                       values, cov, tuple(k[0] for k in keys), design=data.design)


def model_differences(theta: np.ndarray, rows: Differences) -> np.ndarray:
    """The exact model's differences for paper parameters ``theta`` (drho, dL), with ideal
    gauges installed on that machine (installation errors are unknowable).

    Zeroing a gauge slides it along its own ray, which shifts every ray distance by one
    constant: a difference ``sign * (t - t_zero)`` does not depend on it, so the model
    skips the zeroing and reads one batch of postures, whose
    geometry is computed once."""
    machine = MachineParams(drho=theta[:3], dL=theta[3:], design=rows.design)
    specs = sorted(set(rows.gauges), key=lambda g: (g.leg, g.axis, g.at))
    gauges = install(specs, machine)
    postures, row = np.unique(rows.rho, axis=0, return_inverse=True)
    rho = np.vstack([np.zeros(3), postures])
    boxes = collision_boxes(machine, rho, direct(machine, rho))
    t = exact_ray_distances(machine, gauges, rho, boxes)  # (postures, gauges)
    diff = np.array([g.sign for g in gauges]) * (t[1:] - t[0])
    col = np.array([specs.index(g) for g in rows.gauges], dtype=int)
    return diff[np.ravel(row), col]


#: Forward differences: truncation ~FD_STEP / L ~ 3e-7 of each derivative, which only
#: touches a Gauss-Newton iteration's convergence rate and a covariance at that relative
#: level, never a fixed point (residuals are always evaluated exactly).
FD_STEP: float = 1e-4  # mm


def model_jacobian(theta: np.ndarray, rows: Differences, free: tuple[int, ...],
                   at: np.ndarray | None = None) -> np.ndarray:
    """Forward-difference Jacobian of :func:`model_differences` over the ``free``
    parameters (``at``: the model's value at ``theta`` when already known)."""
    base = model_differences(theta, rows) if at is None else at
    cols = []
    for k in free:
        step = np.zeros(6)
        step[k] = FD_STEP
        cols.append((model_differences(theta + step, rows) - base) / FD_STEP)
    return np.column_stack(cols)


def paper_matrix(rows: Differences) -> np.ndarray:
    """Eq. (10)'s rows for these differences: leg ``k`` measured along axis ``m`` at the
    leg's Max (or Min) posture reads ``b drho_k + a drho_m - b dL_k - c dL_m`` with
    ``a = sin(alpha)``, ``b = (1/2 + a) tan(alpha)``, ``c = (1/2 + a) / cos(alpha) - 1/2``."""
    design = rows.design
    # Another design's paper postures are told by their rho (a file's labels name the
    # prototype's).
    names = {tuple(paper_posture(p, design)): p for p in PAPER_POSTURES}
    out = np.zeros((len(rows), 6))
    for r, (g, label, rho) in enumerate(zip(rows.gauges, rows.postures, rows.rho,
                                            strict=True)):
        posture = names.get(tuple(rho), label)
        if g.part != Part.BAR or posture not in PAPER_POSTURES or posture[0] != "XYZ"[g.leg]:
            raise ValueError(f"eq. (10) has no row for gauge {g.name} at posture {label}")
        limit = design.rho_max if posture.endswith("Max") else design.rho_min
        alpha = np.arcsin(limit / design.L)
        a = np.sin(alpha)
        b = (0.5 + a) * np.tan(alpha)
        c = (0.5 + a) / np.cos(alpha) - 0.5
        out[r, [g.leg, g.axis, 3 + g.leg, 3 + g.axis]] = (b, a, -b, -c)
    return out
