"""Which operations the lab refuses, and why: a stand that is not mounted, a slot that is
taken, a posture the machine cannot be assembled at."""

from __future__ import annotations

import contextlib

import numpy as np

from orthoglide_env.instruments.slots import GaugeSpec
from orthoglide_env.lab.operations import CODE
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.model.kinematics import UnreachableError, direct


def assembled(machines: MachineParams, rho: np.ndarray) -> np.ndarray:
    """The TCP (R, 3) of each machine of a batch at its ``rho`` (R, 3); NaN rows where it
    cannot be assembled."""
    try:
        return direct(machines, rho)
    except UnreachableError:
        pass
    out = np.full((len(rho), 3), np.nan)
    for r in range(len(rho)):
        with contextlib.suppress(UnreachableError):
            out[r] = direct(machines[r], rho[r])
    return out


def refusals(machines: MachineParams, rows: np.ndarray, op: np.ndarray, rho: np.ndarray,
             stand: np.ndarray, slot: np.ndarray, target: np.ndarray, held: np.ndarray,
             places: list[GaugeSpec]) -> tuple[list[str], np.ndarray]:
    """Why each well-formed operation of episodes ``rows`` of ``machines`` cannot be done
    ("" when it can): a stand that is not mounted cannot be lifted or engaged, a slot holds
    one stand, and the machine cannot be driven where it cannot assemble; and the TCP
    (R, 3) where each move (or ballbar or step-gauge set-up) takes it (NaN where none),
    solved to know that.  ``target``: where each move puts the carriages; ``held``: the
    slot index of each stand of the rows (R, stands; -1: not mounted), indices into
    ``places``."""
    out = [""] * len(rows)
    reached = np.full((len(rows), 3), np.nan)
    flick = (op == CODE.LIFT) | (op == CODE.ENGAGE)
    for r in np.flatnonzero(flick & (held[np.arange(len(rows)), stand] < 0)):
        out[r] = f"stand {stand[r]} is not mounted"
    others = (held == slot[:, None]) & (np.arange(held.shape[1]) != stand[:, None])
    for r in np.flatnonzero((op == CODE.REMOUNT) & others.any(axis=-1)):
        out[r] = f"slot {places[slot[r]].slot} already holds a stand"
    moves = np.flatnonzero((op == CODE.MOVE) | (op == CODE.PIVOT) | (op == CODE.PLACE))
    if len(moves):
        reached[moves] = assembled(machines[rows[moves]], target[moves])
        for r in moves[np.isnan(reached[moves, 0])]:
            out[r] = f"the machine cannot assemble at rho = {rho[r].tolist()}"
    return out, reached


def raise_unreachable(machines: MachineParams, rows: np.ndarray, op: np.ndarray,
                      rho: np.ndarray, reached: np.ndarray, target: np.ndarray,
                      size: int) -> None:
    """``ValueError`` for the first move its machine cannot be assembled at (naming its env
    in a batch of ``size`` > 1), before anything changes (a lab of strict moves)."""
    bad = np.flatnonzero((op == CODE.MOVE) & np.isnan(reached[:, 0]))
    if not len(bad):
        return
    r = int(bad[0])
    try:
        direct(machines[rows[r]], target[r])
    except UnreachableError as exc:
        reason = str(exc)
    else:  # solved alone, not in the batch: the batch's reason is all there is
        reason = "the machine cannot be assembled there"
    where, after = ((f" of env {rows[r]}", "no env moves") if size > 1
                    else ("", "it stays where it was"))
    raise ValueError(f"action{where} {rho[r].tolist()} mm: {reason} on this machine; "
                     f"{after}")
