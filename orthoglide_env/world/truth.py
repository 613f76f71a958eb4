"""A machine's drawn world: what its drives, its room and its instruments do beyond the
27 geometric errors, and what that does to the joints and the gauges' readings.

Both machine back-ends go through the same two maps, so the exact model and PyBullet
see one world (and agree within 1 um with every effect on):

* :meth:`World.joints`: the carriages' actual positions for commanded ``rho`` (the
  encoders sit on the motors: the drives are semi-closed loop and the encoders read the
  command) -- lead error, backlash, warm-up and the drives' give under the platform's
  weight;
* after the machine is solved there, :meth:`World.scale` grows the whole steel structure
  about the world origin with the room (a similarity: leg parallelism does not see it,
  the TCP and the drives' scale do), and :meth:`World.distance_offsets` moves each gauge's
  reading by its stand (settling, its arm's growth, its give under the measuring force),
  its indicator (error curve over the plunger's travel, retrace) and the bar it presses
  (bent between its hinges).

Sizes come from :data:`~orthoglide_env.world.table.EFFECTS`.  Lengths in mm, times in s.
A batch of machines is one ``World`` whose arrays have the machine first.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.kinematics import direct_paper, jacobian_paper
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import EFFECTS, SCALES, TRACKER_MPE_PER_M

UM: float = 1e-3  # mm
#: The reference temperature (C, ISO 1) that :meth:`World.temperature` is measured from.
REFERENCE_C: float = 20.0
MINUTE: float = 60.0
HOUR: float = 3600.0
#: The room's random walk is drawn as this many smooth modes over this horizon (s): a
#: fixed number of draws, whatever the budget.
WALK_MODES: int = 8
WALK_HORIZON_S: float = 8 * HOUR
#: A walk mode's coefficient is a standard normal times the walk's size (K/sqrt(h)) times
#: this (sqrt(h)): the modes then add up to a random walk of that size over the horizon.
WALK_MODE_SCALE: float = float(np.sqrt(WALK_HORIZON_S / HOUR))
#: A plunger's revolution (mm): the dial's periodic error repeats with it.
REVOLUTION_MM: float = 1.0
#: Where each effect's per-machine numbers live (its fields below), in draw order.
_DRIVE_FIELDS = ("lead_scale", "lead_a1", "lead_a2", "lead_periodic", "lead_phase",
                 "backlash", "warm_amplitude", "warm_tau")
_DIAL_FIELDS = ("dial_range", "dial_phase", "dial_revolution", "dial_revolution_phase",
                "retrace")
_STAND_FIELDS = ("creep", "creep_tau", "thermal", "mounted_at")
#: The rows a digital indicator's numbers are held to instead (no revolution error).
_DIGITAL: dict[str, tuple[str, float]] = {"dial_range": ("digital_range", UM / 2),
                                          "dial_revolution": ("digital_range", 0.0)}
#: Each drawn number's bound: (effect, table parameter, table unit in the field's unit).
#: The curve terms share one peak-to-peak and the dial's terms are half-amplitudes, so
#: each alone stays within the table's number.
_BOUNDS: dict[str, tuple[str, str, float]] = {
    "lead_scale": ("lead", "scale", UM), "lead_a1": ("lead", "curve", UM),
    "lead_a2": ("lead", "curve", UM / 2), "lead_periodic": ("lead", "periodic", UM / 2),
    "backlash": ("backlash", "lost_motion", UM),
    "warm_amplitude": ("warmup", "amplitude", UM),
    "warm_tau": ("warmup", "time_constant", MINUTE),
    "offset": ("room", "offset", 1.0), "rate": ("room", "drift", 1 / HOUR),
    "dial_range": ("dial", "range", UM / 2), "dial_revolution": ("dial", "revolution", UM / 2),
    "retrace": ("dial", "retrace", UM), "creep": ("stands", "creep", UM),
    "creep_tau": ("stands", "creep_time", MINUTE), "thermal": ("stands", "thermal", UM),
}


def draw_range(stream: np.random.Generator, size: tuple[float, float], shape: tuple[int, ...],
               signed: bool = False, scale: float = 1.0) -> np.ndarray:
    """Values of ``shape`` drawn uniformly in a table row's range ``size`` from ``stream``,
    then (``signed``) each given a random sign, times ``scale``: how every size of the
    conditions' table is drawn."""
    value = stream.uniform(size[0], size[1], shape) * scale
    return value * stream.choice((-1.0, 1.0), shape) if signed else value


def _fixed(conditions: Conditions, effect: str, parameter: str) -> float:
    return float(conditions.size(effect, parameter)[0]) if effect in conditions else 0.0


def _all_numbers(value: Any) -> bool:
    """Whether ``value`` is a number or nested lists of them (numpy alone would read
    ``true`` and ``"1.5"`` as numbers)."""
    if isinstance(value, list | tuple):
        return all(_all_numbers(v) for v in value)
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def deflection(rho: np.ndarray, design: MachineDesign, conditions: Conditions,
               load: np.ndarray | float = 0.0) -> np.ndarray:
    """How far (mm, ``rho``'s shape) the drives give at carriage positions ``rho`` under
    the platform's weight and the gauges' forces ``load`` (N): the drives' compliance
    times the generalised load on each, J^T F, from the paper's model of the nominal
    machine (the true machine's differs by a part in 1e3 of a deflection of a few um)."""
    compliance = _fixed(conditions, "compliance", "actuator") * UM
    lengths = np.full(3, design.L)
    p = direct_paper(rho, 0.0, lengths, design.L)
    jac = jacobian_paper(p, rho, 0.0, lengths, design.L)[..., :3]
    force = np.array([0.0, 0.0, -_fixed(conditions, "compliance", "weight")]) + load
    return compliance * np.einsum("...ji,...j->...i", jac, np.broadcast_to(force, rho.shape))


def bar_bending(conditions: Conditions, at: np.ndarray | float, design: MachineDesign
                ) -> np.ndarray | float:
    """How far (mm per N) a leg's bar gives under a gauge pressing it at ``at`` (a fraction
    of the leg) between its hinges: a simply supported beam of the design's section."""
    modulus = _fixed(conditions, "compliance", "bar_modulus") * 1e3  # N/mm^2
    width, height = design.bar_section
    inertia = width * height**3 / 12  # either way: a square bar in the prototype
    a, b = np.asarray(at) * design.L, (1 - np.asarray(at)) * design.L
    return a**2 * b**2 / (3 * modulus * inertia * design.L)



def walk_modes(time: np.ndarray) -> np.ndarray:
    """The room's random walk's modes (..., :data:`WALK_MODES`) at lab ``time`` (s, any
    shape): the Karhunen-Loeve basis of a random walk over :data:`WALK_HORIZON_S`, each
    weighted by its standard deviation."""
    k = np.arange(WALK_MODES) + 0.5
    return np.sqrt(2) * np.sin(np.pi * k * np.asarray(time)[..., None] / WALK_HORIZON_S) / (
        np.pi * k)

@dataclass(frozen=True)
class World:
    """The drawn non-geometric truth of a batch of machines (``(M, ...)`` arrays; zeros
    where an effect is off).  Per axis: lead error (``lead_scale`` at the stroke's end,
    curve terms ``lead_a1``/``lead_a2``, periodic half-amplitude and phase), ``backlash``,
    warm-up amplitude and time constant.  The room: temperature ``offset`` (K), ``rate``
    (K/s) and ``walk`` modes (K).  Per stand: the indicator's error curve (half-amplitudes
    and phases), ``retrace``; the current mounting's ``creep`` (signed), its time constant,
    the arm's ``thermal`` growth (mm/K, signed) and when it was mounted (lab clock)."""

    conditions: Conditions
    lead_scale: np.ndarray
    lead_a1: np.ndarray
    lead_a2: np.ndarray
    lead_periodic: np.ndarray
    lead_phase: np.ndarray
    backlash: np.ndarray
    warm_amplitude: np.ndarray
    warm_tau: np.ndarray
    offset: np.ndarray
    rate: np.ndarray
    walk: np.ndarray
    dial_range: np.ndarray
    dial_phase: np.ndarray
    dial_revolution: np.ndarray
    dial_revolution_phase: np.ndarray
    retrace: np.ndarray
    creep: np.ndarray
    creep_tau: np.ndarray
    thermal: np.ndarray
    mounted_at: np.ndarray

    # -- drawing ------------------------------------------------------------------------
    @classmethod
    def draw(cls, conditions: Conditions, stream: np.random.Generator, stands: int) -> World:
        """One machine's world (batch of one) from its stream: the drives, the room, every
        stand's indicator, then each stand's first mounting (drawn only for the effects
        that act, so ``ideal`` draws nothing)."""
        c, on = conditions, conditions.__contains__
        zero3, zeros = np.zeros((1, 3)), np.zeros((1, stands))
        drives = dict.fromkeys(_DRIVE_FIELDS, zero3)
        drives["warm_tau"] = np.ones((1, 3))
        if on("lead"):
            curve = draw_range(stream, c.size("lead", "curve"), (1, 3), scale=UM)
            share = stream.uniform(0, 1, (1, 3))
            drives.update(
                lead_scale=draw_range(stream, c.size("lead", "scale"), (1, 3), True, UM),
                lead_a1=curve * share * stream.choice((-1.0, 1.0), (1, 3)),
                lead_a2=curve * (1 - share) / 2 * stream.choice((-1.0, 1.0), (1, 3)),
                lead_periodic=draw_range(stream, c.size("lead", "periodic"), (1, 3),
                                       scale=UM / 2),
                lead_phase=stream.uniform(0, 2 * np.pi, (1, 3)))
        if on("backlash"):
            drives["backlash"] = draw_range(stream, c.size("backlash", "lost_motion"), (1, 3),
                                          scale=UM)
        if on("warmup"):
            drives.update(
                warm_amplitude=draw_range(stream, c.size("warmup", "amplitude"), (1, 3),
                                        scale=UM),
                warm_tau=draw_range(stream, c.size("warmup", "time_constant"), (1, 3),
                                  scale=MINUTE))
        room = {"offset": np.zeros(1), "rate": np.zeros(1), "walk": np.zeros((1, WALK_MODES))}
        if on("room"):
            room.update(
                offset=draw_range(stream, c.size("room", "offset"), (1,), True),
                rate=draw_range(stream, c.size("room", "drift"), (1,), True, 1 / HOUR),
                walk=stream.normal(0, 1, (1, WALK_MODES)) * _fixed(c, "room", "walk")
                * WALK_MODE_SCALE)
        dial = dict.fromkeys(_DIAL_FIELDS, zeros)
        if on("dial"):
            digital = c.indicator == "digital"
            dial.update(
                dial_range=draw_range(stream, c.size("dial", "digital_range" if digital
                                                   else "range"), (1, stands), scale=UM / 2),
                dial_phase=stream.uniform(0, 2 * np.pi, (1, stands)),
                dial_revolution=draw_range(stream, c.size("dial", "revolution"), (1, stands),
                                         scale=0.0 if digital else UM / 2),
                dial_revolution_phase=stream.uniform(0, 2 * np.pi, (1, stands)),
                retrace=draw_range(stream, c.size("dial", "retrace"), (1, stands), scale=UM))
        world = cls(conditions, **drives, **room, **dial,
                    **dict.fromkeys(_STAND_FIELDS, zeros))
        return world.mounted(stream, 0.0, range(stands))

    def mounted(self, stream: np.random.Generator, time: float, stands: Any) -> World:
        """This world (a batch of one) with new mountings of ``stands`` drawn from
        ``stream`` at lab time ``time``."""
        if "stands" not in self.conditions:
            return self
        stands = list(stands)
        c, n = self.conditions, len(stands)
        new = {"creep": draw_range(stream, c.size("stands", "creep"), (n,), True, UM),
               "creep_tau": draw_range(stream, c.size("stands", "creep_time"), (n,),
                                     scale=MINUTE),
               "thermal": draw_range(stream, c.size("stands", "thermal"), (n,), True, UM),
               "mounted_at": np.full(n, time)}
        out = {}
        for name, value in new.items():
            array = np.array(getattr(self, name))
            array[0, stands] = value
            out[name] = array
        return self.replace(**out)

    def replace(self, **changes: np.ndarray) -> World:
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values.update(changes)
        return World(**values)

    # -- batches ------------------------------------------------------------------------
    @classmethod
    def stack(cls, worlds: list[World]) -> World:
        """A batch of the machines of ``worlds`` (same conditions, same stand count)."""
        return cls(worlds[0].conditions, **{
            f.name: np.concatenate([getattr(w, f.name) for w in worlds])
            for f in fields(cls) if f.name != "conditions"})

    def __getitem__(self, rows: Any) -> World:
        """Machines ``rows`` (an index keeps a batch of one)."""
        index = np.atleast_1d(np.arange(len(self.offset))[rows])
        return World(self.conditions, **{f.name: getattr(self, f.name)[index]
                                         for f in fields(self) if f.name != "conditions"})

    def columns(self, stands: np.ndarray) -> World:
        """The world with each machine's per-stand numbers taken at its ``stands`` (M, G)
        (the gauges of an installation)."""
        rows = np.arange(len(self.offset))[:, None]
        return self.replace(**{name: getattr(self, name)[rows, stands]
                               for name in _DIAL_FIELDS + _STAND_FIELDS})

    def with_rows(self, rows: np.ndarray, new: World) -> World:
        """A copy with machines ``rows`` replaced by ``new``'s."""
        out = {}
        for f in fields(self):
            if f.name == "conditions":
                continue
            value = np.array(getattr(self, f.name))
            value[rows] = getattr(new, f.name)
            out[f.name] = value
        return self.replace(**out)

    # -- what the world does ------------------------------------------------------------
    def temperature(self, time: np.ndarray) -> np.ndarray:
        """Room temperature minus 20 C (K) of each machine at its lab ``time`` (M,)."""
        return self.offset + self.rate * time + (self.walk * walk_modes(time)).sum(axis=-1)

    def scale(self, time: np.ndarray) -> np.ndarray:
        """The structure's growth factor about the world origin (M,) at ``time``."""
        alpha = _fixed(self.conditions, "room", "expansion") * 1e-6
        return 1.0 + alpha * self.temperature(time)

    def lead_error(self, rho: np.ndarray, design: MachineDesign) -> np.ndarray:
        """The lead error (mm) of each drive at ``rho`` (M, ..., 3): where the nut is minus
        where the encoder says."""
        x = (np.asarray(rho) - design.rho_min) / (design.rho_max - design.rho_min)
        lead = _fixed(self.conditions, "lead", "screw_lead") or 1.0

        def per(name: str) -> np.ndarray:
            value = getattr(self, name)
            return value.reshape(value.shape[:1] + (1,) * (np.ndim(rho) - 2) + (3,))

        return (per("lead_scale") * x + per("lead_a1") * np.sin(np.pi * x)
                + per("lead_a2") * np.sin(2 * np.pi * x)
                + per("lead_periodic") * np.sin(2 * np.pi * (x * (design.rho_max
                                                                  - design.rho_min)) / lead
                                                + per("lead_phase")))

    def joints(self, rho: np.ndarray, approach: np.ndarray, time: np.ndarray,
               design: MachineDesign, load: np.ndarray | float = 0.0) -> np.ndarray:
        """The carriages' positions (M, 3), in control coordinates, for commanded ``rho``
        approached in the direction ``approach`` (+-1 per axis) at lab ``time`` (M,);
        ``load`` (N, (M, 3)): the gauges' forces on the platform, beside its weight."""
        x = (rho - design.rho_min) / (design.rho_max - design.rho_min)
        warm = self.warm_amplitude * x * (1 - np.exp(-np.asarray(time)[:, None]
                                                     / self.warm_tau))
        out = rho + self.lead_error(rho, design) - self.backlash / 2 * approach + warm
        if self.conditions.drives == "scales" and "room" in self.conditions:
            # The carriage follows its scale, not the screw's steel, as the room changes:
            # the structure's growth (:meth:`scale`) is the steel's.
            glass = SCALES["expansion"].lab[0] - _fixed(self.conditions, "room", "expansion")
            out = out + glass * 1e-6 * self.temperature(time)[:, None] * (rho - design.rho_min)
        if _fixed(self.conditions, "compliance", "actuator"):
            out = out + deflection(out, design, self.conditions, load)
        return out

    @staticmethod
    def measuring_force(t: np.ndarray, travel: np.ndarray) -> np.ndarray:
        """The indicator's force (N) with its tip ``t`` mm out of fully pushed in (every
        indicator has one, whether or not its error curve is in the world)."""
        rest, full = EFFECTS["dial"]["force_rest"].lab[0], EFFECTS["dial"]["force_full"].lab[0]
        return rest + (full - rest) * np.clip(1 - t / travel, 0.0, 1.0)

    def platform_load(self, t: np.ndarray, travel: np.ndarray, direction: np.ndarray,
                      share: np.ndarray) -> np.ndarray:
        """The force (N, (M, 3)) that indicators with tips ``t`` out (M, S; NaN where none
        presses) put on the platform, each pushing along its ``direction`` (M, S, 3) with
        its ``share`` of it (a bar pinned at both ends passes the platform the fraction of
        the force by the lever rule)."""
        force = np.where(np.isfinite(t), self.measuring_force(t, travel), 0.0) * share
        return np.nansum(force[..., None] * np.nan_to_num(direction), axis=-2)

    def distance_offsets(self, t: np.ndarray, going_in: np.ndarray, time: np.ndarray,
                         at: np.ndarray, bar: np.ndarray, travel: np.ndarray,
                         design: MachineDesign) -> np.ndarray:
        """What the stands, indicators and bars add (mm) to each gauge's ray distance ``t``
        (M, S) (a reading is ``sign * (t - zero)``): ``going_in`` (+-1) whether the
        plunger last moved in, ``at`` each gauge's place along its bar, ``bar`` whether it
        touches a leg's bar (else a rigid carriage or platform)."""
        time = np.asarray(time)[:, None]
        depth = travel - t  # how far the plunger is pushed in
        out = (self.dial_range * np.sin(np.pi * depth / travel + self.dial_phase)
               + self.dial_revolution * np.sin(2 * np.pi * depth / REVOLUTION_MM
                                               + self.dial_revolution_phase)
               + self.retrace / 2 * going_in)
        since = np.maximum(time - self.mounted_at, 0.0)
        out = out + self.creep * (1 - np.exp(-since / np.maximum(self.creep_tau, 1e-9)))
        out = out + self.thermal * self.temperature(time[:, 0])[:, None]
        force = self.measuring_force(t, travel)
        out = out + force * _fixed(self.conditions, "stands", "give") * UM
        if "compliance" in self.conditions:
            out = out + np.where(bar, force * bar_bending(self.conditions, at, design), 0.0)
        return out

    def tracker_noise(self, draws: np.ndarray, sight: np.ndarray) -> np.ndarray:
        """The tracker's error (mm) from standard normal ``draws`` (M, 3) for points at
        ``sight`` (M, 3) in its frame: sigma half the MPE along and across the line of
        sight."""
        metres = np.linalg.norm(sight, axis=-1, keepdims=True) / 1e3
        along = (EFFECTS["tracker"]["distance"].lab[0]
                 + TRACKER_MPE_PER_M["distance"] * metres) * UM / 2
        across = (EFFECTS["tracker"]["transverse"].lab[0]
                  + TRACKER_MPE_PER_M["transverse"] * metres) * UM / 2
        u = sight / np.linalg.norm(sight, axis=-1, keepdims=True)
        radial = (draws * u).sum(axis=-1, keepdims=True)
        return across * draws + (along - across) * radial * u

    def scatter(self, t: np.ndarray, travel: np.ndarray) -> np.ndarray:
        """A reading's extra scatter (mm, multiplies its standard normal draw) with the tip
        ``t`` mm out (M, S): a digital indicator's within the last part of its stroke at
        either end; zero elsewhere and for dials."""
        if self.conditions.indicator != "digital" or "dial" not in self.conditions:
            return np.zeros(np.shape(t))
        band = _fixed(self.conditions, "dial", "digital_end")
        sigma = _fixed(self.conditions, "dial", "digital_end_sigma") * UM
        with np.errstate(invalid="ignore"):
            return np.where((t < band) | (t > travel - band), sigma, 0.0)

    # -- files --------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """One machine's world (machine 0) as plain JSON values."""
        return {"conditions": self.conditions.to_dict(),
                **{f.name: np.asarray(getattr(self, f.name))[0].tolist()
                   for f in fields(self) if f.name != "conditions"}}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> World:
        """A batch of one from :meth:`to_dict`'s form; ``ValueError`` naming a missing,
        unknown or misshapen key."""
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(data) - set(names))
        missing = [n for n in names if n not in data]
        if unknown or missing:
            raise ValueError(f"world: unknown key(s) {unknown}, missing {missing}")
        conditions = Conditions.from_dict(data["conditions"])
        values = {}
        for name in names[1:]:
            if not _all_numbers(data[name]):
                raise ValueError(f"world: {name} must hold numbers (not booleans or text), "
                                 f"got {data[name]!r:.60}")
            try:
                value = np.asarray(data[name], dtype=float)[None]
            except (OverflowError, ValueError):  # huge integers, ragged lists
                raise ValueError(f"world: {name} must hold finite numbers of its shape"
                                 ) from None
            if not np.isfinite(value).all():
                raise ValueError(f"world: {name} must hold finite numbers")
            values[name] = value
        shapes = {n: values[n].shape for n in values}
        if shapes["walk"] != (1, WALK_MODES) or any(
                shapes[n] != (1, 3) for n in _DRIVE_FIELDS) or len(
                {shapes[n] for n in _DIAL_FIELDS + _STAND_FIELDS}) != 1:
            raise ValueError(f"world: arrays of the wrong shape {shapes}")
        world = cls(conditions, **values)
        world.check()
        return world

    def check(self) -> None:
        """``ValueError`` naming the first number outside what its conditions draw (an
        effect that is off draws zero): a world read from a file is held to the table."""
        digital = self.conditions.indicator == "digital"
        for name, (effect, parameter, unit) in _BOUNDS.items():
            if digital and name in _DIGITAL:
                parameter, unit = _DIGITAL[name]
            value = np.abs(getattr(self, name))
            on = effect in self.conditions
            low, high = self.conditions.size(effect, parameter) if on else (0.0, 0.0)
            # The time constants' ranges are open below (a tau of zero divides).
            if name in ("warm_tau", "creep_tau"):
                if on and np.any(value < low * unit * (1 - 1e-9)):
                    raise ValueError(f"world: {name} below the {self.conditions.name} "
                                     f"table's {low:g} {EFFECTS[effect][parameter].unit}")
                high = np.inf if on else high
                if not on:
                    continue
            if np.any(value > high * unit * (1 + 1e-9) + 1e-15):
                limit = (f"the {self.conditions.name} table's {high:g} "
                         f"{EFFECTS[effect][parameter].unit}" if on
                         else f"zero: {effect} is off in {self.conditions.label}")
                unit_name = EFFECTS[effect][parameter].unit
                raise ValueError(f"world: {name} = {value.max() / unit:g} {unit_name} "
                                 f"exceeds {limit}")
        if "room" not in self.conditions and np.any(self.walk != 0):
            raise ValueError(f"world: walk must be zero: room is off in "
                             f"{self.conditions.label}")
        if np.any(self.mounted_at < 0):
            raise ValueError("world: mounted_at must be a lab time >= 0 s")
