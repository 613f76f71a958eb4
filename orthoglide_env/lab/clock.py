"""The lab's clock: the seconds each operation of a step takes, from the time table.

The table itself (:data:`~orthoglide_env.lab.operations.TIME`) says what one operation
costs; here it is applied to a batch of steps, one entry per episode.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.lab.operations import CODE, TIME


def move_dwell_seconds(tracker: bool = False, laser: np.ndarray | bool = False,
                       probe: np.ndarray | bool = False) -> np.ndarray:
    """Seconds a move takes on top of its drive and settle: the tracker's point where the
    lab has a tracker, the interferometer's dwell while it is set up (``laser``) and the
    probe's on a step gauge's face while it is on one (``probe``); one entry per entry of
    ``laser`` and ``probe`` (broadcast).  The lab charges it (:func:`travel_seconds`) and
    a planner prices its moves with it, so the two clocks agree."""
    return ((TIME.tracker_point_s if tracker else 0.0)
            + np.where(laser, TIME.interferometer_target_s, 0.0)
            + np.where(probe, TIME.step_gauge_face_s, 0.0))


def travel_seconds(op: np.ndarray, before: np.ndarray, goal: np.ndarray, tracker: bool,
                   blocked: np.ndarray | None = None, laser: np.ndarray | None = None,
                   soak: np.ndarray | None = None, probe: np.ndarray | None = None
                   ) -> np.ndarray:
    """Seconds (R,) each move, re-mount, interferometer or ballbar set-up takes to drive the
    carriages from ``before`` to ``goal`` (R, 3) and settle, and then: a move its dwell
    (:func:`move_dwell_seconds`: the tracker's point where the lab has a tracker, and in a
    lab with the interferometer or the step gauge their dwells while set up, ``laser``
    (R,) and ``probe`` (R,)), a re-mount or a ballbar set-up its work, and a re-mount at a
    reference slot (``blocked``, (R,), in a lab with the gauge block) the block's; in a
    lab with the interferometer, a set-up its work (and the material sensor's soak before
    the first, ``soak`` (R,)); in a lab with the step gauge, a set-up its work."""
    work = np.where(op == CODE.PIVOT, TIME.ballbar_setup_s, TIME.remount_s)
    if laser is not None and soak is not None:
        setup = TIME.interferometer_setup_s + np.where(soak, TIME.interferometer_soak_s, 0.0)
        work = np.where(op == CODE.ALIGN, setup, work)
    if probe is not None:
        work = np.where(op == CODE.PLACE, TIME.step_gauge_setup_s, work)
    dwell = move_dwell_seconds(tracker, False if laser is None or soak is None else laser,
                               False if probe is None else probe)
    seconds = TIME.move(before, goal) + np.where(op == CODE.MOVE, dwell, work)
    if blocked is not None:
        seconds = seconds + np.where(blocked, TIME.reference_s, 0.0)
    return seconds


def step_seconds(ok: np.ndarray, flicks: np.ndarray, carried: np.ndarray,
                 travel_s: np.ndarray) -> np.ndarray:
    """Seconds (R,) of each step before any overtravel: a refused operation costs a flick of
    a lever (the technician tried), as a lift or an engagement does; a move or re-mount
    (``carried``) its ``travel_s``; a stop nothing."""
    seconds = np.where(ok, 0.0, TIME.lift_s)
    seconds[flicks] = TIME.lift_s
    seconds[carried] = travel_s[carried]
    return seconds


def overtravel_seconds(new: np.ndarray) -> np.ndarray:
    """Seconds (R,) to check, re-install and re-zero the stands newly pushed past their
    travel (``new``, (R, stands))."""
    return TIME.overtravel_s * np.count_nonzero(new, axis=-1)
