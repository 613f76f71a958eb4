"""Dial gauges as installed: one gauge (:class:`Gauge`) and a set of them as arrays
(:class:`GaugeArray`), for one machine or a batch.

A gauge is a plunger on a magnetic stand fixed to the base.  Its ray starts at
``origin`` (the tip when the plunger is pushed fully in) and runs along ``direction``
(toward the target); the tip touches the first face of the target at distance
``t``.  The plunger can extend by ``travel`` mm, so the gauge is in contact when
``0 <= t <= travel``.  ``t > travel``: the tip hangs in the air (no contact); ``t < 0``:
the target has pushed the plunger past its travel toward the stand (overtravel, which
would damage a real gauge).

Where a gauge can go is in :mod:`orthoglide_env.instruments.slots`, how it is installed
in :mod:`~orthoglide_env.instruments.stands`, how its ray meets the machine in
:mod:`~orthoglide_env.instruments.rays` and what its dial shows in
:mod:`~orthoglide_env.instruments.dial`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from functools import cached_property, lru_cache
from typing import Any

import numpy as np

from orthoglide_env.instruments.slots import GaugeSpec, Part, face_of, target_index
from orthoglide_env.model.design import PROTOTYPE

#: The prototype's gauges' travel (mm), the default where no design says otherwise.
DEFAULT_TRAVEL: float = PROTOTYPE.gauge_travel


@dataclass(frozen=True)
class Gauge:
    """An installed gauge: its real stand pose, travel and zero."""

    spec: GaugeSpec
    origin: np.ndarray
    direction: np.ndarray
    sign: float
    travel: float = DEFAULT_TRAVEL
    zero: float = DEFAULT_TRAVEL / 2


@dataclass(frozen=True)
class GaugeArray:
    """Installed gauges as arrays: one gauge set (batch shape ``()``) or one set per machine
    of a batch (:attr:`MachineParams.batch_shape`).

    Every field has the batch dimensions first, then one entry per gauge ``G``: ``origin``
    and ``direction`` ``(*batch, G, 3)``, the rest ``(*batch, G)``.  ``leg``, ``axis``,
    ``at`` and ``part`` (bars unless given) are each gauge's :class:`GaugeSpec`, so a
    gauge set converts back to :class:`Gauge` objects without loss (:meth:`to_gauges`).
    Every function of the instruments package that takes a ``list[Gauge]`` also takes a
    ``GaugeArray``; the list is converted, so there is one computation for one machine and
    for many.
    """

    origin: np.ndarray
    direction: np.ndarray
    sign: np.ndarray
    travel: np.ndarray
    zero: np.ndarray
    leg: np.ndarray
    axis: np.ndarray
    at: np.ndarray
    part: np.ndarray | int = Part.BAR

    def __post_init__(self) -> None:
        shape = np.shape(self.origin)
        if len(shape) < 2 or shape[-1] != 3:
            raise ValueError(f"gauge origins must have shape (*batch, G, 3), got {list(shape)}")
        for name, tail, dtype in (("origin", (3,), float), ("direction", (3,), float),
                                  ("sign", (), float), ("travel", (), float),
                                  ("zero", (), float), ("leg", (), np.intp),
                                  ("axis", (), np.intp), ("at", (), float),
                                  ("part", (), np.intp)):
            value = np.asarray(getattr(self, name), dtype=dtype)
            object.__setattr__(self, name, np.broadcast_to(value, (*shape[:-1], *tail)))

    @classmethod
    def of(cls, gauges: Sequence[Gauge]) -> GaugeArray:
        """The array form of one machine's gauges (batch shape ``()``)."""
        return replace(
            spec_arrays([g.spec for g in gauges]),
            origin=np.array([g.origin for g in gauges], dtype=float).reshape(len(gauges), 3),
            direction=np.array([g.direction for g in gauges], dtype=float).reshape(-1, 3),
            sign=[g.sign for g in gauges], travel=[g.travel for g in gauges],
            zero=[g.zero for g in gauges])

    @classmethod
    def stack(cls, sets: Sequence[GaugeArray | Sequence[Gauge]]) -> GaugeArray:
        """A batch of shape ``(len(sets),)`` from gauge sets of equal size."""
        if not sets:
            raise ValueError("cannot stack an empty list of gauge sets")
        arrays = [as_gauge_array(s) for s in sets]
        return cls(**{f.name: np.stack([getattr(a, f.name) for a in arrays])
                      for f in fields(cls)})

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading shape of the batch of machines; ``()`` for one machine's gauges."""
        return self.sign.shape[:-1]

    @property
    def count(self) -> int:
        """Gauges per machine."""
        return self.sign.shape[-1]

    def __getitem__(self, index: Any) -> GaugeArray:
        """One machine's gauges (or a sub-batch) of a batch."""
        if not self.batch_shape:
            raise IndexError("one machine's gauges have no batch axis to index")
        return GaugeArray(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    def columns(self, index: np.ndarray) -> GaugeArray:
        """The gauges ``index`` of every set (along the gauge axis); remembered, with what
        they work out (their targets), for the next ask of the same gauges: a lab looks
        at the stands down at every step, and its gauges change only at a re-mount."""
        if np.array_equal(index, np.arange(self.count)):  # all of them, as most looks ask
            return self
        kept = self.__dict__.setdefault("_columns", {})  # (frozen: as cached_property does)
        key = tuple(np.asarray(index).tolist())
        if key not in kept:
            at = len(self.batch_shape)
            kept[key] = GaugeArray(**{f.name: np.take(getattr(self, f.name), index, axis=at)
                                      for f in fields(self)})
        return kept[key]

    def with_rows(self, index: Any, rows: GaugeArray) -> GaugeArray:
        """A copy of this batch whose gauges at ``index`` (machines along the first batch
        axis, or a tuple of indices reaching into the gauge axis) are ``rows`` instead (of
        the indexed shape, or that shape with singleton axes)."""
        out = {}
        for f in fields(self):
            value = np.array(getattr(self, f.name))
            value[index] = np.reshape(getattr(rows, f.name), value[index].shape)
            out[f.name] = value
        return GaugeArray(**out)

    # Remembered: a lab asks its installed gauges for them at every look.
    @cached_property
    def target(self) -> np.ndarray:
        """Index in :data:`BOX_NAMES` of each gauge's target box, ``(*batch, G)``."""
        return target_index(self.part, self.leg, self.face)

    @cached_property
    def face(self) -> np.ndarray:
        """The target box's face (box axis) each gauge touches, ``(*batch, G)``."""
        return face_of(self.part, self.leg, self.axis)

    def spec(self, index: tuple[int, ...]) -> GaugeSpec:
        """The :class:`GaugeSpec` of the gauge at ``index`` (batch indices, then the
        gauge's)."""
        return GaugeSpec(int(self.leg[index]), int(self.axis[index]), float(self.at[index]),
                         Part(int(self.part[index])))

    def for_postures(self, ndim: int) -> GaugeArray:
        """The fields reshaped to broadcast against arrays of ``ndim`` leading dimensions
        (the batch, then posture dimensions) before the gauge axis."""
        batch = len(self.batch_shape)
        extra = ndim - batch
        if extra <= 0:
            return self
        return GaugeArray(**{f.name: _insert_axes(getattr(self, f.name), batch, extra)
                             for f in fields(self)})

    def to_gauges(self) -> list[Gauge]:
        """One machine's gauges as :class:`Gauge` objects."""
        if self.batch_shape:
            raise ValueError("to_gauges() converts one machine's gauges: index the batch first")
        return [Gauge(self.spec((k,)), origin.copy(), direction.copy(), float(sign),
                      float(travel), float(zero))
                for k, (origin, direction, sign, travel, zero) in enumerate(zip(
                    self.origin, self.direction, self.sign, self.travel, self.zero, strict=True))]

    def zeroed(self, t_at_zero: np.ndarray) -> GaugeArray:
        """The gauges set up at the Zero posture: see :func:`zero_gauges`."""
        t_at_zero = np.asarray(t_at_zero, dtype=float)
        if np.isnan(t_at_zero).any():
            names = [(f"machine {k[0] if len(k) == 2 else list(k[:-1])}: " if len(k) > 1
                      else "") + self.spec(k).name
                     for k in map(tuple, np.argwhere(np.isnan(t_at_zero)).tolist())]
            raise ValueError(f"gauge(s) {names} do not touch their target at the Zero posture")
        half = self.travel / 2
        return replace(self, origin=self.origin + (t_at_zero - half)[..., None] * self.direction,
                       zero=half)


def _insert_axes(value: np.ndarray, position: int, count: int) -> np.ndarray:
    """``value`` with ``count`` singleton axes inserted before axis ``position``."""
    return value.reshape(*value.shape[:position], *(1,) * count, *value.shape[position:])


def as_gauge_array(gauges: GaugeArray | Sequence[Gauge]) -> GaugeArray:
    """``gauges`` as a :class:`GaugeArray` (a list of one machine's gauges is converted)."""
    return gauges if isinstance(gauges, GaugeArray) else GaugeArray.of(gauges)


def spec_arrays(specs: Sequence[GaugeSpec]) -> GaugeArray:
    """The specs of ``specs`` as the index fields of a :class:`GaugeArray` (its rays are
    placeholders); made once per set of specs (an estimator's model asks at every step)."""
    return _spec_arrays(tuple(specs))


@lru_cache(maxsize=256)
def _spec_arrays(specs: tuple[GaugeSpec, ...]) -> GaugeArray:
    n = len(specs)
    return GaugeArray(origin=np.zeros((n, 3)), direction=np.zeros((n, 3)), sign=0.0,
                      travel=0.0, zero=0.0, leg=[s.leg for s in specs],
                      axis=[s.axis for s in specs], at=[s.at for s in specs],
                      part=[s.part for s in specs])
