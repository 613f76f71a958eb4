"""Installing gauges on their magnetic stands: rays aimed at their slots, the preset's
installation errors, the technician's zeroing at the Zero posture, and the four stand
parameters an estimator fits per mounting.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from typing import overload

import numpy as np

from orthoglide_env.instruments.gauges import DEFAULT_TRAVEL, Gauge, GaugeArray, spec_arrays
from orthoglide_env.instruments.rays import exact_ray_distances, target_boxes
from orthoglide_env.instruments.slots import PLATFORM_AIM, GaugeSpec, Part, on_platform
from orthoglide_env.model.errors import AXIS_NAMES, ErrorPreset, MachineParams
from orthoglide_env.model.kinematics import cross, direct, divided, dot


def ideal_rays(specs: tuple[GaugeSpec, ...] | list[GaugeSpec], machine: MachineParams,
               travel: float = DEFAULT_TRAVEL) -> tuple[np.ndarray, np.ndarray]:
    """Rays of perfectly installed gauges: each aimed at its place on its target's face at
    the Zero posture of ``machine`` (a bar's ``at``, a carriage face's middle, the
    platform face's :data:`PLATFORM_AIM`), the plunger at mid-travel.  Origins
    ``(*batch, n, 3)`` and directions ``(n, 3)`` (a stand's nominal direction is a world
    axis)."""
    zero = np.zeros(3)
    g = spec_arrays(specs)
    centre, rot, half = target_boxes(machine, g, zero, direct(machine, zero))
    n = len(specs)
    face = g.face
    direction = np.array([s.approach for s in specs])[:, None] * np.eye(3)[g.axis]
    # The place on the face, in the box's frame: along a bar from its platform end
    # (at=0) to its carriage end (at=1); off a platform face's centre; a carriage face's
    # middle.
    clearance = machine.design.bar_clearance
    along = np.where(g.part == Part.BAR, (0.5 - g.at) * 2 * (half[..., 0] + clearance), 0.0)
    aside = np.where((np.arange(3) != face[:, None]) & on_platform(g.part)[:, None],
                     -PLATFORM_AIM, 0.0)
    local = aside + along[..., None] * np.eye(3)[0]
    place = rot[..., 0] * local[..., 0, None] + rot[..., 1] * local[..., 1, None] + (
        rot[..., 2] * local[..., 2, None])
    point = centre + place - direction * half[..., np.arange(n), face][..., None]
    return point - direction * (travel / 2), direction


# --- the stand's installation, as an estimator sees it ------------------------------------
#: A stand is never exactly where the layout says.  Sliding it along its own measuring
#: axis only moves the zero, and turning the gauge about that axis changes nothing, so its
#: installation has four effective parameters: the ray's shift along the two other world
#: axes (mm) and its tilt toward them (rad).
STAND_PARAMS: tuple[str, ...] = ("shift", "shift", "tilt", "tilt")


def stand_axes(spec: GaugeSpec) -> tuple[int, int]:
    """The two world axes across a gauge's measuring axis, in x, y, z order."""
    a, b = (k for k in range(3) if k != spec.axis)
    return a, b


def stand_names(mounting: str, spec: GaugeSpec) -> list[str]:
    """Names of a mounting's four stand parameters, e.g. ``x-leg/y@0.5.shift_x``."""
    a, b = (AXIS_NAMES[k] for k in stand_axes(spec))
    return [f"{mounting}.shift_{a}", f"{mounting}.shift_{b}",
            f"{mounting}.tilt_{a}", f"{mounting}.tilt_{b}"]


def across_axes(specs: tuple[GaugeSpec, ...] | list[GaugeSpec]) -> np.ndarray:
    """Unit vectors of the two cross axes of each gauge, shape (n, 2, 3) (read-only: made
    once per set of specs)."""
    return _across_axes(tuple(specs))


@lru_cache(maxsize=256)
def _across_axes(specs: tuple[GaugeSpec, ...]) -> np.ndarray:
    out = np.stack([np.eye(3)[list(stand_axes(s))] for s in specs]).reshape(len(specs), 2, 3)
    out.setflags(write=False)
    return out


def stand_rays(specs: tuple[GaugeSpec, ...] | list[GaugeSpec], origins: np.ndarray,
               directions: np.ndarray, stand: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays of stands installed with errors ``stand`` (shape ``(*batch, n, 4)``, in
    :data:`STAND_PARAMS` order) from the ideal ``origins`` and ``directions``."""
    across = across_axes(specs)
    stand = np.asarray(stand, dtype=float)
    origin = origins + np.einsum("...gk,gkj->...gj", stand[..., :2], across)
    direction = directions + np.einsum("...gk,gkj->...gj", stand[..., 2:], across)
    return origin, divided(direction, np.sqrt(dot(direction, direction)))


def stand_errors(specs: tuple[GaugeSpec, ...] | list[GaugeSpec], origins: np.ndarray,
                 directions: np.ndarray, ideal_origins: np.ndarray, ideal_directions: np.ndarray
                 ) -> np.ndarray:
    """The stand parameters (n, 4) of installed rays relative to ideal ones: the inverse of
    :func:`stand_rays` (the shift is measured where the ray crosses the plane through the
    ideal origin normal to the ideal direction).  For scoring against the truth only."""
    across = across_axes(specs)
    d0 = ideal_directions
    slope = np.sum(directions * d0, axis=-1, keepdims=True)
    s = np.sum((ideal_origins - origins) * d0, axis=-1, keepdims=True) / slope
    crossing = origins + s * directions - ideal_origins
    tilt = np.einsum("gj,gkj->gk", directions / slope, across)
    return np.concatenate([np.einsum("gj,gkj->gk", crossing, across), tilt], axis=-1)


def install(specs: tuple[GaugeSpec, ...] | list[GaugeSpec], machine: MachineParams | None = None, *,
            travel: float | None = None, preset: ErrorPreset | None = None,
            rng: np.random.Generator | None = None) -> list[Gauge]:
    """Install gauges on ``machine`` (default nominal) as the paper does: each aimed at
    its place on its target's face at the Zero posture, plus the preset's installation
    errors (stand position and tilt) when ``preset`` and ``rng`` are given.

    The zero is provisional; :func:`zero_gauges` sets the gauges up at the Zero posture.
    ``travel``: default the machine design's gauge travel.
    """
    machine = machine if machine is not None else MachineParams()
    travel = machine.design.gauge_travel if travel is None else travel
    if travel <= 0:
        raise ValueError("gauge travel must be positive")
    if not specs:
        return []
    errors = (installation_errors(len(specs), preset, rng)
              if preset is not None and rng is not None else None)
    return install_array(specs, machine, travel=travel, errors=errors).to_gauges()


def installation_errors(count: int, preset: ErrorPreset, rng: np.random.Generator
                        ) -> np.ndarray:
    """The preset's installation errors of ``count`` stands, drawn from ``rng`` stand by
    stand (position, then tilt): shape ``(count, 2, 3)``, the stand's position error (mm)
    and the rotation vector (rad) that tilts its measuring axis."""
    draws = [[rng.normal(0.0, preset.gauge_position, 3), rng.normal(0.0, preset.gauge_tilt, 3)]
             for _ in range(count)]
    return np.array(draws, dtype=float).reshape(count, 2, 3)


def install_array(specs: tuple[GaugeSpec, ...] | list[GaugeSpec], machine: MachineParams, *,
                  travel: float | None = None, errors: np.ndarray | None = None) -> GaugeArray:
    """:func:`install` for a batch of machines: the gauges of ``specs`` aimed at their targets
    on every machine of ``machine``, moved by installation ``errors`` (shape
    ``(*batch, G, 2, 3)``, see :func:`installation_errors`) when given.  ``travel``:
    default the machine design's gauge travel."""
    travel = machine.design.gauge_travel if travel is None else travel
    specs = list(specs)
    origin, direction = ideal_rays(specs, machine, travel)
    direction = np.broadcast_to(direction, origin.shape)
    if errors is not None:
        errors = np.asarray(errors, dtype=float)
        origin = origin + errors[..., 0, :]
        direction = direction + cross(errors[..., 1, :], direction)
        direction = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    g = spec_arrays(specs)
    # The reading runs along the world axis, whichever side the stand is on.
    sign = np.sign(direction[..., np.arange(len(specs)), g.axis])
    return replace(g, origin=origin, direction=direction, sign=sign, travel=float(travel),
                   zero=travel / 2)


@overload
def zero_gauges(gauges: GaugeArray, t_at_zero: np.ndarray) -> GaugeArray: ...
@overload
def zero_gauges(gauges: list[Gauge], t_at_zero: np.ndarray) -> list[Gauge]: ...
def zero_gauges(gauges: GaugeArray | list[Gauge], t_at_zero: np.ndarray
                ) -> GaugeArray | list[Gauge]:
    """Set up each gauge at the Zero posture as a technician does: slide it in its holder
    until the plunger sits at mid-travel, then zero the dial there.

    ``t_at_zero`` are the ray distances measured at Zero before the adjustment; a gauge
    whose ray misses its target (NaN) cannot be set up and raises ``ValueError``.  The
    result has the type of ``gauges`` (a list of one machine's, or a :class:`GaugeArray`).
    """
    if isinstance(gauges, GaugeArray):
        return gauges.zeroed(t_at_zero)
    return GaugeArray.of(gauges).zeroed(t_at_zero).to_gauges()


def installed_on(machine: MachineParams, gauges: list[Gauge]) -> list[Gauge]:
    """The gauges set up and zeroed by the exact model at the Zero posture of ``machine``."""
    return zero_gauges(gauges, exact_ray_distances(machine, gauges, np.zeros(3)))
