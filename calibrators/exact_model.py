"""The exact model of an experiment's gauge readings, batched over parameter vectors.

A *design* says where readings were taken: which gauge mountings (stand installations)
and, for every reading, its mounting and the commanded posture.  The model reading of a
mounting at a posture is ``sign * t`` with ``t`` the distance along the stand's ray to the
plane of the bar face it is aimed at (:func:`orthoglide_env.gauges.face_distances`); the
gauge's zero is one unknown constant per mounting, which estimators eliminate, so the
model leaves it out.

The parameter vector is the one of :mod:`calibrators.parameters`: 27 machine errors, then
four stand parameters per mounting.  Any leading dimensions of it are a batch (machines,
or the perturbations of a finite-difference Jacobian), evaluated in one numpy pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.gauges import GaugeSpec, face_distances, ideal_rays, stand_rays
from orthoglide_env.geometry import ERROR_NAMES, MachineParams

from .parameters import ParameterSpace

N_MACHINE: int = len(ERROR_NAMES)


def mounting_key(spec: GaugeSpec) -> str:
    """Default name of a gauge's mounting: its slot, ``x-leg/y@0.5``."""
    return f"{spec.name}@{spec.at:g}"


@dataclass(frozen=True)
class Design:
    """Where an experiment's readings were taken."""

    mountings: tuple[str, ...]
    specs: tuple[GaugeSpec, ...]  # one per mounting
    mounting: np.ndarray  # (N,) index of each reading's mounting
    rho: np.ndarray  # (N, 3) commanded posture of each reading, mm

    def __post_init__(self) -> None:
        postures, index = np.unique(self.rho, axis=0, return_inverse=True)
        object.__setattr__(self, "_postures", postures)
        object.__setattr__(self, "_posture_index", np.ravel(index))

    def __len__(self) -> int:
        return len(self.mounting)

    @property
    def space(self) -> ParameterSpace:
        return ParameterSpace(self.mountings, self.specs)

    @property
    def postures(self) -> np.ndarray:
        """The distinct postures (P, 3)."""
        return self._postures  # type: ignore[attr-defined]

    @property
    def signs(self) -> np.ndarray:
        """Reading sign of every mounting: +1 when its plunger points along the world axis."""
        _, directions = ideal_rays(self.specs, MachineParams())
        return np.sign(directions[np.arange(len(self.specs)), [s.axis for s in self.specs]])

    @classmethod
    def of(cls, mountings: list[str], specs: list[GaugeSpec], rho: np.ndarray) -> Design:
        """A design from each reading's mounting name and gauge spec, and its posture."""
        names = list(dict.fromkeys(mountings))
        spec_of: dict[str, GaugeSpec] = {}
        for name, spec in zip(mountings, specs, strict=True):
            if spec_of.setdefault(name, spec) != spec:
                raise ValueError(f"mounting '{name}' holds two different gauges "
                                 f"({spec_of[name].name}@{spec_of[name].at:g} and "
                                 f"{spec.name}@{spec.at:g})")
        index = np.array([names.index(m) for m in mountings], dtype=int)
        return cls(tuple(names), tuple(spec_of[n] for n in names), index,
                   np.asarray(rho, dtype=float).reshape(-1, 3))


def predict(theta: np.ndarray, design: Design) -> np.ndarray:
    """Model readings (mm, up to one constant per mounting) of every reading of
    ``design`` for parameter vectors ``theta`` of shape ``(*batch, n)``: ``(*batch, N)``."""
    theta = np.asarray(theta, dtype=float)
    batch = theta.shape[:-1]
    machine = MachineParams.from_vector(theta[..., :N_MACHINE])
    stand = theta[..., N_MACHINE:].reshape(*batch, len(design.specs), 4)
    origins, directions = ideal_rays(design.specs, machine)
    origins, directions = stand_rays(design.specs, origins, directions, stand)
    postures = design.postures.reshape((1,) * len(batch) + design.postures.shape)
    t = face_distances(machine, design.specs, origins, directions, postures)  # (*b, P, K)
    rows = t[..., design._posture_index, design.mounting]  # type: ignore[attr-defined]
    return design.signs[design.mounting] * rows


#: Forward-difference step, in units of each parameter's scale (2 mm for drho, 2 mrad for a
#: tilt, ...): truncation ~1e-6 * scale / L relative, round-off ~1e-16 * 300 mm / step; both
#: far below what moves a Gauss-Newton fixed point (residuals are always exact).
FD_STEP: float = 1e-6


def jacobian(theta: np.ndarray, design: Design, free: np.ndarray, scale: np.ndarray,
             at: np.ndarray | None = None) -> np.ndarray:
    """Forward-difference Jacobian of :func:`predict` over the ``free`` parameters, per unit
    of their ``scale``: ``(*batch, N, n_free)``.  All perturbations go through one call."""
    theta = np.asarray(theta, dtype=float)
    idx = np.flatnonzero(free)
    steps = np.zeros((len(idx), theta.shape[-1]))
    steps[np.arange(len(idx)), idx] = FD_STEP * scale[idx]
    base = predict(theta, design) if at is None else at
    moved = predict(theta[..., None, :] + steps, design)  # (*batch, n_free, N)
    return np.swapaxes((moved - base[..., None, :]) / FD_STEP, -1, -2)
