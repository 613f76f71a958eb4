"""What a controller compensates beyond its kinematic model: per-axis pitch-error tables.

A CNC controller's pitch-error compensation holds, per axis, the drive's error at
equally spaced nodes from a reference position; between nodes it interpolates
linearly.  Here an axis's error is where the carriage is minus where its encoder says
(the sign of :meth:`orthoglide_env.world.truth.World.lead_error`), in mm, and the
nodes start at ``rho_min`` (where the screw's fixed bearing is), whose error is 0 by
definition: a constant error is an encoder offset, which the kinematic model's
``drho`` holds.  The controller compensates by commanding ``rho - error(rho)``.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from typing import Any

import numpy as np

from orthoglide_env.model.errors import AXIS_NAMES


def node_count(stroke_mm: float, spacing_mm: float) -> int:
    """The nodes after the reference one that cover a stroke: the last at or beyond its
    end.  ``ValueError`` for a spacing that is not positive or exceeds the stroke."""
    if not np.isfinite(spacing_mm) or spacing_mm <= 0:
        raise ValueError(f"the pitch-error table's node spacing must be positive, got "
                         f"{spacing_mm:g} mm")
    if spacing_mm > stroke_mm:
        raise ValueError(f"the pitch-error table's node spacing ({spacing_mm:g} mm) is "
                         f"larger than the drives' travel ({stroke_mm:g} mm)")
    return int(np.ceil(stroke_mm / spacing_mm - 1e-9))


def interpolation_weights(rho: np.ndarray, start: float, spacing: float, count: int
                          ) -> np.ndarray:
    """(..., count) the weights of nodes 1..count (node 0 is the reference, error 0) in
    the linear interpolation at ``rho`` (...); held flat beyond the last node."""
    u = np.clip((np.asarray(rho, dtype=float) - start) / spacing, 0.0, count)
    nodes = np.arange(1, count + 1)
    return np.clip(1.0 - np.abs(u[..., None] - nodes), 0.0, 1.0)


@dataclass(frozen=True)
class PitchTable:
    """Per-axis pitch-error tables: the error (mm) at ``start + k * spacing`` for
    k = 0..count (``values`` (3, count + 1), column 0 the reference's 0), and each
    value's standard deviation ``sigma`` (3, count + 1), mm."""

    start: float
    spacing: float
    values: np.ndarray
    sigma: np.ndarray

    def __post_init__(self) -> None:
        values = np.asarray(self.values, dtype=float)
        sigma = np.asarray(self.sigma, dtype=float)
        if values.ndim != 2 or values.shape[0] != 3 or values.shape != sigma.shape:
            raise ValueError(f"a pitch-error table holds 3 axes of equal length with a "
                             f"sigma each, got values {values.shape}, sigma {sigma.shape}")
        if not self.spacing > 0:
            raise ValueError(f"the node spacing must be positive, got {self.spacing:g}")
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "sigma", sigma)

    @property
    def nodes(self) -> np.ndarray:
        """The nodes' positions (mm, control coordinates)."""
        return self.start + self.spacing * np.arange(self.values.shape[1])

    def error(self, rho: np.ndarray) -> np.ndarray:
        """The tables' error (mm) at ``rho`` (..., 3), interpolated as a controller does."""
        rho = np.asarray(rho, dtype=float)
        count = self.values.shape[1] - 1
        weights = interpolation_weights(rho, self.start, self.spacing, count)  # (..., 3, c)
        return np.einsum("...ak,ak->...a", weights, self.values[:, 1:])

    def to_dict(self) -> dict[str, Any]:
        return {"start": self.start, "spacing": self.spacing,
                "values": self.values.tolist(), "sigma": self.sigma.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PitchTable:
        return cls(float(data["start"]), float(data["spacing"]), np.array(data["values"]),
                   np.array(data["sigma"]))

    def to_csv(self) -> str:
        """One row per axis and node: ``axis,position_mm,error_mm,sigma_mm``."""
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["axis", "position_mm", "error_mm", "sigma_mm"])
        for a, axis in enumerate(AXIS_NAMES):
            for rho, value, sigma in zip(self.nodes, self.values[a], self.sigma[a],
                                         strict=True):
                writer.writerow([axis, f"{rho:.3f}", f"{value:.6f}", f"{sigma:.6f}"])
        return out.getvalue()
