"""The exact model of an experiment's readings, batched over parameter vectors.

A *reading layout* says where readings were taken: which gauge mountings (stand installations)
and, for every reading, its mounting and the commanded posture.  The model reading of a
mounting at a posture is ``sign * t`` with ``t`` the distance along the stand's ray to the
plane of the bar face it is aimed at (:func:`orthoglide_env.instruments.rays.face_distances`),
less, for a reference gauge at Zero, the gauge block's nominal length over the cosine of
the ray's tilt (:attr:`ReadingLayout.through`; its derivative over the tilt, the length times the
tilt, about 0.25 mm/rad for the stands' 5 mrad, is left out of :func:`jacobian`); the
gauge's zero is one unknown constant per mounting, which estimators eliminate, so the
model leaves it out.

The parameter vector is the one of :mod:`calibrators.estimators.parameters`: 27 machine errors, then
four stand parameters per mounting.  Any leading dimensions of it are a batch (machines,
or the perturbations of a finite-difference Jacobian), evaluated in one numpy pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import NamedTuple

import numpy as np

from orthoglide_env.instruments.ballbar import BallbarSpec, centring_sigma
from orthoglide_env.instruments.gauges import Gauge, GaugeArray, spec_arrays
from orthoglide_env.instruments.interferometer import InterferometerAxis
from orthoglide_env.instruments.rays import boxes_at, face_normals, plane_distances
from orthoglide_env.instruments.slots import GaugeSpec, Part, on_platform
from orthoglide_env.instruments.stands import (
    across_axes,
    ideal_rays,
    stand_errors,
    stand_names,
    stand_rays,
)
from orthoglide_env.instruments.step_gauge import StepGaugeSpec, face_lengths, faces_of
from orthoglide_env.model.boxes import bar_normal_pullback
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import (
    AXIS_NAMES,
    DEFAULT_PRESET,
    ERROR_NAMES,
    PRESETS,
    ErrorPreset,
    MachineParams,
    error_group,
)
from orthoglide_env.model.kinematics import (
    ATTACH_COLUMN,
    CARRIAGE_COLUMNS,
    carriage_parts,
    carriage_points,
    direct,
    divided,
    dot,
    platform_points,
    scaled,
    sensitivity_along,
    skew,
    tcp_sensitivity_factors,
)
from orthoglide_env.world.table import REFERENCE_LENGTH_MM

N_MACHINE: int = len(ERROR_NAMES)


@dataclass(frozen=True)
class TrackerAxis:
    """One coordinate (0, 1, 2 for x, y, z) of a laser tracker's reading of the reflector
    on the platform, in the tracker's own frame.  A tracker station's three coordinates are
    three mountings named ``STATION.x``, ``.y``, ``.z``: each has its own unknown offset
    (the station's position, eliminated like a gauge's zero), and the station has three
    unknown rotations (``STATION.rot_x``, ...).  The reflector's place on the platform is an
    offset too: the platform only translates."""

    component: int

    @property
    def slot(self) -> str:
        return f"tracker/{AXIS_NAMES[self.component]}"


#: What a reading reads: a dial gauge's slot, a tracker's coordinate, an
#: interferometer's drive (whose model reading is the carriage's offset along it: its
#: derivative by that drive's ``drho`` is 1, by every other error 0, and the zero of its
#: set-up takes the offset itself), a ballbar set-up (the TCP's distance from its
#: pivot, whose position is three unknowns of the set-up, less the bar's length), or a
#: step-gauge set-up (the TCP's coordinate along its axis less the nominal distance of the
#: face read from face 0; the set-up's zero takes where face 0 lies).
Spec = GaugeSpec | TrackerAxis | InterferometerAxis | BallbarSpec | StepGaugeSpec


def station_of(mounting: str) -> str:
    """The tracker station a tracker mounting belongs to (``tracker.x`` -> ``tracker``)."""
    return mounting.rsplit(".", 1)[0]


@dataclass(frozen=True)
class ParameterSpace:
    """Every parameter a fit could estimate for a set of mountings: the 27 machine errors in
    :data:`~orthoglide_env.model.errors.ERROR_NAMES` order, four stand parameters per gauge
    mounting (:data:`~orthoglide_env.instruments.stands.STAND_PARAMS`), three rotations per
    tracker station, then three coordinates per ballbar set-up: its pivot's offset (mm)
    from where the machine puts the TCP at the set-up's centre command."""

    mountings: tuple[str, ...] = ()
    specs: tuple[Spec, ...] = ()

    @cached_property
    def gauges(self) -> list[int]:
        """Indices of the gauge mountings."""
        return [k for k, s in enumerate(self.specs) if isinstance(s, GaugeSpec)]

    @cached_property
    def stations(self) -> list[str]:
        """Tracker stations, in order of first appearance."""
        return list(dict.fromkeys(station_of(m) for m, s in zip(self.mountings, self.specs,
                                                                strict=True)
                                  if isinstance(s, TrackerAxis)))

    @cached_property
    def ballbars(self) -> list[int]:
        """Indices of the ballbar set-ups."""
        return [k for k, s in enumerate(self.specs) if isinstance(s, BallbarSpec)]

    @cached_property
    def names(self) -> tuple[str, ...]:
        stands = [n for k in self.gauges for n in stand_names(self.mountings[k], self.specs[k])]
        rotations = [f"{st}.rot_{a}" for st in self.stations for a in AXIS_NAMES]
        centres = [f"{self.mountings[k]}.centre_{a}" for k in self.ballbars for a in AXIS_NAMES]
        return ERROR_NAMES + tuple(stands) + tuple(rotations) + tuple(centres)

    @cached_property
    def groups(self) -> tuple[str, ...]:
        """Group of every parameter: a machine-file key, ``stand_shift``, ``stand_tilt``,
        ``tracker_rotation`` or ``ballbar_centre``."""
        stands = ("stand_shift",) * 2 + ("stand_tilt",) * 2
        return (tuple(error_group(n) for n in ERROR_NAMES) + stands * len(self.gauges)
                + ("tracker_rotation",) * (3 * len(self.stations))
                + ("ballbar_centre",) * (3 * len(self.ballbars)))

    @property
    def centre_start(self) -> int:
        """The column of the first ballbar set-up's first centre coordinate."""
        return len(ERROR_NAMES) + 4 * len(self.gauges) + 3 * len(self.stations)

    def __len__(self) -> int:
        return self.centre_start + 3 * len(self.ballbars)



#: Scale of a tracker frame's rotation (rad) once its readings are turned into the
#: machine's frame by a best fit to the nominal machine: what is left is of the order of
#: the machine's own errors over its workspace, ~1 mm over ~100 mm.
TRACKER_ROTATION_SCALE: float = 1e-2
#: Scale of a ballbar pivot's offset from the TCP it was centred at (mm): the centring's
#: few micrometres (along the plane's normal a circle sees it to second order only: 5 um
#: change a 50 mm bar by 0.25 nm).
BALLBAR_CENTRE_SCALE: float = 0.01


def preset_sigmas(preset: ErrorPreset, space: ParameterSpace) -> np.ndarray:
    """A preset's sigma of every parameter of ``space``: the machine errors, each stand's
    installation tolerance, 0 for a tracker's frame (no preset says how it was turned),
    and a ballbar pivot's centring (the instrument's, whatever the preset)."""
    stands = [preset.gauge_position] * 2 + [preset.gauge_tilt] * 2
    return np.concatenate([preset.sigmas(), np.tile(stands, len(space.gauges)),
                           np.zeros(3 * len(space.stations)),
                           np.full(3 * len(space.ballbars), centring_sigma())])


def default_scales(space: ParameterSpace) -> np.ndarray:
    """Typical size of every parameter: the default preset's sigma, and
    :data:`TRACKER_ROTATION_SCALE` for a tracker's frame.  It makes the numerics unit-free
    (mm and rad) and sets what "identified" means: known better than this."""
    scale = preset_sigmas(PRESETS[DEFAULT_PRESET], space)
    scale[[g == "tracker_rotation" for g in space.groups]] = TRACKER_ROTATION_SCALE
    scale[[g == "ballbar_centre" for g in space.groups]] = BALLBAR_CENTRE_SCALE
    return np.where(scale > 0, scale, 1.0)

@dataclass(frozen=True)
class ReadingLayout:
    """Where an experiment's readings were taken."""

    mountings: tuple[str, ...]
    specs: tuple[Spec, ...]  # one per mounting
    mounting: np.ndarray  # (N,) index of each reading's mounting
    rho: np.ndarray  # (N, 3) commanded posture of each reading, mm
    machine_design: MachineDesign  # the design of the machine read

    @cached_property
    def _unique_postures(self) -> tuple[np.ndarray, np.ndarray]:
        # On first use: of a sweep's many identical layouts, only the one fitted needs it.
        postures, index = np.unique(self.rho, axis=0, return_inverse=True)
        return postures, np.ravel(index)

    def __len__(self) -> int:
        return len(self.mounting)

    @cached_property
    def space(self) -> ParameterSpace:
        return _space(self.mountings, self.specs)

    @cached_property
    def distinct(self) -> tuple[ReadingLayout, np.ndarray]:
        """The layout with each mounting read once at each of its postures, and every
        reading's row in it: repeated readings share their model and its derivatives."""
        key = self.posture_index * len(self.specs) + self.mounting
        _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
        if len(first) == len(self):
            return self, np.arange(len(self))
        return (ReadingLayout(self.mountings, self.specs, self.mounting[first],
                              self.rho[first], self.machine_design), np.ravel(inverse))

    @cached_property
    def gauge_reads(self) -> tuple[np.ndarray, np.ndarray]:
        """The dial gauges' readings, each mounting once at each of its postures: their
        rows of :attr:`postures` and their mountings (the model reads a gauge only where
        it was read, not at every posture)."""
        gauges = np.isin(self.mounting, self.space.gauges)
        key = np.unique(self.posture_index[gauges] * len(self.specs) + self.mounting[gauges])
        return key // len(self.specs), key % len(self.specs)

    @property
    def postures(self) -> np.ndarray:
        """The distinct postures (P, 3)."""
        return self._unique_postures[0]

    @property
    def posture_index(self) -> np.ndarray:
        """Each reading's row in :attr:`postures` (N,)."""
        return self._unique_postures[1]

    @cached_property
    def through(self) -> np.ndarray:
        """Per reading, the nominal length (mm) of the gauge block between the plunger and
        the face: a reference gauge's readings at Zero are through it, its others and every
        other gauge's are not (0)."""
        block = np.array([isinstance(s, GaugeSpec) and s.part == Part.REFERENCE
                          for s in self.specs])
        at_zero = ~self.rho.any(axis=-1)
        return np.where(block[self.mounting] & at_zero, REFERENCE_LENGTH_MM, 0.0)

    @cached_property
    def signs(self) -> np.ndarray:
        """Reading sign of every mounting: +1 when a gauge's plunger points along the world
        axis, and for a tracker coordinate."""
        gauges = [s for s in self.specs if isinstance(s, GaugeSpec)]
        signs = np.ones(len(self.specs))
        if gauges:
            _, directions = ideal_rays(gauges, MachineParams(design=self.machine_design))
            signs[self.space.gauges] = np.sign(
                directions[np.arange(len(gauges)), [s.axis for s in gauges]])
        return signs

    @cached_property
    def probed(self) -> np.ndarray:
        """Which readings are a step gauge's (N,)."""
        gauge = np.array([isinstance(s, StepGaugeSpec) for s in self.specs], dtype=bool)
        return gauge[self.mounting] if len(gauge) else np.zeros(len(self), dtype=bool)

    @cached_property
    def face_distances(self) -> np.ndarray:
        """Per reading, the nominal distance (mm) from face 0 of the step-gauge face it
        read (the face the nominal machine puts the TCP at); 0 for other readings."""
        out = np.zeros(len(self))
        for m, spec in enumerate(self.specs):
            if isinstance(spec, StepGaugeSpec):
                rows = np.flatnonzero(self.mounting == m)
                face = faces_of(self.machine_design, spec, self.rho[rows])[0]
                out[rows] = face_lengths()[np.clip(face, 0, len(face_lengths()) - 1)]
        return out

    @classmethod
    def of(cls, mountings: list[str], specs: list[Spec], rho: np.ndarray,
           machine_design: MachineDesign) -> ReadingLayout:
        """A layout from each reading's mounting name and spec, and its posture, on a
        machine of ``machine_design``."""
        spec_of: dict[str, Spec] = {}
        for name, spec in zip(mountings, specs, strict=True):
            known = spec_of.setdefault(name, spec)
            if known is not spec and known != spec:
                raise ValueError(f"mounting '{name}' holds two different instruments "
                                 f"({known.slot} and {spec.slot})")
        names = list(spec_of)
        position = {name: k for k, name in enumerate(names)}
        index = np.array([position[m] for m in mountings], dtype=int)
        return cls(tuple(names), tuple(spec_of[n] for n in names), index,
                   np.asarray(rho, dtype=float).reshape(-1, 3), machine_design)



@lru_cache(maxsize=64)
def _space(mountings: tuple[str, ...], specs: tuple[Spec, ...]) -> ParameterSpace:
    """The :class:`ParameterSpace` of ``mountings`` holding ``specs``, one for every layout
    of them: a sweep's fits (every machine its own layout of the same mountings) share
    its names and groups, made once."""
    return ParameterSpace(mountings, specs)


#: The earlier name of :class:`ReadingLayout` ("design" now means a MachineDesign only).
Design = ReadingLayout

class GaugeSight(NamedTuple):
    """What the dial gauges of machines ``(*b,)`` meet where they were read (the rows of
    :attr:`ReadingLayout.gauge_reads`, in that order; a layout and its
    :attr:`~ReadingLayout.distinct` one have the same): the part of the model that its
    readings (:func:`predict`) and their derivatives (:func:`jacobian`) share.  One
    computation serves both, so a fit passes the readings' own to the derivatives at the
    same parameters instead of computing them again, with the same bits (each machine's
    numbers are its own, whatever its batch)."""

    aim: np.ndarray  # (G, 3) each stand's ray's direction as aimed (a world axis)
    origins: np.ndarray  # (*b, G, 3) the rays as the stands hold them
    directions: np.ndarray  # (*b, G, 3)
    tcp: np.ndarray  # (*b, P, 3) the TCP at each posture of the layout
    a: np.ndarray  # (*b, R, 3) each reading's leg's R1 centre
    c: np.ndarray  # (*b, R, 3) and R2 centre
    centre: np.ndarray  # (*b, R, 3) its target box's centre
    normal: np.ndarray  # (*b, R, 3) and the normal of the face it reads
    t: np.ndarray  # (*b, R) the distance along its ray to the face's plane

    def rows(self, index: np.ndarray | slice | int) -> GaugeSight:
        """The sight of the machines ``index`` of the batch."""
        return GaugeSight(self.aim, *(x[index] for x in self[1:]))


def gauge_sight(theta: np.ndarray, layout: ReadingLayout,
                machine: MachineParams | None = None) -> GaugeSight:
    """The :class:`GaugeSight` of parameter vectors ``theta`` (``(*batch, n)``; their
    ``machine``, when made already) in a layout with dial gauges."""
    batch = theta.shape[:-1]
    if machine is None:
        machine = MachineParams.from_vector(theta[..., :N_MACHINE], layout.machine_design)
    gauges = layout.space.gauges
    specs = [layout.specs[k] for k in gauges]
    stand = theta[..., N_MACHINE:N_MACHINE + 4 * len(gauges)].reshape(*batch, -1, 4)
    ideal, aim = ideal_rays(specs, machine)
    origins, directions = stand_rays(specs, ideal, aim, stand)
    at, read = layout.gauge_reads
    gauge = np.searchsorted(gauges, read)  # (``space.gauges`` is in mounting order)
    postures = layout.postures.reshape((1,) * len(batch) + layout.postures.shape)
    tcp = direct(machine, postures)
    a, c, centre, normal, t = _gauge_targets(
        machine, spec_arrays([layout.specs[k] for k in read]), postures[..., at, :],
        tcp[..., at, :], origins[..., gauge, :], directions[..., gauge, :])
    return GaugeSight(aim, origins, directions, tcp, a, c, centre, normal, t)


def predict(theta: np.ndarray, layout: ReadingLayout, sight: GaugeSight | None = None
            ) -> np.ndarray:
    """Model readings (mm, up to one constant per mounting) of every reading of
    ``layout`` for parameter vectors ``theta`` of shape ``(*batch, n)``: ``(*batch, N)``;
    ``sight``: their :func:`gauge_sight`, when known."""
    theta = np.asarray(theta, dtype=float)
    batch = theta.shape[:-1]
    flat = theta.reshape(-1, theta.shape[-1])
    if len(flat) > 1 and bool((flat == flat[0]).all()):
        # Every fit of a batch starts at the same point (nominal): one evaluation serves all.
        one = None if sight is None else sight.rows(0)
        return np.broadcast_to(predict(flat[0], layout, one), (*batch, len(layout))).copy()
    space = layout.space
    machine = MachineParams.from_vector(theta[..., :N_MACHINE], layout.machine_design)
    postures = layout.postures.reshape((1,) * len(batch) + layout.postures.shape)
    values = np.zeros((*batch, len(layout.postures), len(layout.specs)))  # (*b, P, K)
    gauges = space.gauges
    if gauges:
        if sight is None:
            sight = gauge_sight(theta, layout, machine)
        directions = sight.directions
        at, read = layout.gauge_reads
        values[..., at, read] = sight.t
    stations = space.stations
    if stations:
        tcp = direct(machine, postures)  # (*b, P, 3)
        start = N_MACHINE + 4 * len(gauges)
        for k, station in enumerate(stations):
            rotation = rotation_matrices(theta[..., start + 3 * k:start + 3 * k + 3])
            seen = np.einsum("...ij,...pj->...pi", rotation, tcp)
            for m, (name, spec) in enumerate(zip(layout.mountings, layout.specs, strict=True)):
                if isinstance(spec, TrackerAxis) and station_of(name) == station:
                    values[..., m] = seen[..., spec.component]
    for m, spec in enumerate(layout.specs):
        if isinstance(spec, InterferometerAxis):
            values[..., m] = theta[..., None, spec.axis]
    if space.ballbars:
        tcp = direct(machine, postures)
        for m, pivot in zip(space.ballbars, _pivots(theta, layout, machine), strict=True):
            values[..., m] = (np.linalg.norm(tcp - pivot[..., None, :], axis=-1)
                              - layout.specs[m].length)
    probed = layout.probed
    if probed.any():
        tcp = direct(machine, postures)
        for m, spec in enumerate(layout.specs):
            if isinstance(spec, StepGaugeSpec):
                values[..., m] = tcp[..., spec.axis]
    rows = values[..., layout.posture_index, layout.mounting]
    if probed.any():
        rows[..., probed] -= layout.face_distances[probed]
    through = np.flatnonzero(layout.through)
    if len(through):
        gauge = np.full(len(layout.specs), -1)
        gauge[gauges] = np.arange(len(gauges))
        axes = np.array([layout.specs[k].axis for k in gauges])
        cosines = np.abs(directions[..., np.arange(len(gauges)), axes])
        rows[..., through] -= (layout.through[through]
                               / cosines[..., gauge[layout.mounting[through]]])
    return layout.signs[layout.mounting] * rows


def _pivots(theta: np.ndarray, layout: ReadingLayout, machine: MachineParams
            ) -> list[np.ndarray]:
    """Each ballbar set-up's pivot (``(*batch, 3)``, mm) for parameter vectors ``theta``
    (``(*batch, n)``) and their ``machine``: where the machine puts the TCP at the
    set-up's centre command (the pivot was centred there), plus its centring offset."""
    space = layout.space
    batch = theta.shape[:-1]
    start = space.centre_start
    return [direct(machine, np.broadcast_to(np.asarray(layout.specs[m].centre, dtype=float),
                                            (*batch, 3)))
            + theta[..., start + 3 * k:start + 3 * k + 3]
            for k, m in enumerate(space.ballbars)]


def rotation_matrices(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of rotation vectors ``(..., 3)`` (Rodrigues),
    batched (scipy's Rotation holds one batch axis only)."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    k = skew(rotvec)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(angle > 1e-8, np.sin(angle) / angle, 1.0 - angle**2 / 6)
        b = np.where(angle > 1e-8, (1 - np.cos(angle)) / angle**2, 0.5 - angle**2 / 24)
    return np.eye(3) + a * k + b * (k @ k)


def rotated_derivatives(rotvec: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Derivative of ``R(rotvec) @ points`` over the rotation vector, premultiplied by
    ``R^T``: ``-[p]x J_r(rotvec)`` with the right Jacobian of SO(3), ``J_r = I - (1 - cos
    a) / a^2 [w]x + (a - sin a) / a^3 [w]x^2`` (``a = |w|``), ``(..., 3, 3)``."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    k = skew(rotvec)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(angle > 1e-2, (1 - np.cos(angle)) / angle**2, 0.5 - angle**2 / 24)
        b = np.where(angle > 1e-2, (angle - np.sin(angle)) / angle**3, 1 / 6 - angle**2 / 120)
    right = np.eye(3) - a * k + b * (k @ k)
    return -skew(points) @ right


def jacobian(theta: np.ndarray, layout: ReadingLayout, free: np.ndarray, scale: np.ndarray,
             sight: GaugeSight | None = None) -> np.ndarray:
    """Derivative of :func:`predict` over the ``free`` parameters, per unit of their
    ``scale``: ``(*batch, N, n_free)``; ``sight``: the :func:`gauge_sight` of ``theta``
    (flattened to one batch axis), when known.

    By the chain rule, each reading's kinematics solved once: a reading ``t = (n . (c -
    o) - h sign(n . d)) / (n . d)`` depends on the machine through its target box (the
    leg's R1 and R2 centres, or the TCP: their derivatives in closed form, the TCP's by the
    implicit function theorem) and its stand's ideal ray, and on the stand parameters
    through its ray alone."""
    theta = np.asarray(theta, dtype=float)
    batch = theta.shape[:-1]
    flat = theta.reshape(-1, theta.shape[-1])
    idx = np.flatnonzero(free)
    # Every fit of a batch starts at the same point (nominal): one evaluation serves all.
    same = len(flat) > 1 and bool((flat == flat[0]).all())
    distinct, rows = layout.distinct
    if sight is not None and same:
        sight = sight.rows(slice(0, 1))
    full = _derivatives(flat[:1] if same else flat, distinct, np.asarray(free, dtype=bool),
                        sight=sight)
    if len(idx) == full.shape[-1]:
        full *= scale
    else:
        full = full[..., idx] * scale[idx]
    full = full[:, rows]
    if same:
        full = np.repeat(full, len(flat), axis=0)
    return full.reshape(*batch, len(layout), len(idx))


def _derivatives(theta: np.ndarray, layout: ReadingLayout, wanted: np.ndarray,
                 aimed: bool = True, sight: GaugeSight | None = None) -> np.ndarray:
    """Derivative of every reading over every parameter, ``(B, N, n)`` for ``theta``
    ``(B, n)``; the stands' columns are left at zero unless one of them is ``wanted``, and
    so are the machine's errors' kinds (:func:`~orthoglide_env.model.kinematics.
    tcp_sensitivity_factors`) of which none is;
    ``aimed`` False: a gauge's ray stays where its stand was aimed (see
    :func:`_gauge_derivatives`); ``sight``: ``theta``'s :func:`gauge_sight`, when known."""
    space = layout.space
    machine = MachineParams.from_vector(theta[:, :N_MACHINE], layout.machine_design)
    postures = layout.postures[None]
    if space.gauges and sight is None:
        sight = gauge_sight(theta, layout, machine)
    p = direct(machine, postures) if sight is None else sight.tcp  # (B, P, 3)
    # The TCP's derivative (B, P, 3, 27) as its factors (B, P, 3, 3) and (B, P, 27).
    columns = np.flatnonzero(wanted[:N_MACHINE])
    inv, row = tcp_sensitivity_factors(machine, postures, p, columns)
    out = np.zeros((len(theta), len(layout), theta.shape[-1]))
    at = layout.posture_index
    gauges = space.gauges
    if gauges:
        where = np.full(len(layout.specs), -1)
        where[gauges] = np.arange(len(gauges))
        rows = np.flatnonzero(where[layout.mounting] >= 0)
        _gauge_derivatives(theta, layout, machine, sight, (inv, row), rows,  # type: ignore[arg-type]
                           where[layout.mounting[rows]], at[rows], out,
                           stands=bool(wanted[N_MACHINE:N_MACHINE + 4 * len(gauges)].any()),
                           columns=columns, aimed=aimed)
    for m, spec in enumerate(layout.specs):
        if isinstance(spec, InterferometerAxis):
            out[:, layout.mounting == m, spec.axis] = 1.0
        if isinstance(spec, StepGaugeSpec):
            # The TCP's coordinate along the gauge's axis.
            rows = np.flatnonzero(layout.mounting == m)
            along = np.zeros((len(theta), len(rows), 3))
            along[..., spec.axis] = 1.0
            out[:, rows, :N_MACHINE] = sensitivity_along(inv[:, at[rows]], row[:, at[rows]],
                                                         along)
    pivots = _pivots(theta, layout, machine)
    for k, (m, pivot) in enumerate(zip(space.ballbars, pivots, strict=True)):
        # The distance moves with the TCP along the bar, and against the pivot (the TCP
        # where it was centred).
        rows = np.flatnonzero(layout.mounting == m)
        along = p[:, at[rows]] - pivot[:, None, :]
        along = along / np.linalg.norm(along, axis=-1, keepdims=True)
        centre = np.broadcast_to(layout.specs[m].centre, (len(theta), 1, 3))
        at_centre = tcp_sensitivity_factors(machine, centre, direct(machine, centre))
        out[:, rows, :N_MACHINE] = (
            sensitivity_along(inv[:, at[rows]], row[:, at[rows]], along)
            - sensitivity_along(*at_centre, along))
        columns = space.centre_start + 3 * k + np.arange(3)
        out[:, rows[:, None], columns] = -along
    start = N_MACHINE + 4 * len(gauges)
    for k, station in enumerate(space.stations):
        rows = np.flatnonzero([isinstance(layout.specs[m], TrackerAxis)
                               and station_of(layout.mountings[m]) == station
                               for m in layout.mounting])
        component = np.array([layout.specs[m].component for m in layout.mounting[rows]])
        columns = slice(start + 3 * k, start + 3 * k + 3)
        rotation = rotation_matrices(theta[:, columns])
        # Component i of R p moves with row i of R.
        out[:, rows, :N_MACHINE] = sensitivity_along(inv[:, at[rows]], row[:, at[rows]],
                                                     rotation[:, component])
        turned = np.einsum("bij,brjk->brik", rotation, rotated_derivatives(
            theta[:, None, columns], p[:, at[rows]]))
        out[:, rows, columns] = turned[:, np.arange(len(rows)), component]
    return out


def carriage_derivatives(layout: ReadingLayout) -> np.ndarray:
    """Derivative (N, 3) of every reading of ``layout`` over each drive's carriage, moved
    where and when that reading was taken, at the nominal machine: the reading's
    derivative by the encoder offsets, but for a ballbar's only through the TCP it reads
    (its pivot was centred where the carriages were then: :func:`pivot_derivatives`
    takes that part), and for a dial gauge's only through the target it touches: its
    stand was aimed at the machine's geometry at Zero, not at where the carriages stood
    then, and what they were off when its plunger was zeroed is a constant of the
    mounting that its zero takes."""
    space = layout.space
    theta = np.zeros(len(space))
    drho = np.isin(np.arange(len(space)), np.arange(3))
    distinct, rows = layout.distinct
    out = _derivatives(theta[None], distinct, drho, aimed=False)[0, rows][:, :3]
    return out - pivot_derivatives(layout) if space.ballbars else out


def pivot_derivatives(layout: ReadingLayout) -> np.ndarray:
    """Derivative (N, 3) of every reading of ``layout`` over each drive's carriage where
    and when its ballbar set-up's pivot was centred, at the nominal machine: the pivot
    sits where the carriages then put the TCP at the centre command, so a carriage's
    error there moves the pivot and, against it, the reading along the bar.  Zero for
    every other instrument's readings."""
    out = np.zeros((len(layout), 3))
    space = layout.space
    if not space.ballbars:
        return out
    theta = np.zeros(len(space))
    machine = MachineParams.from_vector(theta[None, :N_MACHINE], layout.machine_design)
    for m, pivot in zip(space.ballbars, _pivots(theta[None], layout, machine), strict=True):
        rows = np.flatnonzero(layout.mounting == m)
        centre = np.broadcast_to(layout.specs[m].centre, (1, 1, 3))
        p = direct(machine, centre)
        along = direct(machine, layout.rho[rows][None]) - pivot[:, None, :]
        along = along / np.linalg.norm(along, axis=-1, keepdims=True)
        at_centre = tcp_sensitivity_factors(machine, centre, p)
        out[rows] = -sensitivity_along(*at_centre, along)[0, :, :3]
    return out


def _gauge_targets(machine: MachineParams, g: GaugeArray, rho: np.ndarray, p: np.ndarray,
                   origins: np.ndarray, directions: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What gauge readings ``g`` (``(R,)``) of ``machine`` (batch ``(*b,)``) touch at
    commands ``rho`` and TCPs ``p`` (``(*b | 1, R, 3)``), along rays ``origins`` and
    ``directions`` (``(*b, R, 3)``): their legs' R1 and R2 centres, their target boxes'
    centres (:func:`~orthoglide_env.instruments.rays.boxes_at`), the normals of the faces
    read, and the distance along each ray to its face's plane
    (:func:`~orthoglide_env.instruments.rays.face_distances`, each reading alone)."""
    legs = np.maximum(g.leg, 0)
    each = np.arange(len(legs))
    a = carriage_points(machine, rho)[..., each, legs, :]
    c = platform_points(machine, p)[..., each, legs, :]
    centre, rot, half = boxes_at(g, a, c, p, machine.design)
    normal = face_normals(rot, g.face)
    return a, c, centre, normal, plane_distances(centre, rot, half, g.face, origins,
                                                 directions, normal)


def _gauge_derivatives(theta: np.ndarray, layout: ReadingLayout, machine: MachineParams,
                       sight: GaugeSight, dp: tuple[np.ndarray, np.ndarray], rows: np.ndarray,
                       gauge: np.ndarray, at: np.ndarray, out: np.ndarray, stands: bool,
                       columns: np.ndarray, aimed: bool = True) -> None:
    """Fill ``out[:, rows]``: the derivatives of the gauge readings ``rows`` (their gauge
    among the layout's gauges, their posture index ``at``, what they meet ``sight``) over
    the machine's errors ``columns`` (the others are left as they are), and over the stand
    parameters when ``stands``.  ``aimed``: the ray moves with the machine at Zero, where
    its stand was aimed (a geometric error); else it stays (an error of the carriages at
    the reading only, which the stand's aim did not see)."""
    space = layout.space
    specs = [layout.specs[k] for k in space.gauges]
    count = len(specs)
    stand = theta[:, N_MACHINE:N_MACHINE + 4 * count].reshape(-1, count, 4)
    aim = sight.aim
    g = spec_arrays([specs[j] for j in gauge])
    legs = np.maximum(g.leg, 0)
    postures = layout.postures[at]
    o, d = sight.origins[:, gauge], sight.directions[:, gauge]
    a, c, centre, normal, t = sight.a, sight.c, sight.centre, sight.normal, sight.t
    # The sight holds the readings in ``gauge_reads``' order; a layout of distinct readings
    # only is its own ``distinct`` layout, in its readings' order.
    reads_at, reads = layout.gauge_reads
    count_specs = len(layout.specs)
    order = np.searchsorted(reads_at * count_specs + reads,
                            at * count_specs + layout.mounting[rows])
    if not np.array_equal(order, np.arange(len(order))):
        a, c, centre, normal, t = (x[:, order] for x in (a, c, centre, normal, t))
    nd = dot(normal, d)
    towards_centre = divided(normal, nd)  # dt/dc, and -dt/do
    # dt/dn = (c - hit) / (n . d) through the bar's normal, which turns with v = c - a.
    turn = bar_normal_pullback(divided(centre - o - scaled(d, t), nd), a, c, legs, g.face)
    bar = (g.part == Part.BAR)[:, None]
    d_a = np.where(bar, towards_centre / 2 - turn,
                   np.where((g.part == Part.CARRIAGE)[:, None], towards_centre, 0.0))
    d_c = np.where(bar, towards_centre / 2 + turn, 0.0)
    d_p = np.where(on_platform(g.part)[:, None], towards_centre, 0.0)
    # The machine moves the target through A, C and p at the posture, and the ray's
    # origin (aimed at Zero) through the same points at Zero: on a bar at ``at * A + (1 -
    # at) * C``, on a carriage with A, on the platform with p.
    zero = np.zeros((1, 1, 3))
    p_zero = direct(machine, zero)
    origin = [np.where(bar, g.at[:, None], np.where((g.part == Part.CARRIAGE)[:, None], 1.0, 0.0)),
             np.where(bar, 1 - g.at[:, None], 0.0),
             np.where(on_platform(g.part)[:, None], 1.0, 0.0)]
    inv_zero, row_zero = tcp_sensitivity_factors(machine, zero, p_zero, columns)
    machine_part = _through_leg(machine, postures[None], (dp[0][:, at],
                                                          dp[1][:, at[:, None], columns]),
                                legs, d_a, d_c, d_p, columns)
    if aimed:
        machine_part = machine_part - _through_leg(
            machine, zero, (inv_zero, row_zero[..., columns]), legs,
            *(w * towards_centre for w in origin), columns)
    sign = layout.signs[layout.mounting[rows]]
    out[:, rows[:, None], columns] = sign[:, None] * machine_part
    if not stands:
        return
    # Stand parameters move the ray only: shifts its origin across the measuring axis,
    # tilts its direction d = (d0 + tilt . across) / |...|.
    across = across_axes(specs)[gauge]  # (R, 2, 3)
    tilt = stand[:, gauge, 2:]
    raw = aim[gauge] + tilt[..., 0, None] * across[:, 0] + tilt[..., 1, None] * across[:, 1]
    size = np.sqrt(dot(raw, raw))[..., None, None]
    turned = (across - d[..., None, :] * dot(d[..., None, :], across)[..., None]) / size
    shifts = -dot(towards_centre[..., None, :], across)
    tilts = -t[..., None] * dot(towards_centre[..., None, :], turned)
    columns = N_MACHINE + 4 * gauge[:, None] + np.arange(4)
    out[:, rows[:, None], columns] = sign[:, None] * np.concatenate([shifts, tilts], axis=-1)


def _through_leg(machine: MachineParams, rho: np.ndarray, dp: tuple[np.ndarray, np.ndarray],
                 legs: np.ndarray, d_a: np.ndarray, d_c: np.ndarray, d_p: np.ndarray,
                 columns: np.ndarray) -> np.ndarray:
    """``d_a . dA/dtheta + d_c . dC/dtheta + d_p . dp/dtheta`` over the errors ``columns``
    (sorted, of the 27), for the R1 centre A and R2 centre C of leg ``legs`` (``(R,)``) and
    the TCP p at commands ``rho`` (``(..., R, 3)``, or one posture for all), the TCP's
    derivative ``dp`` as its :func:`~orthoglide_env.model.kinematics.
    tcp_sensitivity_factors` (``(B, R, 3, 3)``, and the entries of ``columns`` ``(B, R,
    K)``, or one posture for all): ``(B, R, K)``.

    Each entry is the same sum, in the same order, as in the derivative over all 27: a fit
    of a few errors (the paper's six) forms only their columns, with the same bits."""
    out = sensitivity_along(*dp, d_c + d_p, columns)
    # Where each leg's carriage and attachment columns sit among ``columns`` (-1: not
    # wanted); a leg's are apart from the other legs' and from each other.
    position = np.full(N_MACHINE, -1)
    position[columns] = np.arange(len(columns))
    carriage = position[CARRIAGE_COLUMNS[legs]]  # (R, 5)
    kinds = [carriage[:, :1], carriage[:, 1:3], carriage[:, 3:]]  # encoder, tilts, offsets
    parts = carriage_parts(machine, rho, d_a[..., None, :], legs[:, None],
                           tuple(bool((kind >= 0).any()) for kind in kinds))
    for kind, part in zip(kinds, parts, strict=True):
        r, k = np.nonzero(kind >= 0)
        if len(r):
            out[:, r, kind[r, k]] += np.broadcast_to(
                part[..., 0, :], (*out.shape[:2], kind.shape[1]))[:, r, k]
    attach = position[ATTACH_COLUMN + 3 * legs[:, None] + np.arange(3)]  # (R, 3)
    r, k = np.nonzero(attach >= 0)
    if len(r):
        out[:, r, attach[r, k]] += d_c[..., r, k]
    return out


def parameters_of(layout: ReadingLayout, machine: MachineParams, gauges: list[Gauge]) -> np.ndarray:
    """The true parameter vector of a simulated experiment: the machine's errors and the
    stand parameters of its installed ``gauges`` (matched to the layout's mountings by
    slot).  For scoring an estimate; an agent never sees it."""
    by_slot = {g.spec.slot: g for g in gauges}
    slots = [spec.slot for spec in layout.specs]
    missing = [m for m, slot in zip(layout.mountings, slots, strict=True) if slot not in by_slot]
    if missing:
        raise ValueError(f"no installed gauge for mounting(s) {missing}")
    installed = [by_slot[slot] for slot in slots]
    origins, directions = ideal_rays(layout.specs, machine)
    stand = stand_errors(layout.specs, np.array([g.origin for g in installed]),
                         np.array([g.direction for g in installed]), origins, directions)
    return np.concatenate([machine.to_vector(), stand.ravel()])
