"""The exact model of an experiment's readings, batched over parameter vectors.

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

from .gauges import (
    Gauge,
    GaugeSpec,
    face_distances,
    ideal_rays,
    stand_errors,
    stand_names,
    stand_rays,
)
from .geometry import ERROR_NAMES, MachineParams, error_group

N_MACHINE: int = len(ERROR_NAMES)


@dataclass(frozen=True)
class ParameterSpace:
    """Every parameter a fit could estimate for a set of gauge mountings: the 27 machine
    errors in :data:`~orthoglide_env.geometry.ERROR_NAMES` order, then four stand
    parameters per mounting (:data:`~orthoglide_env.gauges.STAND_PARAMS`)."""

    mountings: tuple[str, ...] = ()
    specs: tuple[GaugeSpec, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return ERROR_NAMES + tuple(
            n for m, s in zip(self.mountings, self.specs, strict=True) for n in stand_names(m, s)
        )

    @property
    def groups(self) -> tuple[str, ...]:
        """Group of every parameter: a machine-file key, ``stand_shift`` or ``stand_tilt``."""
        stands = ("stand_shift",) * 2 + ("stand_tilt",) * 2
        return tuple(error_group(n) for n in ERROR_NAMES) + stands * len(self.mountings)

    def __len__(self) -> int:
        return len(ERROR_NAMES) + 4 * len(self.mountings)


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


#: Central-difference step, in units of each parameter's scale (2 mm for drho, 2 mrad for
#: a tilt, ...).  Gauss-Newton stops where ``J^T r = 0`` with the ``J`` it uses, so the
#: Jacobian's round-off makes the last steps wander and its truncation moves the fixed
#: point.  The model computes positions of the order of L = 310 mm, so a reading's
#: round-off is ~eps * L ~ 7e-14 mm, and divided by the step it is the Jacobian's noise:
#: at 1e-2 of a scale, ~3.5e-12 mm per scale unit, a wander of ~2e-10 of a scale.  The
#: truncation, relative ~ (step * scale / L)^2 < 5e-9 (the model bends on the scale of
#: the leg length, and of a radian for tilts), is smooth: it moves the fixed point by less
#: than the gauge noise's millionth and the same way in any batch.  (Forward differences at
#: 1e-6 left the fixed point ~1e-6 of a scale off; central ones at 1e-5 wandered at 1e-7.)
FD_STEP: float = 1e-2


def jacobian(theta: np.ndarray, design: Design, free: np.ndarray, scale: np.ndarray
             ) -> np.ndarray:
    """Central-difference Jacobian of :func:`predict` over the ``free`` parameters, per unit
    of their ``scale``: ``(*batch, N, n_free)``.  All perturbations go through one call."""
    theta = np.asarray(theta, dtype=float)
    idx = np.flatnonzero(free)
    steps = np.zeros((len(idx), theta.shape[-1]))
    steps[np.arange(len(idx)), idx] = FD_STEP * scale[idx]
    moved = predict(theta[..., None, :] + np.concatenate([steps, -steps]), design)
    forward, backward = moved[..., : len(idx), :], moved[..., len(idx):, :]
    return np.swapaxes((forward - backward) / (2 * FD_STEP), -1, -2)


def parameters_of(design: Design, machine: MachineParams, gauges: list[Gauge]) -> np.ndarray:
    """The true parameter vector of a simulated experiment: the machine's errors and the
    stand parameters of its installed ``gauges`` (matched to the design's mountings by
    slot).  For scoring an estimate; an agent never sees it."""
    by_slot = {g.spec.slot: g for g in gauges}
    slots = [spec.slot for spec in design.specs]
    missing = [m for m, slot in zip(design.mountings, slots, strict=True) if slot not in by_slot]
    if missing:
        raise ValueError(f"no installed gauge for mounting(s) {missing}")
    installed = [by_slot[slot] for slot in slots]
    origins, directions = ideal_rays(design.specs, machine)
    stand = stand_errors(design.specs, np.array([g.origin for g in installed]),
                         np.array([g.direction for g in installed]), origins, directions)
    return np.concatenate([machine.to_vector(), stand.ravel()])
