"""The checks of the envs' actions: joint targets for both envs, the lab's whole action.

One rule for joint targets, whichever env takes them: integers or floats (never
booleans, text, complex numbers or objects), of the right shape, finite and inside the
joint limits, else ``ValueError`` naming the action (and the env of a vector env).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from orthoglide_env.lab.operations import CODE, V0_OPS, V1_OPS, V2_OPS, Op
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import check_rho
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM


def check_targets(value: Any, shape: tuple[int, ...], *, clip: bool = False,
                  rows: np.ndarray | None = None, name: str = "action",
                  design: MachineDesign) -> np.ndarray:
    """Joint targets (mm, float64) from ``value`` of ``shape``: ``(3,)`` for one env,
    ``(N, 3)`` for N, or ``ValueError`` naming the rule.  With ``clip`` finite targets are
    clipped into the joint limits.  ``rows``: which rows must be valid targets (the others
    are not used); ``name``: what the caller calls the value; ``design``: whose control
    limits bound the targets."""
    try:
        values = np.asarray(value)
    except (TypeError, ValueError):
        values = np.asarray(None)
    # Integer and float arrays only: numpy would also read booleans, numeric strings
    # and complex numbers with a zero imaginary part as numbers, and turns a boolean
    # among numbers in a list into a number silently.
    if values.dtype.kind not in "iuf" or _holds_bool(value):
        what = "3 numbers" if shape == (3,) else f"an array of shape {shape} of numbers"
        raise ValueError(f"{name} must be {what} (mm), not text, booleans, complex "
                         f"numbers or objects; got {value!r}")
    target = values.astype(np.float64)
    if target.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {target.shape}")
    if clip:
        finite = np.all(np.isfinite(target), axis=-1, keepdims=True)
        target = np.where(finite, np.clip(target, design.rho_min, design.rho_max), target)
    if target.ndim == 1:
        return check_rho(target, design=design)
    used = np.ones(len(target), dtype=bool) if rows is None else rows
    low, high = design.rho_min, design.rho_max
    bad = used & ~np.all(np.isfinite(target) & (target >= low) & (target <= high), axis=-1)
    if bad.any():
        env = int(np.flatnonzero(bad)[0])
        try:
            check_rho(target[env], design=design)
        except ValueError as exc:
            raise ValueError(f"{name} of env {env}: {exc}") from None
    return target


def _holds_bool(value: Any) -> bool:
    """Whether a (nested) list or tuple holds a boolean anywhere."""
    if isinstance(value, list | tuple):
        return any(isinstance(v, bool | np.bool_) or _holds_bool(v) for v in value)
    return False


def check_lab_actions(action: Any, shape: tuple[int, ...], stands: int, slots: int,
                      rows: np.ndarray | None = None, *, design: MachineDesign,
                      version: int = 0) -> tuple[np.ndarray, ...]:
    """``op``, ``rho``, ``stand``, ``slot`` of a lab action (``shape ()``) or of a batch of
    them (``shape (N,)``, each field with the batch axis first), as arrays, or
    ``ValueError`` naming the field (and the env).  ``slots``: the size of the lab's slot
    catalogue; ``rows``: the envs whose action is used (the others are not checked);
    ``rho`` is checked where the operation is a move, a pivot or a place.  ``version`` 1
    (``OrthoglideLab-v1``) adds the ``align`` operation and its ``axis`` field, version 2
    the ``pivot`` operation and its ``bar`` field, version 3 the ``place`` operation, which
    takes ``axis`` too (other operations may leave either out); an align's or a place's
    axis and a pivot's bar are returned in its ``slot``.  Version 4 adds the ``laser``
    field (0 or 1, every operation may leave it out: 1), returned last, as booleans: whether
    a move reads the interferometer set up (and waits its dwell)."""
    keys = {"op", "rho", "stand", "slot"}
    optional = ({"axis"} if version == 1 else {"axis", "bar"} if version in (2, 3)
                else {"axis", "bar", "laser"} if version >= 4 else set())
    if not isinstance(action, dict) or not (keys <= set(action) <= keys | optional):
        raise ValueError("action must be a dict with keys op, rho, stand, slot"
                         + (" and, for align, axis" if version >= 1 else "")
                         + (" and, for pivot, bar" if version >= 2 else "")
                         + (" and, for a move, laser" if version >= 4 else ""))
    used = np.ones(shape, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    ops = (len(Op) if version >= 3 else V2_OPS if version == 2 else V1_OPS if version == 1
           else V0_OPS)
    op = _integers(action["op"], "op", ops, shape, used)
    stand = _integers(action["stand"], "stand", stands, shape, used)
    slot = _integers(action["slot"], "slot", slots, shape, used)
    for kind, key, size, what in ((CODE.ALIGN, "axis", 3, "align: the drive (0, 1, 2 for x, y, "
                                   "z) to set the interferometer up along"),
                                  (CODE.PIVOT, "bar", len(BALLBAR_LENGTHS_MM), "pivot: the "
                                   f"index of the bar's length in {list(BALLBAR_LENGTHS_MM)} "
                                   "mm"),
                                  (CODE.PLACE, "axis", 3, "place: the world axis (0, 1, 2 for "
                                   "x, y, z) to lay the step gauge along")):
        doing = used & (op == kind)
        if doing.any():
            if key not in action:
                raise ValueError(f"action {key} is needed by {what}")
            slot = np.where(doing, _integers(action[key], key, size, shape, doing), slot)
    moving = used & ((op == CODE.MOVE) | (op == CODE.PIVOT) | (op == CODE.PLACE))
    rho = np.zeros((*shape, 3))
    if moving.any():
        given = check_targets(action["rho"], (*shape, 3), rows=moving if shape else None,
                              name="action rho", design=design)
        rho[moving] = given[moving]
    if version < 4:
        return op, rho, stand, slot
    laser = (np.ones(shape, dtype=bool) if "laser" not in action
             else _integers(action["laser"], "laser", 2, shape, used).astype(bool) | ~used)
    return op, rho, stand, slot, laser


def _integers(value: Any, name: str, size: int, shape: tuple[int, ...], used: np.ndarray
              ) -> np.ndarray:
    """An action's integer field: integers (not booleans) in ``[0, size)`` of ``shape``."""
    array = np.asarray(value) if isinstance(value, int | np.integer | np.ndarray) else None
    if array is None or array.dtype.kind not in "iu" or array.shape != shape:
        if shape:
            raise ValueError(f"action {name} must be an integer array of shape {shape}, got "
                             f"{value!r}")
        raise ValueError(f"action {name} must be an integer in [0, {size}), got {value!r}")
    bad = used & ((array < 0) | (array >= size))
    if bad.any():
        where = f" of env {np.flatnonzero(bad)[0]}" if shape else ""
        shown = array[np.flatnonzero(bad)[0]] if shape else value
        raise ValueError(f"action {name}{where} must be an integer in [0, {size}), got "
                         f"{shown!r}")
    return np.where(used, array, 0).astype(np.int64)
