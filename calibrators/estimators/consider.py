"""Consider terms: the real lab's effects that an exact-model fit does not fit, in its
error bars.

Under ``lab`` or ``workshop`` conditions the readings carry, beyond the 27 geometric
errors and white noise, what the drives, the room and the instruments add
(:mod:`orthoglide_env.world`).  A fit that does not model an effect is biased by it, and
its white-noise covariance lies.  Each effect here is a *consider term*: a known pattern
over the readings with a random coefficient whose second moment is what the conditions'
table draws (:data:`~orthoglide_env.world.table.EFFECTS`).  The fit's error then has the
part ``gain @ C c``, and ``(gain C) E[c c^T] (gain C)^T`` is added to its covariance
(:func:`calibrators.estimators.exact_fit.fit_batch`): consider-covariance analysis, as
orbit determination does for parameters it cannot afford to estimate.  Every coefficient
has zero mean except backlash (its sign is known from the approach); a second moment in
place of a variance keeps the bias in the error bars.

The terms (each is named in :attr:`Consider.names`, so the estimate says what it
considered):

* ``lead``: per axis, the carriage's error along its travel ``x`` in [0, 1] (from
  ``rho_min``): the linear scale ``x``, the curve ``sin(pi x)`` and ``sin(2 pi x)``, and
  the screw's periodic error ``sin``/``cos(2 pi stroke x / lead)``.  A carriage error
  moves a reading as an encoder offset does: its pattern multiplies the reading's
  derivative by that axis's ``drho``.  With a node spacing the curve is instead a
  controller's pitch-error table (:func:`lead_terms`, :func:`table_prior`), and the
  periodic terms are their own family, ``periodic``.
* ``backlash``: per axis, half the lost motion times the direction of the last move of
  that axis before the reading (from the readings' order, with a ballbar set-up's drive
  to its centre before its first reading: the lab starts each axis as if last moved
  forward).
* ``warmup``: per axis, ``x (1 - exp(-t / tau))``, the time constant's spread by
  Simpson's rule over its range; the amplitude's mean acts on every axis at once.
* ``stands``: per gauge mounting, its creep ``1 - exp(-(t - t0) / tau)`` from its first
  reading ``t0`` (a stand is mounted before it is read: this overstates what is left;
  the time constant's spread by Simpson's rule over its range), its arm's growth with
  the room, ``t`` times the room's drift (its random walk folded in at one hour), or,
  when the readings carry a thermometer's (:func:`thermometer_sigma`), the arm's
  coefficient times ``T(t) - T(t0)``, and
  its give, with the bar's bending under ``compliance``, under the measuring force that
  grows as the plunger goes in (a known gain on the reading: one term over every
  mounting, as every known term is one, so that its parts add up as they do).
* ``dial``: per gauge mounting, the indicator's error over the plunger's position, which
  is the reading up to the mounting's zero: ``sin``/``cos(pi y / travel)`` and
  ``sin``/``cos(2 pi y / revolution)`` (the phase is random, so the zero's offset is in
  it); each mounting is taken as its own indicator.  And its retrace
  (:func:`retrace_terms`): half of it, one way with the plunger going in and the other
  coming out, the way read from the mounting's readings in their order; a digital
  indicator's way at a posture's repetitions is unknown where a drift acts, one
  considered sign per run of them (``dial.turn``).  A digital
  indicator's readings within the last part of its stroke, where they scatter more, are
  not fitted (:func:`indicator_end`).

* ``stands.dead_path``: an interferometer's dead path (:func:`dead_path_terms`): the
  room grows the 100 mm from the drive's back end to where its count was zeroed, about
  0.3 um per hour under ``lab``, and a set-up stays on while the gauges' experiment
  after it reads it for hours.  The room's drift and walk are shared by every set-up.

A term's *family* (:func:`term_family`, :data:`TERM_FAMILIES`) is what an estimator
fits or considers: ``full`` fits :data:`FULL_TERMS` and considers the rest, but for
what an instrument's readings show plainly: the screw's periodic error with an
interferometer's or a ballbar's, and with a digital indicator's (2 um) the periodic error
and the indicator's own curve and retrace.

Left out, each at most about 1 um over a one-hour experiment under ``lab``: the
structure's growth with the room (a similarity the legs' parallelism does not see), the
drives' compliance under the platform's weight and the gauges'
force, and the gauge block's deviation from its nominal length (a reference gauge's
zeroing reading; its grade allows 0.2 um under ``lab``, 0.8 um in the workshop:
:data:`~orthoglide_env.world.table.REFERENCE_DEVIATION`); and with linear scales
(``drives="scales"``), the scale's expansion against the steel's (3.5 ppm/K over the
stroke: 0.2 um per hour of the lab's drift; its part at the room's offset is the
grade's linear term).  A tracker's noise under
conditions with its MPE is not a term but its readings' sigma (:func:`tracker_sigma`);
an interferometer's scatter likewise (:func:`~orthoglide_env.instruments.interferometer.
sigma`), and its scale error (laser, air, material sensor) is a term per set-up,
``interferometer.scale``, on the displacement from its zero.  A step gauge's errors are
terms too: each face's calibration error, one term per face over every set-up (the same
gauge is laid along each axis), and its scale error, one term on every face's distance;
per set-up, its cosine error and what the room leaves once the gauge and the machine are
taken to 20 C, ``step-gauge.scale``, on the face's distance.  A ballbar's transducer
scale error is one term, ``ballbar.scale``, on every set-up's readings (the lab has one
bar); a pivot's offset is a fitted unknown, and every drive term moves the pivot as
well as the TCP the bar reads: a ballbar reading's term has its pattern at the reading
and, through the pivot, at its set-up's centre command when the set-up ended
(:attr:`Consider.pivot`; the lab reads the bar first a move after that, and a sheet's
first reading is taken as so too), so the offset's prior holds only the centring and the
room's growth (:func:`pivot_sigmas` without ``drives``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthoglide_env.instruments.ballbar import BallbarSpec, centring_sigma
from orthoglide_env.instruments.ballbar import scale_rms as ballbar_scale_rms
from orthoglide_env.instruments.interferometer import InterferometerAxis, scale_second_moment
from orthoglide_env.instruments.slots import GaugeSpec, Part
from orthoglide_env.instruments.step_gauge import (
    StepGaugeSpec,
    cosine_rms,
    expansion_rms,
    face_lengths,
    face_sigmas,
    length_sigma,
)
from orthoglide_env.lab.operations import TIME
from orthoglide_env.model.compensation import interpolation_weights, node_count
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import AXIS_NAMES, MachineParams
from orthoglide_env.model.kinematics import direct, sensitivity_along, tcp_sensitivity_factors
from orthoglide_env.reading_model import ReadingLayout
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.table import TRACKER_MPE_PER_M
from orthoglide_env.world.truth import (
    HOUR,
    MINUTE,
    REVOLUTION_MM,
    UM,
    WALK_MODE_SCALE,
    WALK_MODES,
    bar_bending,
    deflection,
    walk_modes,
)

#: A fitted term's parameter name is its name after this.
WORLD_PREFIX: str = "world."
#: The effects whose terms need each reading's time.
TIMED_EFFECTS: tuple[str, ...] = ("warmup", "stands")
#: What moves a gauge's plunger between its readings at one posture: the room's growth,
#: the drives' warm-up, a stand's creep (:func:`retrace_terms`).
TURNING: tuple[str, ...] = ("room", "warmup", "stands")
#: A digital indicator's retrace turned at a posture's repetitions: one term per run of
#: them, considered even where the ``dial`` family is fitted (as many coefficients as the
#: plan's visits, which the readings cannot tell apart from the noise).
TURN_TERM: str = "dial.turn"
#: The pitch-error table's terms are named this and their index.
TABLE_TERM: str = "lead.table"
#: The families of terms an estimator fits or considers: the lead error's curve (its
#: table), the screw's periodic error, backlash, warm-up, the stands' drift and give, the
#: indicators' error curves.
TERM_FAMILIES: tuple[str, ...] = ("lead", "periodic", "backlash", "warmup", "stands", "dial")
#: What the ``full`` estimator fits; the rest it considers: a table coarser than the
#: screw's lead cannot compensate the periodic error, and an indicator's error curve is
#: told apart from the geometry only against a reference.
FULL_TERMS: tuple[str, ...] = ("lead", "backlash", "warmup", "stands")
#: The ``full`` estimator's pitch-error table's default node spacing (mm).  Assumption:
#: 10 mm, a usual spacing of a controller's pitch-error table on a short axis.
DEFAULT_NODE_SPACING: float = 10.0

@dataclass(frozen=True)
class Consider:
    """The consider terms of one design's readings, for machines ``(M, ...)``: ``drive``
    (M, N, 3, K), the carriages' errors of each of K terms (mm per unit coefficient: the
    pattern times its coefficient's root second moment), which move a reading as the
    encoder offsets ``drho`` do; ``reading`` (M, N, J), what J terms add to the readings
    themselves (mm); ``names`` the K drive terms, then the J reading terms.  The terms'
    coefficients are uncorrelated with unit second moment."""

    names: tuple[str, ...]
    drive: np.ndarray
    reading: np.ndarray
    #: (M, N, 3, K) or None (no ballbar readings): for a ballbar reading, the K drive
    #: terms' carriage errors where and when its set-up's pivot was centred (the centre
    #: command, at the set-up's time), which moved the pivot
    #: (:func:`~orthoglide_env.reading_model.pivot_derivatives`); zero for other readings.
    pivot: np.ndarray | None = None

    @property
    def empty(self) -> bool:
        return not self.drive.shape[-1] and not self.reading.shape[-1]

    @property
    def effects(self) -> list[str]:
        """The terms without their axes and mountings (``dial.range_sin``, once)."""
        return list(dict.fromkeys(name.split("[")[0] for name in self.names))

    def rows(self, rows: np.ndarray) -> Consider:
        """The terms of machines ``rows``."""
        return Consider(self.names, self.drive[rows], self.reading[rows],
                        None if self.pivot is None else self.pivot[rows])

    def split(self, families: tuple[str, ...]) -> tuple[Consider, Consider]:
        """The terms of ``families`` (:func:`term_family`), and the others (with every
        :data:`TURN_TERM`, which is never fitted)."""
        k = self.drive.shape[-1]
        chosen = np.array([term_family(n) in families and not n.startswith(TURN_TERM)
                           for n in self.names], dtype=bool)

        def part(keep: np.ndarray) -> Consider:
            return Consider(tuple(n for n, c in zip(self.names, keep, strict=True) if c),
                            self.drive[..., keep[:k]], self.reading[..., keep[k:]],
                            None if self.pivot is None else self.pivot[..., keep[:k]])

        return part(chosen), part(~chosen)


def term_family(name: str) -> str:
    """The family of a term (:data:`TERM_FAMILIES`), by which terms are chosen."""
    return "periodic" if name.startswith("lead.periodic") else name.split(".")[0]


def check_families(families: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """``families`` in :data:`TERM_FAMILIES` order; ``ValueError`` naming an unknown
    one."""
    unknown = [f for f in families if f not in TERM_FAMILIES]
    if unknown:
        raise ValueError(f"unknown estimator term(s) {unknown}; terms are "
                         f"{', '.join(TERM_FAMILIES)}")
    return tuple(f for f in TERM_FAMILIES if f in families)


def tracker_sigma(conditions: Conditions, distance_mm: float) -> float:
    """A tracker coordinate's sigma (mm) for points up to ``distance_mm`` from it, under
    conditions with the tracker's MPE: half the transverse MPE there, which bounds every
    coordinate's (the lab draws half the MPE along and across the line of sight, and the
    one along it is the smaller)."""
    mpe = _fixed("tracker", "transverse", conditions) + TRACKER_MPE_PER_M["transverse"] * (
        distance_mm / 1e3)
    return mpe / 2 * UM


def second_moment(effect: str, parameter: str, conditions: Conditions) -> float:
    """E[v^2] of a value drawn uniformly in the table's range under ``conditions``."""
    low, high = conditions.size(effect, parameter)
    return (low * low + low * high + high * high) / 3.0


def _fixed(effect: str, parameter: str, conditions: Conditions) -> float:
    return conditions.size(effect, parameter)[0]


def _mean(effect: str, parameter: str, conditions: Conditions) -> float:
    low, high = conditions.size(effect, parameter)
    return (low + high) / 2.0


#: Simpson's rule over a time constant drawn uniformly in its range: E over tau of
#: f_tau f_tau^T is sum_j w_j f_j f_j^T, a sum of terms with positive weights.
_NODES: tuple[float, ...] = (0.0, 0.5, 1.0)
_WEIGHTS: tuple[float, ...] = (1 / 6, 2 / 3, 1 / 6)


def _taus(effect: str, parameter: str, conditions: Conditions) -> list[float]:
    low, high = conditions.size(effect, parameter)
    return [(low + (high - low) * node) * MINUTE for node in _NODES]


def _approach(design: ReadingLayout) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) the direction (+-1) of each axis's last move before each reading of
    ``design``, from the readings' order; +1 before an axis first moves.  A ballbar
    set-up drove to its centre command unread, so its first reading was approached from
    there.  And (B, 3) the same at each of the B ballbar set-ups' centres, where its pivot
    was centred."""
    bars = design.space.ballbars
    firsts = [int(np.flatnonzero(design.mounting == k)[0]) for k in bars]
    # The points driven to in order: each set-up's centre just before its first reading.
    centre = np.array([design.specs[k].centre for k in bars], dtype=float).reshape(-1, 3)
    state = _last_directions(np.insert(design.rho, firsts, centre, axis=0), design.rho[0])
    # Where each reading and each centre landed among the points.
    ordered = np.sort(firsts)
    readings = np.arange(len(design.rho))
    at = readings + np.searchsorted(ordered, readings, side="right")
    centres = np.array(firsts, dtype=int) + np.searchsorted(ordered, firsts)
    return state[at], state[centres].reshape(len(bars), 3)


def _last_directions(points: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(N, 3) the sign (+-1.0) of each axis's last non-zero step up to each of
    ``points`` (N, 3) driven to in order from ``start`` (3,), +1 before the first."""
    step = np.diff(points, axis=0, prepend=start[None])
    moved = (step > 0) | (step < 0)
    last = np.maximum.accumulate(np.where(moved, np.arange(len(points))[:, None], -1), axis=0)
    sign = np.where(step > 0, 1.0, -1.0)
    return np.where(last >= 0, np.take_along_axis(sign, np.maximum(last, 0), axis=0), 1.0)


def _per_axis(name: str, pattern: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Three terms, one per axis, of a pattern (..., N, 3): the axes' coefficients are
    drawn independently."""
    out = []
    for a, axis in enumerate(AXIS_NAMES):
        only = np.zeros(pattern.shape)
        only[..., a] = pattern[..., a]
        out.append((f"{name}[{axis}]", only))
    return out


def lead_terms(rho: np.ndarray, machine: MachineDesign, conditions: Conditions,
               spacing: float | None = None) -> list[tuple[str, np.ndarray]]:
    """The lead error's terms at the carriages' positions ``rho`` (..., 3): (name,
    pattern (..., 3), mm per unit coefficient), none where the lead effect is off.

    ``spacing`` None: the curve as the conditions' table describes it (:func:`curve_terms`)
    and the screw's periodic sin/cos.  A spacing (mm): the curve as a controller's
    pitch-error table with nodes that far apart (:func:`table_prior`), in the coefficients
    that whiten its prior (``lead.table<i>``), and the periodic terms, which a table
    coarser than the screw's lead cannot hold."""
    if "lead" not in conditions:
        return []
    stroke = machine.rho_max - machine.rho_min
    x = (np.asarray(rho, dtype=float) - machine.rho_min) / stroke
    periodic = np.sqrt(second_moment("lead", "periodic", conditions) / 2) * UM / 2
    angle = 2 * np.pi * x * stroke / conditions.size("lead", "screw_lead")[0]
    waves = [("lead.periodic_sin", periodic * np.sin(angle)),
             ("lead.periodic_cos", periodic * np.cos(angle))]
    if spacing is None:
        curves = curve_terms(x, conditions)
    else:
        count, root = table_prior(machine, conditions, spacing)
        weights = interpolation_weights(rho, machine.rho_min, spacing, count) @ root
        curves = [(f"{TABLE_TERM}{i}", weights[..., i]) for i in range(root.shape[1])]
    out: list[tuple[str, np.ndarray]] = []
    for name, pattern in (*curves, *waves):
        out += _per_axis(name, pattern)
    return out


def curve_terms(x: np.ndarray, conditions: Conditions) -> list[tuple[str, np.ndarray]]:
    """The lead error's smooth part at ``x`` (...), a fraction of the stroke from
    ``rho_min``, as the lab draws it (:meth:`~orthoglide_env.world.truth.World.draw`):
    (name, pattern (...), mm per unit coefficient) of three uncorrelated coefficients, so
    that the patterns' outer products add up to the drawn curve's second moments.  The
    scale ``x`` at the table's ``scale``; the table's ``curve`` C split between two sines,
    a share s ~ U(0, 1) to ``sin(pi x)`` and (1 - s) / 2 to ``sin(2 pi x)``, with random
    signs: E[C^2 s^2] = E[C^2] / 3 and E[C^2 (1 - s)^2 / 4] = E[C^2] / 12."""
    scale = np.sqrt(second_moment("lead", "scale", conditions)) * UM
    curve = np.sqrt(second_moment("lead", "curve", conditions)) * UM
    return [("lead.scale", scale * x),
            ("lead.curve1", curve / np.sqrt(3) * np.sin(np.pi * x)),
            ("lead.curve2", curve / np.sqrt(12) * np.sin(2 * np.pi * x))]


def table_prior(machine: MachineDesign, conditions: Conditions, spacing: float
                ) -> tuple[int, np.ndarray]:
    """The pitch-error table's node count after the reference node and ``R`` (count, K),
    mm: node values ``R z`` with ``z ~ N(0, I)`` have the second moments of the lead
    error's smooth part that the lab draws at the nodes (:func:`curve_terms`), 0 at the
    reference (an error there is an encoder offset).  One source for the fit and the
    lab: the table's prior is the truth's own distribution, so the fit's error bars hold
    the curve as large and as shaped as it acts, no narrower and no wider.  Its K = 3
    columns are the curve's terms at the nodes; a table finer than the curve holds no
    more."""
    stroke = machine.rho_max - machine.rho_min
    count = node_count(stroke, spacing)
    x = spacing * np.arange(1, count + 1) / stroke
    return count, np.stack([pattern for _, pattern in curve_terms(x, conditions)], axis=-1)


def _drive_terms(design: ReadingLayout, t: np.ndarray | None, conditions: Conditions,
                 spacing: float | None) -> tuple[list[tuple[str, np.ndarray]],
                                                 np.ndarray | None]:
    """The carriages' terms: (name, pattern (M or 1, N, 3)) at the readings, and, with
    ballbar readings, every term's pattern (M or 1, N, 3, K) where and when each one's
    set-up centred its pivot (:attr:`Consider.pivot`), else None."""
    approach, centre_approach = _approach(design)
    out = _carriage_terms(design.rho, approach, t, design, conditions, spacing)
    bars = design.space.ballbars
    if not bars or not out:
        return out, None
    first = np.array([np.flatnonzero(design.mounting == k)[0] for k in bars])
    centres = np.array([design.specs[k].centre for k in bars], dtype=float)  # (B, 3)
    # The pivot was centred when the set-up's work ended: its first reading came a move
    # (drive and settle) later.
    when = None if t is None else t[:, first] - TIME.move(centres, design.rho[first])
    at_centres = _carriage_terms(centres, centre_approach, when, design, conditions, spacing)
    # Each ballbar reading gets its set-up's centre's patterns; other readings none.
    setup = np.full(len(design), len(bars))
    for b, k in enumerate(bars):
        setup[design.mounting == k] = b
    machines = max(len(pattern) for _, pattern in at_centres)
    patterns = np.stack([np.broadcast_to(pattern, (machines, *centres.shape))
                         for _, pattern in at_centres], axis=-1)  # (M|1, B, 3, K)
    padded = np.concatenate([patterns, np.zeros((*patterns.shape[:1], 1,
                                                 *patterns.shape[2:]))], axis=1)
    return out, padded[:, setup]


def _carriage_terms(rho: np.ndarray, approach: np.ndarray, t: np.ndarray | None,
                    design: ReadingLayout, conditions: Conditions, spacing: float | None
                    ) -> list[tuple[str, np.ndarray]]:
    """The carriages' terms at commands ``rho`` (P, 3) approached from ``approach`` (P, 3)
    at lab times ``t`` (M, P) or None: (name, pattern (M or 1, P, 3))."""
    on = conditions.__contains__
    machine = design.machine_design
    out = [(name, pattern[None]) for name, pattern in lead_terms(
        rho, machine, conditions, spacing)]
    x = (rho - machine.rho_min) / (machine.rho_max - machine.rho_min)  # (P, 3)
    if on("backlash"):
        # Half the lost motion, b / 2, against the approach: b's mean acts on every axis
        # at once (the axes' b are all positive), its spread on each alone.
        lag = -approach[None] / 2 * UM
        mean, spread = backlash_sizes(conditions)
        out.append(("backlash.mean", mean * lag))
        out += _per_axis("backlash.spread", spread * lag)
    if on("compliance") and design.space.ballbars:
        # The drives give under the platform's weight by about 1 um, changing with the
        # posture: below what a dial gauge at 20 um tells, but a ballbar reads the TCP at
        # 0.35 um.  Its size is the table's (an assumption): considered at that size.
        out.append(("compliance.weight", deflection(rho, machine, conditions)[None]))
    if on("warmup"):
        out += warmup_terms(x, t, conditions)
    return out


def warmup_terms(x: np.ndarray, t: np.ndarray, conditions: Conditions
                 ) -> list[tuple[str, np.ndarray]]:
    """The warm-up's terms as ``full`` fits them, for carriages at ``x`` (..., 3), a
    fraction of the stroke, at lab times ``t`` (...): (name, pattern (..., 3) in mm per
    unit coefficient)."""
    # A x (1 - exp(-t / tau)): A's mean times tau's mean curve acts on every axis at
    # once; what tau's spread and A's spread add, on each alone.
    curves, mean_curve = warmup_curves(x, t, conditions)
    mean, spread = warmup_sizes(conditions)
    out = [("warmup.mean", mean * mean_curve)]
    for j, (w, c) in enumerate(zip(_WEIGHTS, curves, strict=True)):
        out += _per_axis(f"warmup.tau{j}", np.sqrt(w) * mean * (c - mean_curve))
        out += _per_axis(f"warmup.spread{j}", np.sqrt(w) * spread * c)
    return out


def warmup_curves(x: np.ndarray, t: np.ndarray, conditions: Conditions
                  ) -> tuple[list[np.ndarray], np.ndarray]:
    """The warm-up's curves ``x (1 - exp(-t / tau))`` at the time constant's Simpson nodes
    for carriages at ``x`` (..., 3), a fraction of the stroke, at lab times ``t`` (...),
    and their mean over the time constant's range."""
    curves = [x * (1 - np.exp(-t[..., None] / tau))
              for tau in _taus("warmup", "time_constant", conditions)]
    return curves, sum(w * c for w, c in zip(_WEIGHTS, curves, strict=True))


def warmup_sizes(conditions: Conditions) -> tuple[float, float]:
    """The warm-up amplitude's mean and spread (mm) under ``conditions``: the sizes of the
    ``warmup.mean`` term and of each axis's own terms."""
    mean = _mean("warmup", "amplitude", conditions) * UM
    spread = np.sqrt(second_moment("warmup", "amplitude", conditions)) * UM
    return mean, float(np.sqrt(spread**2 - mean**2))


def backlash_sizes(conditions: Conditions) -> tuple[float, float]:
    """The lost motion's mean and spread (um) under ``conditions``: the sizes of the
    ``backlash.mean`` term and of each axis's ``backlash.spread`` term, so that an axis's
    lost motion is ``mean c_mean + spread c_axis`` in their coefficients."""
    mean = _mean("backlash", "lost_motion", conditions)
    return mean, float(np.sqrt(second_moment("backlash", "lost_motion", conditions) - mean**2))


def pivot_sigmas(design: ReadingLayout, conditions: Conditions, drives: bool = True
                 ) -> np.ndarray:
    """The prior sigma (mm, ``(3 B,)``) of each of ``design``'s B ballbar set-ups' pivot
    offsets from where the nominal-model machine puts the TCP at its centre command.  The
    pivot is centred where the TCP truly was, so beside the centring
    (:func:`~orthoglide_env.instruments.ballbar.centring_sigma`) the offset holds the
    structure's growth at the room's offset and, with ``drives``, what the drives'
    carriages were off at the centre then, through the TCP's sensitivity: the lead error,
    half the lost motion and the warm-up once warm (its amplitude's mean on every axis at
    once, its spread on each alone), at the table's second moments under ``conditions``.
    A fit's centre takes them, as ISO 230-4's analysis removes the centring.  A fit whose
    terms move the pivot with the drives (:attr:`Consider.pivot`) leaves ``drives`` out:
    an offset's zero-mean prior per set-up would pull every set-up's weakly seen
    coordinate (along its plane's normal) the same way, where the drives' errors at a
    centre are one machine's, shared by its set-ups and positive for the warm-up."""
    bars = design.space.ballbars
    if not bars:
        return np.zeros(0)
    machine = design.machine_design
    centres = np.array([design.specs[k].centre for k in bars], dtype=float)  # (B, 3)
    nominal = MachineParams(design=machine)
    tcp = direct(nominal, centres)
    spread2 = np.zeros(centres.shape)
    if drives:
        inverse, row = tcp_sensitivity_factors(nominal, centres, tcp)
        # Row i of the TCP's derivative over the carriages (the encoder offsets' columns).
        sensitivity = np.stack([sensitivity_along(inverse, row, np.broadcast_to(e, tcp.shape))
                                [..., :3] for e in np.eye(3)], axis=-2)  # (B, 3, 3)
        spread2 = np.einsum("bij,bjk,bik->bi", sensitivity,
                            _carriage_covariance(centres, machine, conditions), sensitivity)
    if "room" in conditions:
        alpha = _fixed("room", "expansion", conditions) * 1e-6
        spread2 = spread2 + second_moment("room", "offset", conditions) * (alpha * tcp) ** 2
    return np.sqrt(centring_sigma() ** 2 + spread2).ravel()


def _carriage_covariance(rho: np.ndarray, machine: MachineDesign, conditions: Conditions
                         ) -> np.ndarray:
    """(P, 3, 3) the second moments (mm^2) of the drives' carriage errors at commands
    ``rho`` (P, 3) under ``conditions``: the lead error, half the lost motion and the
    warm-up once warm (its amplitude's mean on every axis at once, its spread on each
    alone)."""
    variance = sum((pattern**2 for _, pattern in lead_terms(rho, machine, conditions)),
                   np.zeros(rho.shape))
    if "backlash" in conditions:
        variance = variance + second_moment("backlash", "lost_motion", conditions) / 4 * UM**2
    carriage = variance[..., None] * np.eye(3)
    if "warmup" in conditions:
        x = (rho - machine.rho_min) / (machine.rho_max - machine.rho_min)
        mean, spread = warmup_sizes(conditions)
        carriage = carriage + mean**2 * x[..., :, None] * x[..., None, :] + (
            spread**2 * x**2)[..., None] * np.eye(3)
    return carriage


def thermometer_sigma(conditions: Conditions) -> float:
    """What a thermometer's error adds (mm, a standard deviation) to a gauge reading when
    the stands' growth is sized by its readings: the arm's coefficient times its rounding,
    uniform within half its resolution.  Its offset is the same in every reading, so each
    mounting's zero takes it.  Zero where the stands or the room do not act, or the
    thermometer reads the truth."""
    if not all(e in conditions for e in ("stands", "room", "thermometer")):
        return 0.0
    step = _fixed("thermometer", "resolution", conditions)
    return float(np.sqrt(second_moment("stands", "thermal", conditions)) * UM * step
                 / np.sqrt(12.0))


def plunger_directions(values: np.ndarray, sign: float, rho: np.ndarray) -> np.ndarray:
    """(M, R) whether one mounting's plunger last moved in (+1) or out (-1) at each of its
    readings ``values`` (M, R, in the order taken) at commanded postures ``rho`` (R, 3),
    from the readings themselves: the tip's distance out is the reading along the gauge's
    ``sign``, so it went in where that fell since the mounting's reading before.  A reading
    at the same posture as the one before keeps the direction (the plunger did not move);
    a mounting's first reading went in (its stand was slid in to mid-travel)."""
    out = np.ones(np.shape(values))
    if not out.shape[-1]:
        return out
    tip = sign * np.asarray(values, dtype=float)
    moved = ~repeated_readings(rho)[1:]
    step = np.where(moved, np.sign(tip[:, :-1] - tip[:, 1:]), 0.0)
    for j in range(1, out.shape[-1]):
        out[:, j] = np.where(step[:, j - 1] != 0, step[:, j - 1], out[:, j - 1])
    return out


def retrace_terms(values: np.ndarray, sign: float, rho: np.ndarray, conditions: Conditions
                  ) -> list[tuple[str, np.ndarray]]:
    """An indicator's retrace on one mounting's readings ``values`` (M, R) at postures
    ``rho`` (R, 3): the reading moves by half of it, one way with the plunger going in
    and the other coming out (:func:`plunger_directions`); (name, pattern in mm per unit
    coefficient), its coefficient's second moment the table's; none without the ``dial``
    effect.  A 2 um digital reading shows it (up to 1 um each way): left out, it made a
    digital indicator's error bars 1.5x too small with the indicator's errors alone.

    A digital indicator's repetitions at one posture (:func:`repeated_readings`) where a
    drift acts (:data:`TURNING`) take no way from the readings: a retrace turns on the
    plunger's last move however small, and between repetitions the room's growth, the
    drives' warm-up and a stand's creep move it by nanometres either way, which no
    reading shows.  Its way there is an unknown sign, one per run of repetitions (the
    drift that turns them is slow): the retrace's pattern is zero on them and each run
    has a term :data:`TURN_TERM` at half the retrace, a zero-mean sign of second moment
    one (the second moment of ``(r / 2) d`` with ``d`` either way at even odds).  A dial
    indicator keeps the way of its run's first reading: its 20 um scatter hides the
    retrace."""
    if "dial" not in conditions:
        return []
    size = np.sqrt(second_moment("dial", "retrace", conditions)) / 2 * UM
    directions = plunger_directions(values, sign, rho)
    if conditions.indicator != "digital" or not any(e in conditions for e in TURNING):
        return [("dial.retrace", size * directions)]
    repeated = repeated_readings(rho)
    run = np.cumsum(~repeated)
    out = [("dial.retrace", size * np.where(repeated, 0.0, directions))]
    return out + [(TURN_TERM, np.broadcast_to(size * (repeated & (run == j)), values.shape))
                  for j in np.unique(run[repeated])]


def repeated_readings(rho: np.ndarray) -> np.ndarray:
    """(R,) which of one mounting's readings at commanded postures ``rho`` (R, 3), in the
    order taken, repeat the posture of the reading before (the plunger was not moved)."""
    out = np.zeros(len(rho), dtype=bool)
    out[1:] = np.all(rho[1:] == rho[:-1], axis=-1)
    return out


def indicator_end(design: ReadingLayout, values: np.ndarray, conditions: Conditions
                  ) -> np.ndarray:
    """(M, N) which of ``design``'s readings ``values`` (M, N) a digital indicator took
    within the last part of its stroke at either end (the table's ``digital_end``), where
    its datasheets give no repeatability: a mounting's zero is set at mid-travel, so the
    plunger's position is half the travel plus the reading along its sign.  None for a
    dial indicator or without the ``dial`` effect."""
    out = np.zeros(np.shape(values), dtype=bool)
    if conditions.indicator != "digital" or "dial" not in conditions:
        return out
    gauge = np.zeros(len(design.specs), dtype=bool)
    gauge[design.space.gauges] = True
    travel = design.machine_design.gauge_travel
    band = _fixed("dial", "digital_end", conditions)
    tip = travel / 2 + design.signs[design.mounting] * values
    with np.errstate(invalid="ignore"):
        return gauge[design.mounting] & ((tip < band) | (tip > travel - band))


def _reading_terms(design: ReadingLayout, values: np.ndarray, t: np.ndarray | None,
                   conditions: Conditions, temperatures: np.ndarray | None = None
                   ) -> list[tuple[str, np.ndarray]]:
    """The gauges' own terms: (name, (M, N) zero off the mounting)."""
    on = conditions.__contains__
    n = len(design)
    out: list[tuple[str, np.ndarray]] = []
    # The give is known, sign and all: one term over every mounting (terms of their own
    # would take its parts as uncorrelated, where they add up or cancel).
    give_all = np.zeros((len(values), n))
    gives = False
    laser = np.sqrt(scale_second_moment(conditions))
    # The lab has one bar: its transducer's scale error is one term over every set-up.
    bar_scale = np.zeros((len(values), n))
    for k, name in enumerate(design.mountings):
        rows = np.flatnonzero(design.mounting == k)
        spec = design.specs[k]
        if isinstance(spec, InterferometerAxis) and laser:
            # Its scale error, on the displacement from where its count was zeroed.
            moved = design.rho[rows, spec.axis] - design.rho[rows[0], spec.axis]
            out.append((f"interferometer.scale[{name}]",
                        _on_rows(np.broadcast_to(laser * moved, (len(values), len(rows))),
                                 rows, n)))
        if isinstance(spec, BallbarSpec) and conditions.active:
            bar_scale[:, rows] = ballbar_scale_rms() * values[:, rows]
        if not isinstance(spec, GaugeSpec):
            continue
        # The measuring force grows as the plunger goes in, and the stand (and a bar,
        # between its hinges) yields under it: a known gain on the readings.
        give = _fixed("stands", "give", conditions) * UM if on("stands") else 0.0
        if on("compliance") and spec.part == Part.BAR:
            give += float(bar_bending(conditions, spec.at, design.machine_design))
        gives = gives or bool(give)
        force = (_fixed("dial", "force_full", conditions)
                 - _fixed("dial", "force_rest", conditions))
        give_all[:, rows] = -give * force / design.machine_design.gauge_travel * values[:, rows]
        if on("stands"):
            since = t[:, rows] - t[:, rows[:1]]
            heat = (None if temperatures is None
                    else temperatures[:, rows] - temperatures[:, rows[:1]])
            out += [(f"{label}[{name}]", _on_rows(pattern, rows, n))
                    for label, pattern in drift_terms(since, t[:, rows], conditions, heat)]
        out += [(f"{label}[{name}]", _on_rows(pattern, rows, n)) for label, pattern in
                (*dial_terms(values[:, rows], design.machine_design.gauge_travel, conditions),
                 *retrace_terms(values[:, rows], design.signs[k], design.rho[rows],
                                conditions))]
    if gives:
        out.append(("stands.give", give_all))
    if design.space.ballbars and conditions.active:
        out.append(("ballbar.scale", bar_scale))
    if design.probed.any() and conditions.active:
        out += _step_gauge_terms(design, len(values), conditions)
    return out + dead_path_terms(design, t, conditions)


def dead_path_terms(design: ReadingLayout, t: np.ndarray | None, conditions: Conditions
                    ) -> list[tuple[str, np.ndarray]]:
    """An interferometer's dead path under ``room``: the machine between the drive's back
    end (``rho_min``, where the instrument counts from) and the carriage where the count
    was zeroed grows with the room, and the material compensation, which scales what the
    count moved, does not take it.  A set-up zeroed ``d`` mm from that end reads
    ``d alpha (T(t) - T(t0))`` beyond the carriage's move; its zero takes ``T(t0)``.  The
    room is one for every set-up: its drift and its walk's modes
    (:func:`~orthoglide_env.world.truth.walk_modes`) are terms shared by them, each
    sized by its prior (name, (M, N) pattern per unit coefficient).  In the ``stands``
    family: the set-up's own growth, as a stand's arm's is."""
    lasers = [(k, spec) for k, spec in enumerate(design.specs)
              if isinstance(spec, InterferometerAxis)]
    if not lasers or "room" not in conditions:
        return []
    if t is None:
        raise ValueError(f"under the {conditions.name} conditions every reading needs its "
                         "time (time_s) to size an interferometer's dead path")
    machine = design.machine_design
    alpha = _fixed("room", "expansion", conditions) * 1e-6
    dead = np.zeros(len(design))
    for k, spec in lasers:
        rows = np.flatnonzero(design.mounting == k)
        dead[rows] = alpha * (design.rho[rows[0], spec.axis] - machine.rho_min)
    rate = np.sqrt(second_moment("room", "drift", conditions)) / HOUR
    walk = np.sqrt(second_moment("room", "walk", conditions)) * WALK_MODE_SCALE
    out = [("stands.dead_path.drift", dead * rate * t)]
    modes = walk_modes(t)
    out += [(f"stands.dead_path.walk{j}", dead * walk * modes[..., j])
            for j in range(WALK_MODES)]
    return out


def _step_gauge_terms(design: ReadingLayout, machines: int, conditions: Conditions
                      ) -> list[tuple[str, np.ndarray]]:
    """A step gauge's own terms on ``design``'s readings: (name, (M, N))."""
    distance = design.face_distances
    face = np.rint(distance / face_lengths()[1]).astype(int)
    probed = design.probed

    def term(pattern: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.where(probed, pattern, 0.0), (machines, len(design)))

    out = [(f"step-gauge.face{k}", term(np.where(face == k, sigma, 0.0)))
           for k, sigma in enumerate(face_sigmas()) if sigma and (probed & (face == k)).any()]
    out.append(("step-gauge.length", term(length_sigma() * distance)))
    per_setup = float(np.hypot(cosine_rms(conditions), expansion_rms(conditions)))
    for k, name in enumerate(design.mountings):
        if isinstance(design.specs[k], StepGaugeSpec):
            mine = design.mounting == k
            out.append((f"step-gauge.scale[{name}]", term(np.where(mine, per_setup * distance,
                                                                    0.0))))
    return out


def drift_terms(since: np.ndarray, t: np.ndarray, conditions: Conditions,
                heat: np.ndarray | None = None) -> list[tuple[str, np.ndarray]]:
    """A gauge mounting's drift at lab times ``t``, ``since`` its first reading (s, same
    shapes): its creep at the time constant's Simpson nodes and, with the room on, its
    arm's growth, against the room's ``heat`` since that reading (same shapes) when a
    thermometer read it, else linear in the clock; (name, pattern in mm per unit
    coefficient).  Only under ``stands``."""
    creep = np.sqrt(second_moment("stands", "creep", conditions)) * UM
    out = [(f"stands.creep{j}", np.sqrt(w) * creep * (1 - np.exp(-since / tau)))
           for j, (w, tau) in enumerate(zip(_WEIGHTS, _taus("stands", "creep_time",
                                                            conditions), strict=True))]
    if "room" in conditions and heat is not None:
        # The growth itself, against the thermometer (its offset cancels here).
        arm = np.sqrt(second_moment("stands", "thermal", conditions)) * UM
        out.append(("stands.thermal", arm * heat))
    elif "room" in conditions:
        # The walk's variance at one hour folded into the drift's.
        rate2 = (second_moment("room", "drift", conditions)
                 + second_moment("room", "walk", conditions)) / HOUR**2
        arm = np.sqrt(second_moment("stands", "thermal", conditions) * rate2) * UM
        out.append(("stands.thermal", arm * t))
    return out


def dial_terms(y: np.ndarray, travel: float, conditions: Conditions
               ) -> list[tuple[str, np.ndarray]]:
    """An indicator's error curve at readings ``y`` (mm, the plunger's position up to the
    mounting's zero) of a gauge of ``travel``: (name, pattern in mm per unit coefficient);
    none without the ``dial`` effect."""
    if "dial" not in conditions:
        return []
    parameter = "digital_range" if conditions.indicator == "digital" else "range"
    # Half-amplitudes drawn uniformly; a random phase splits E[A^2] between sin, cos.
    waves = [("range", parameter, np.pi * y / travel)]
    if conditions.indicator != "digital":
        waves.append(("revolution", "revolution", 2 * np.pi * y / REVOLUTION_MM))
    out = []
    for label, row, wave in waves:
        size = np.sqrt(second_moment("dial", row, conditions) / 2) * UM / 2
        out += [(f"dial.{label}_sin", size * np.sin(wave)),
                (f"dial.{label}_cos", size * np.cos(wave))]
    return out


def consider_terms(design: ReadingLayout, values: np.ndarray, times: np.ndarray | None,
                   conditions: Conditions, spacing: float | None = None,
                   temperatures: np.ndarray | None = None) -> Consider:
    """The consider terms of ``design`` read as ``values`` (M, N) at lab ``times`` (M, N)
    or None, under ``conditions``; ``spacing``: the lead error as a pitch-error table
    with nodes that far apart (:func:`lead_terms`); ``temperatures``: the room's (M, N,
    C) as a thermometer read it with each reading, or None.  ``ValueError`` when an
    effect that acts needs the readings' times and they are not given."""
    needs = [e for e in TIMED_EFFECTS if e in conditions]
    if needs and times is None:
        raise ValueError(f"under the {conditions.name} conditions every reading needs its "
                         f"time (time_s) to size {', '.join(needs)}")
    t = None if times is None else np.asarray(times, dtype=float)
    m_count, n = len(values), len(design)
    drive, pivot = _drive_terms(design, t, conditions, spacing)
    reading = _reading_terms(design, values, t, conditions,
                             None if temperatures is None else np.asarray(temperatures, float))
    drive_array = (np.stack([np.broadcast_to(p, (m_count, n, 3)) for _, p in drive], axis=-1)
                   if drive else np.zeros((m_count, n, 3, 0)))
    reading_array = (np.stack([np.broadcast_to(p, (m_count, n)) for _, p in reading],
                              axis=-1) if reading else np.zeros((m_count, n, 0)))
    return Consider(tuple(name for name, _ in drive) + tuple(name for name, _ in reading),
                    drive_array, reading_array,
                    None if pivot is None else np.broadcast_to(pivot, drive_array.shape))


def _on_rows(pattern: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
    """(M, N): ``pattern`` (M, len(rows)) at ``rows``, zero elsewhere."""
    out = np.zeros((len(pattern), n))
    out[:, rows] = pattern
    return out
