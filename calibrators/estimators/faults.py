"""Faults found in a fit's readings, each named with its kind and where it is: a stand
that moved (``knock``: a change point in its mounting's residuals), a change common to
several stands at once (``thermal-step`` or ``lost-steps``: a door opened or a drive lost
steps, not told apart here), a reading written with the wrong sign (``sign``), a dial that
stuck (``stick``: an outlier repeating its mounting's previous reading) and a row skipped
on the sheet (``skip``: from a reading on, each fits the posture before its own).

A found knock or skipped row comes with the readings repaired for a refit: the moved
stand's readings from the change on as a new mounting (its own zero, a new nuisance
parameter), the late rows put back against their postures.  Each test works at a stated
significance level per fit (:data:`LEVEL`), Bonferroni-corrected over the splits it
tries, so a clean experiment is flagged at most that often.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from itertools import pairwise

import numpy as np

from calibrators.estimators.holdout import held_out_residuals
from calibrators.measurements import Measurements
from orthoglide_env.model.errors import AXIS_NAMES
from orthoglide_env.reading_model import ReadingLayout, TrackerAxis

#: The false-alarm probability of each test on one clean fit.
LEVEL: float = 0.005
#: A segment of a mounting's readings on either side of a change point holds at least this
#: many readings (fewer cannot tell a step from a wrong reading).
MIN_SEGMENT: int = 3
#: Change points of different stands within this lab time (s) are one change.
COMMON_S: float = 120.0
#: A sign slip's residual is twice its reading within this many sigmas (and the reading is
#: itself beyond them: a small reading negated is inside the error bars).
SIGN_K: float = 4.0
#: The step (mm) of a drive's offset that its readings' sensitivities are taken over: the
#: model is linear in an encoder offset to well below a reading's sigma over it.
DRIVE_STEP: float = 1e-3
#: Against the nominal machine a reading may be off by at most this (mm) before it is
#: taken for a slip (a fit that does not converge is screened with it, a session's answer
#: checked): an assumption, above the 1.75 mm that a realistic machine's errors moved a
#: gauge reading by in a 20-minute designed experiment (tests/test_hostile_faults.py's).
NOMINAL_MM: float = 2.5
#: A fit repairs at most this many faults (a moved stand, a skipped row), one refit each.
MAX_REPAIRS: int = 3
#: The prefix of every warning of this module: ``fault <kind>: ...``.
PREFIX: str = "fault"


def _isf(p: float) -> float:
    """The standard normal's upper ``p`` quantile."""
    # Imported here: a command's --help imports no scipy (and the standard library's
    # ``statistics`` is shadowed by benchmarks/statistics.py for the benchmark scripts).
    # scipy.special's, what scipy.stats.norm.isf returns bit for bit, without its
    # three milliseconds a call and its import.
    from scipy.special import ndtri

    return float(-ndtri(p))


@dataclass
class Finding:
    """One fault found: its ``kind``, the warning's words and, for a repairable one, the
    readings repaired (None: nothing to refit)."""

    kind: str
    text: str
    repaired: Measurements | None = None
    where: str = ""  # the mounting or drive it is of ("" for the room)


def _place(data: Measurements, k: int) -> str:
    m = data.items[k]
    return f"line {m.line}" if m.line else f"reading {k + 1}"


def _mountings(data: Measurements, used: np.ndarray) -> dict[str, np.ndarray]:
    """Each gauge mounting's used readings, in the order they were taken."""
    out: dict[str, list[int]] = {}
    for k, m in enumerate(data.items):
        if used[k] and not isinstance(m.gauge, TrackerAxis):
            out.setdefault(m.mounting or m.gauge.slot, []).append(k)
    return {name: np.array(ks) for name, ks in out.items()}


def change_points(residuals: np.ndarray, groups: dict[str, np.ndarray], spread: float,
                  level: float = LEVEL) -> list[tuple[str, int, float, float]]:
    """Each mounting (``groups``: its readings' indices) whose ``residuals`` step at one
    reading beyond the ``level`` test (two-sample z of the means before and after, in units
    of ``spread``, Bonferroni over every split tried): (mounting, first reading after the
    step, the step in mm, its z)."""
    splits = sum(max(0, len(ks) - 2 * MIN_SEGMENT + 1) for ks in groups.values())
    if not splits:
        return []
    threshold = _isf(level / (2 * splits))
    found = []
    for name, ks in groups.items():
        r, n = residuals[ks], len(ks)
        if n < 2 * MIN_SEGMENT:
            continue
        k = np.arange(MIN_SEGMENT, n - MIN_SEGMENT + 1)
        before = np.cumsum(r)[k - 1]
        step = (r.sum() - before) / (n - k) - before / k
        z = np.abs(step) / (spread * np.sqrt(1 / k + 1 / (n - k)))
        best = int(np.argmax(z))
        if z[best] > threshold:
            found.append((name, int(ks[k[best]]), float(step[best]), float(z[best])))
    return found


def drive_sensitivities(design: ReadingLayout, values: np.ndarray, theta: np.ndarray,
                        used: np.ndarray) -> np.ndarray:
    """(3, N) how each reading's residual moves per mm of each drive's offset (``drho``
    of the fit at ``theta``), each mounting's zero taken again from its ``used``
    readings."""
    every = np.ones(len(values), dtype=bool)
    base = held_out_residuals(design, values, theta, used, every)
    out = np.zeros((3, len(values)))
    for a, axis in enumerate(AXIS_NAMES):
        moved = theta.copy()
        moved[design.space.names.index(f"drho_{axis}")] += DRIVE_STEP
        out[a] = (base - held_out_residuals(design, values, moved, used, every)) / DRIVE_STEP
    return out


def drive_steps(residuals: np.ndarray, drives: np.ndarray, used: np.ndarray, spread: float,
                level: float = LEVEL) -> tuple[int, int, float, float] | None:
    """The drive whose offset changes from one reading on beyond the ``level`` test (a
    score test per drive and reading, Bonferroni over all of them; the fit's own
    parameters, which the residuals are orthogonal to, only make it conservative): (drive,
    first reading after the change, the change in mm, its z); None if none does."""
    ks = np.flatnonzero(used & np.isfinite(residuals))
    if len(ks) < 2 * MIN_SEGMENT:
        return None
    r, g = residuals[ks], np.nan_to_num(drives[:, ks])
    score = np.cumsum((g * r)[:, ::-1], axis=1)[:, ::-1]  # from each reading on
    info = np.cumsum((g * g)[:, ::-1], axis=1)[:, ::-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(info > 0, np.abs(score) / (spread * np.sqrt(info)), 0.0)
    z[:, :MIN_SEGMENT] = z[:, len(ks) - MIN_SEGMENT + 1:] = 0.0
    drive, at = np.unravel_index(int(np.argmax(z)), z.shape)
    if z[drive, at] <= _isf(level / (2 * z.size)):
        return None
    return int(drive), int(ks[at]), float(score[drive, at] / info[drive, at]), float(
        z[drive, at])


def _split(data: Measurements, mounting: str, first: int) -> Measurements:
    """``data`` with ``mounting``'s readings from reading ``first`` on as a new mounting."""
    new = f"{mounting}+moved"
    items = [replace(m, mounting=new, design=data.design)
             if k >= first and (m.mounting or m.gauge.slot) == mounting else m
             for k, m in enumerate(data.items)]
    return replace(data, items=items)


def _late(values: np.ndarray, residuals: np.ndarray, ks: np.ndarray, spread: float,
          level: float) -> int | None:
    """The first of a mounting's readings ``ks`` from which each fits the prediction of the
    reading before it better than its own (a row skipped), when the gain passes the
    ``level`` test; None otherwise."""
    if len(ks) < 2 * MIN_SEGMENT:
        return None
    predicted = values[ks] - residuals[ks]
    own = residuals[ks[1:]] ** 2
    shifted = (values[ks[1:]] - predicted[:-1]) ** 2
    gain = np.cumsum((own - shifted)[::-1])[::-1] / spread**2  # from each reading on
    count = np.arange(len(gain), 0, -1)
    # Under no skip the gain's mean is at most 0; its scale grows with the moves between
    # readings, so a chi-square bound on the shifted residuals is asked for as well.
    fits = np.cumsum(shifted[::-1])[::-1] / spread**2 <= count + _isf(level) * np.sqrt(
        2 * count)
    ok = (gain > _isf(level / len(gain)) * np.sqrt(2 * count) + count) & fits
    ok[len(gain) - MIN_SEGMENT + 1:] = False
    return int(ks[1:][np.argmax(ok)]) if ok.any() else None


def _realigned(data: Measurements, mounting: str, first: int) -> Measurements:
    """``data`` with ``mounting``'s readings from reading ``first`` on put back one row:
    each takes the value written in the next row; the last, whose value is lost, goes."""
    mine = [k for k, m in enumerate(data.items)
            if k >= first and (m.mounting or m.gauge.slot) == mounting]
    items = list(data.items)
    for a, b in pairwise(mine):
        items[a] = replace(items[a], reading=data.items[b].reading, design=data.design)
    del items[mine[-1]]
    return replace(data, items=items)


def _against_nominal(design: ReadingLayout, values: np.ndarray) -> np.ndarray:
    """Each reading minus the nominal machine's, each mounting's zero the median of its
    readings' offsets."""
    every = np.ones(len(values), dtype=bool)
    raw = held_out_residuals(design, values, np.zeros(len(design.space.names)), every, every)
    for k in range(len(design.mountings)):
        mine = design.mounting == k
        raw[mine] -= np.median(raw[mine]) if mine.any() else 0.0
    return raw


def slips_against_nominal(data: Measurements, design: ReadingLayout, values: np.ndarray,
                          level: float = LEVEL) -> list[Finding]:
    """What stops a fit of ``data`` from converging, found against the nominal machine:
    the readings it puts more than :data:`NOMINAL_MM` away while their negative is within
    it (sign slips, each with the readings without them), else a mounting whose rows are
    written late (:func:`_late` on the nominal residuals, in units of their robust spread),
    with the rows put back."""
    raw = _against_nominal(design, values)
    gauge = np.array([not isinstance(m.gauge, TrackerAxis) for m in data.items])
    slips = np.flatnonzero(gauge & (np.abs(raw) > NOMINAL_MM)
                           & (np.abs(raw - 2 * values) < NOMINAL_MM))
    if not len(slips):
        spread = 1.4826 * float(np.median(np.abs(raw[gauge])))
        for name, ks in _mountings(data, gauge).items():
            first = _late(values, raw, ks, spread, level)
            if first is not None:
                return [Finding("skip", f"{PREFIX} skip: {name}, from {_place(data, first)} on "
                                "each reading fits the posture before its own better: a row "
                                "skipped on the sheet (fitted with the rows put back)",
                                _realigned(data, name, first), name)]
        return []
    kept = replace(data, items=[m for k, m in enumerate(data.items) if k not in set(slips)])
    return [Finding("sign", f"{PREFIX} sign: {_place(data, k)} "
                    f"({data.items[k].mounting or data.items[k].gauge.slot}) reads "
                    f"{values[k]:+.3f} mm where the nominal machine expects "
                    f"{values[k] - raw[k]:+.3f} mm: written with the wrong sign (left out)",
                    kept) for k in slips]


def find_faults(data: Measurements, residuals: np.ndarray, used: np.ndarray,
                outliers: list[int], sigma: float, level: float = LEVEL,
                drives: Callable[[], np.ndarray] | None = None, structural: bool = True,
                words: bool = True) -> list[Finding]:
    """The faults a fit of ``data`` shows: its ``residuals`` (mm, per reading), the readings
    it ``used``, its left-out ``outliers``, the gauges' ``sigma`` (mm) and what makes the
    residuals' sensitivities to the drives' offsets (:func:`drive_sensitivities`, called
    only where their test is run; None: drives not looked at).  A drive's change steps
    several stands at once: it is named instead of the stands' steps when its test is
    stronger than each of theirs.  ``structural``: look for steps and late rows at all
    (their tests hold where the model can fit the machine; outliers are named whatever
    the model).  ``words``: every fault found is wanted; else only those that repair the
    readings (a row skipped, a knocked stand) and what holds them back: the drives' test,
    which repairs nothing, is then run only where a stand steps."""
    values = np.array([m.reading for m in data.items])
    gauge = np.array([not isinstance(m.gauge, TrackerAxis) for m in data.items])
    finite = used & gauge & np.isfinite(residuals)
    if not finite.any():
        return []
    spread = max(sigma, 1.4826 * float(np.median(np.abs(residuals[finite]))))
    found: list[Finding] = []
    # Each reading's mounting, which only the outliers are named by (most fits have none).
    names = [m.mounting or m.gauge.slot for m in data.items] if outliers else []
    # Steps and rows written late are looked for only where the model can fit the machine.
    groups = _mountings(data, finite) if structural else {}
    # Rows written late are far from the model, and mostly left out: all of a mounting's
    # readings are followed, in order.
    followed = _mountings(data, gauge & np.isfinite(residuals)) if structural else {}
    for name, ks in followed.items():
        first = _late(values, residuals, ks, spread, level)
        if first is not None:
            found.append(Finding("skip", f"{PREFIX} skip: {name}, from {_place(data, first)} "
                                 "on each reading fits the posture before its own: a row "
                                 "skipped on the sheet (refitted with the rows put back)",
                                 _realigned(data, name, first), name))
            groups.pop(name, None)
            break
    late = {f.where for f in found}
    for k in outliers:
        if not gauge[k] or names[k] in late:  # a late row's outliers are the skip's
            continue
        previous = [j for j in range(k) if names[j] == names[k]]
        if previous and values[previous[-1]] == values[k]:
            found.append(Finding("stick", f"{PREFIX} stick: {_place(data, k)} ({names[k]}) "
                                 f"repeats its previous reading {values[k]:+.3f} mm where the "
                                 f"model expects {values[k] - residuals[k]:+.3f} mm: a plunger "
                                 "that stuck (left out)", where=names[k]))
        elif (abs(values[k]) > SIGN_K * spread
              and abs(residuals[k] - 2 * values[k]) < SIGN_K * spread):
            found.append(Finding("sign", f"{PREFIX} sign: {_place(data, k)} ({names[k]}) "
                                 f"reads {values[k]:+.3f} mm where the model expects "
                                 f"{values[k] - residuals[k]:+.3f} mm: written with the wrong "
                                 "sign (left out)", where=names[k]))
    if not structural:
        return found
    steps = change_points(residuals, groups, spread, level)
    drive = (None if drives is None or not (words or steps)
             else drive_steps(residuals, drives(), finite, spread, level))
    if drive is not None and all(drive[3] >= s[3] for s in steps):
        axis, first, size, z = drive
        found.append(Finding("lost-steps", f"{PREFIX} lost-steps: drive {AXIS_NAMES[axis]} "
                             f"is off by about {1e3 * size:+.0f} um from {_place(data, first)} "
                             f"on (z = {z:.1f}): a drive that lost steps; re-home it",
                             where=AXIS_NAMES[axis]))
        return found
    times = {k: data.items[k].time_s for k in range(len(values))}
    common = [s for s in steps if sum(
        abs((times[s[1]] or 0.0) - (times[t[1]] or 0.0)) <= COMMON_S for t in steps) > 1]
    if common:
        where = ", ".join(f"{name} {1e3 * step:+.0f} um" for name, _, step, _ in common)
        found.append(Finding("thermal-step", f"{PREFIX} thermal-step or lost-steps: several "
                             f"stands step at once near {_place(data, common[0][1])} "
                             f"({where}): the room's temperature stepped or a drive lost "
                             "steps"))
    for name, first, step, _ in steps:
        if any(name == c[0] for c in common):
            continue
        found.append(Finding("knock", f"{PREFIX} knock: stand {name} moved by about "
                             f"{1e3 * step:+.0f} um at {_place(data, first)}: refitted with "
                             "a new mounting from there on", _split(data, name, first), name))
    return found
