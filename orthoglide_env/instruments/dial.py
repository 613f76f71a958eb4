"""What a dial gauge shows: the reading of a ray distance, its status (contact,
overtravel), and the repeatability noise and display step.

Reading convention (docs/getting-started.md, Conventions): the coordinate of the touched
surface point along the gauge's world measuring axis, relative to the gauge's zero, in mm::

    reading = sign * (t - zero),  sign = direction . e_axis  (+1 or -1 nominally)

so the difference of two readings is the surface's displacement along that axis.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from orthoglide_env.instruments.gauges import DEFAULT_TRAVEL, Gauge, GaugeArray, as_gauge_array
from orthoglide_env.instruments.rays import exact_ray_distances, ray_box_interval
from orthoglide_env.model.boxes import to_box_frame
from orthoglide_env.model.errors import MachineParams

DEFAULT_SIGMA: float = 0.02  # mm, repeatability (paper, section 4)
DEFAULT_RESOLUTION: float = 0.01  # mm (paper, section 4)
#: Readings of ideal (noise-free) gauges are weighted as if their repeatability were this
#: (mm): weights and identifiability thresholds need a finite sigma, and a finer one lets
#: the readings' own round-off (whitened) swamp the steps of an ill-conditioned fit.
NOISE_FLOOR: float = 1e-4
#: The gauge body (radius, mm) and its stand behind the tip (length, mm): a bar that
#: reaches into them behind the tip presses the plunger past its travel, even when it is
#: off the flat face that gives a reading.
GAUGE_BODY_RADIUS: float = 6.0
STAND_LENGTH: float = 60.0


def weighting_sigma(sigma: float | np.ndarray) -> float | np.ndarray:
    """The noise a reading is weighted with (mm): its instrument's, or :data:`NOISE_FLOOR`
    for an ideal one (every weight, information and plan of the lab, the estimators and
    the agents takes it from here)."""
    floored = np.maximum(sigma, NOISE_FLOOR)
    return float(floored) if np.ndim(floored) == 0 else floored


class Status(IntEnum):
    """Why a reading is or is not valid."""

    VALID = 0
    NO_CONTACT = 1  # tip extended fully without touching
    OVERTRAVEL = 2  # plunger pushed in past its travel
    MISSED = 3  # tip off the target's flat face, or the ray meets something else first


def status_of(gauges: GaugeArray | Sequence[Gauge], t: np.ndarray) -> np.ndarray:
    """Status codes for ray distances ``t`` of shape ``(*batch, *postures, G)`` (NaN means
    the ray missed the target)."""
    travel = as_gauge_array(gauges).for_postures(np.ndim(t) - 1).travel
    # Plain ints: numpy takes an IntEnum member several times slower than an int.
    status = np.full(np.shape(t), int(Status.VALID), dtype=np.int8)
    with np.errstate(invalid="ignore"):
        status[t > travel] = Status.NO_CONTACT
        status[t < 0] = Status.OVERTRAVEL
    status[np.isnan(t)] = Status.MISSED
    return status


def readings_from_distances(gauges: GaugeArray | Sequence[Gauge], t: np.ndarray
                            ) -> np.ndarray:
    """Ideal readings ``sign * (t - zero)`` (mm) from ray distances; NaN where the gauge is
    not in contact."""
    g = as_gauge_array(gauges).for_postures(np.ndim(t) - 1)
    return readings_of_status(g, t, status_of(g, t))


def readings_of_status(gauges: GaugeArray, t: np.ndarray, status: np.ndarray) -> np.ndarray:
    """:func:`readings_from_distances` of ``gauges`` (shaped to broadcast against ``t``)
    whose :func:`status_of` is known."""
    return np.where(status == int(Status.VALID), gauges.sign * (t - gauges.zero), np.nan)


def exact_readings(machine: MachineParams, gauges: GaugeArray | Sequence[Gauge],
                   rho: np.ndarray) -> np.ndarray:
    """Ideal (noise-free, unquantised) readings of the exact model; NaN if not valid."""
    return readings_from_distances(gauges, exact_ray_distances(machine, gauges, rho))


def pressed_past_travel(gauges: GaugeArray | Sequence[Gauge], centre: np.ndarray, rot: np.ndarray,
                        half: np.ndarray) -> np.ndarray:
    """Whether each gauge's target presses it past its travel: the target's box, grown by
    the body radius, meets the gauge axis behind the fully pushed-in tip (``t < 0``) and
    in front of the stand's end.  The boxes are :func:`exact_target_boxes`, ``(..., G,
    ...)``; the result has shape ``(..., G)``."""
    g = as_gauge_array(gauges).for_postures(np.ndim(centre) - 2)
    # The body is a cylinder around the gauge axis: grow the box across the axis only.
    along = to_box_frame(rot, g.direction)
    grown = half + GAUGE_BODY_RADIUS * np.sqrt(np.clip(1 - along**2, 0.0, 1.0))
    t_in, t_out = ray_box_interval(g.origin, g.direction, centre, rot, grown)
    return (t_in <= t_out) & (t_in < 0) & (t_out > -STAND_LENGTH)


#: A dial gauge's repeatability and display step are small against its travel: at most
#: this fraction of it.  A noisy, quantised reading then stays inside the env's
#: observation box (half a travel of margin is >= 25 sigma).
MAX_NOISE_FRACTION: float = 1 / 50
#: Finest display step accepted (mm): no dial gauge resolves a nanometre, and dividing a
#: reading by a subnormal step overflows to infinity.
MIN_RESOLUTION: float = 1e-6


def check_noise(sigma: object, resolution: object, travel: float = DEFAULT_TRAVEL, *,
                names: tuple[str, str] = ("gauge_sigma", "gauge_resolution")) -> GaugeNoise:
    """The noise of a dial gauge with ``travel`` mm of travel, or ``ValueError`` naming the
    bad value (``names``: what the caller calls sigma and resolution).

    Repeatability ``sigma`` and display step ``resolution`` (mm, 0 = ideal) must be real
    numbers in [0, travel * MAX_NOISE_FRACTION]; a non-zero step at least MIN_RESOLUTION.
    """
    limit = travel * MAX_NOISE_FRACTION
    rule = (f"a dial gauge's repeatability and resolution lie in [0, travel/"
            f"{1 / MAX_NOISE_FRACTION:g}] = [0, {limit:g}] mm")
    for name, value in zip(names, (sigma, resolution), strict=True):
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"{name} must be a number (mm), got {value!r}")
        if not (np.isfinite(value) and 0 <= value <= limit):
            raise ValueError(f"{name} {value:g} mm is out of range: {rule}")
    if 0 < resolution < MIN_RESOLUTION:  # type: ignore[operator]
        raise ValueError(f"{names[1]} {resolution:g} mm is finer than any dial gauge's: "
                         f"use 0 (ideal) or at least {MIN_RESOLUTION:g} mm")
    return GaugeNoise(float(sigma), float(resolution))  # type: ignore[arg-type]


@dataclass(frozen=True)
class GaugeNoise:
    """Repeatability noise (normal, ``sigma`` mm) and display resolution (mm); 0 = ideal."""

    sigma: float = DEFAULT_SIGMA
    resolution: float = DEFAULT_RESOLUTION

    def __post_init__(self) -> None:
        for name in ("sigma", "resolution"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"gauge {name} must be a finite number >= 0")

    def apply(self, readings: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy, quantised readings (NaN stays NaN).  Noise is drawn for every gauge so
        the random stream does not depend on which readings are valid."""
        return self.applied(readings, self.draws(rng, np.shape(readings)))

    @staticmethod
    def draws(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Standard normal draws for readings of ``shape``, as :meth:`apply` takes them."""
        return rng.normal(0.0, 1.0, shape)

    def applied(self, readings: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """:meth:`apply` with the standard normal ``draws`` given: a batch of machines draws
        from one stream per machine."""
        noisy = np.asarray(readings, dtype=float) + draws * self.sigma
        if self.resolution > 0:
            # A dial shows a multiple of its step: 1.14, not 114 * 0.01 = 1.1400000000000001
            # (rounding to 12 decimals gives the double nearest the shown decimal, far
            # below any step a gauge has).
            noisy = np.round(np.round(noisy / self.resolution) * self.resolution, 12)
        return noisy

    @property
    def effective_sigma(self) -> float:
        """Standard deviation of one reading: noise plus uniform quantisation error."""
        return float(np.hypot(self.sigma, self.resolution / np.sqrt(12)))
