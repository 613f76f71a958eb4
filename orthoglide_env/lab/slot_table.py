"""The slot table: what a gauge at each slot of a design's catalogue would do at each
candidate posture of the nominal machine, and where its plunger may safely go down.

An experiment's designer (``calibrators.planning.belief``), the world's terms it weighs
(``calibrators.planning.world_terms``) and the env's design wrappers
(:mod:`orthoglide_env.wrappers`, whose actions are its candidate operations) read it; it is
computed once per process and design (seconds).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from orthoglide_env.instruments.dial import pressed_past_travel
from orthoglide_env.instruments.rays import exact_ray_distances, exact_target_boxes
from orthoglide_env.instruments.stands import install, installed_on
from orthoglide_env.lab.kept import Kept
from orthoglide_env.lab.operations import slot_catalogue
from orthoglide_env.model.boxes import collision_boxes
from orthoglide_env.model.collisions import clearance
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import ERROR_NAMES, MachineParams
from orthoglide_env.model.kinematics import axis_postures, direct
from orthoglide_env.reading_model import ReadingLayout, default_scales, jacobian, predict

if TYPE_CHECKING:
    from orthoglide_env.instruments.slots import GaugeSpec

#: A plunger goes down only where its tip's predicted distance from the pushed-in end is
#: at least this many standard deviations of the prediction plus :data:`END_GAP` (mm):
#: a fault costs two minutes and the stand's readings until it is re-mounted, so the risk
#: is kept below ~1e-3 per engaged posture.
SAFETY_SIGMAS: float = 3.0
END_GAP: float = 0.5
#: Where the tip misses its bar, a plunger may stay down only if the bar, grown by this
#: much (mm) all round, would still not press it: ~3 sigma of how far the machine errors
#: move a bar.
PRESS_MARGIN: float = 3.0
#: Closest two parts that must never meet may come at a candidate posture, on the
#: nominal model (mm): more than the machine errors move them.
CLEARANCE: float = 3.0

def candidate_postures(design: MachineDesign) -> np.ndarray:
    """Postures an experiment may visit (P, 3): a 20 mm grid of the machine design's joint
    cube; denser tubes along each axis (20 mm along it, 10 mm across from -40 to +20
    mm), where the gauges on that axis's bars stay within their travel; and the postures
    that put the TCP on each axis (:func:`~orthoglide_env.model.kinematics.axis_postures`,
    20 mm apart and at both limits: the paper's Max and Min among them), where that leg's
    gauges, wherever they meet their targets, are as far from them as at Zero on the
    nominal machine: mid-travel, the surest readings a plan can count on."""
    along = np.arange(design.rho_min, design.rho_max + 1e-9, 20.0)
    side = np.arange(-40.0, 20.0 + 1e-9, 10.0)
    points = [np.stack(np.meshgrid(along, along, along, indexing="ij"), -1).reshape(-1, 3)]
    ends = np.union1d(along, [design.rho_min, design.rho_max])
    for axis in range(3):
        a, b, c = np.meshgrid(along, side, side, indexing="ij")
        tube = np.zeros((*a.shape, 3))
        tube[..., axis], tube[..., (axis + 1) % 3], tube[..., (axis + 2) % 3] = a, b, c
        points += [tube.reshape(-1, 3), axis_postures(axis, ends, design)]
    return np.unique(np.vstack(points), axis=0)


@dataclass(frozen=True)
class SlotTable:
    """What a gauge at each slot of the catalogue would do at each candidate posture on
    the nominal machine (installed as a technician does, zeroed at Zero): ``S`` slots,
    ``P`` postures.  ``change`` is the derivative of its reading's change since Zero over
    the 27 machine errors and its stand's 4 unknowns, per unit of their scale (mm)."""

    postures: np.ndarray  # (P, 3)
    zero: int  # index of the Zero posture
    tip: np.ndarray  # (S, P) nominal tip distance, mm (NaN: the tip misses the bar)
    pressed: np.ndarray  # (S, P) a bar would press the gauge past its travel
    near: np.ndarray  # (S, P) ... if it were PRESS_MARGIN larger all round
    change: np.ndarray  # (S, P, 31)
    at_zero: np.ndarray  # (S, 31) the derivative at Zero, which ``change`` is taken from
    sign: np.ndarray  # (S,) reading = sign * (tip - tip at Zero)
    reading: np.ndarray  # (S, P) nominal reading, zeroed at Zero, of the reading model
    travel: float  # the design's gauge travel, mm

    @cached_property
    def prior_spread(self) -> np.ndarray:
        """(S, P) standard deviation of the tip's change since Zero, a priori (mm)."""
        return np.sqrt(np.sum(self.change**2, axis=-1))

    @cached_property
    def prior_reach(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, P) ``safe`` and ``contact`` of :func:`reach` a priori (what a plan knows)."""
        return reach(self, np.arange(len(self.tip)), self.tip, self.prior_spread)


def reach(table: SlotTable, slots: np.ndarray, tip: np.ndarray, spread: np.ndarray,
          postures: np.ndarray | slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """For gauges at ``slots`` (K,) whose tips are predicted at ``tip`` give or take
    ``spread`` (K, P') at ``postures``, mm: ``safe`` (K, P'), the plunger may be down
    there, and ``contact`` (K, P'), the probability that the tip then touches (0 where
    it misses): :func:`reach_at` of every slot at every posture."""
    index = np.arange(len(table.postures))[postures]
    return reach_at(table, np.asarray(slots)[:, None], index[None, :], tip, spread)


def reach_at(table: SlotTable, slots: np.ndarray, postures: np.ndarray, tip: np.ndarray,
             spread: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reach` of gauges at ``slots`` and candidate ``postures`` (indices, broadcast
    to the shape of ``tip`` and ``spread``), entry by entry: each answer depends on its
    own entry alone, so a caller may ask only the entries it needs.

    Where the tip is on its bar, the tip must be :data:`SAFETY_SIGMAS` of its spread plus
    :data:`END_GAP` off the pushed-in end; where it misses, the bar must be
    :data:`PRESS_MARGIN` clear of pressing the gauge's body."""
    # SciPy loads at the first reach asked, not with the module: a comparison's own
    # process imports the planner's modules (its agents') but asks none.
    from scipy.special import ndtr

    missed = np.isnan(tip)
    with np.errstate(invalid="ignore"):
        safe = np.where(missed, ~at_entries(table.near, slots, postures),
                        ~at_entries(table.pressed, slots, postures)
                        & (tip - SAFETY_SIGMAS * spread >= END_GAP))
    contact = np.zeros(tip.shape)
    touches = safe & ~missed
    contact[touches] = ndtr((table.travel - tip[touches]) / np.maximum(spread[touches], 1e-9))
    return safe, contact


def at_entries(values: np.ndarray, slots: np.ndarray, postures: np.ndarray) -> np.ndarray:
    """``values[slots, postures]`` of an (S, P) array (a slot table's, or a
    belief's stands' spread bounds) at row and posture indices (non-negative, broadcast
    together), by one ``take`` of their flat index: a third of the price of indexing with
    both, on the few hundred entries a stand is asked at every decision."""
    return np.take(values, slots * values.shape[1] + postures)


#: The slot tables this process made or was handed (:func:`handed_tables`), by design.
_TABLES: Kept[MachineDesign, SlotTable] = Kept(2)


def slot_table(machine_design: MachineDesign) -> SlotTable:
    """The :class:`SlotTable` of every slot of the design's catalogue over the
    :func:`candidate_postures` the nominal machine of ``machine_design`` reaches with its
    parts :data:`CLEARANCE` apart (once per process and design: seconds; a sweep's
    workers are handed it, :func:`handed_tables`)."""
    return _TABLES.get(machine_design, lambda: _slot_table(machine_design))


def made_tables() -> dict[MachineDesign, SlotTable]:
    """The slot tables this process has made, by design: for a sweep's workers
    (:func:`handed_tables`), which then need not make them again."""
    return _TABLES.made()


def handed_tables(tables: dict[MachineDesign, SlotTable]) -> None:
    """Keep ``tables`` (:func:`made_tables` of another process) as if made here, with
    what each has worked out since (its a-priori spread and reach)."""
    _TABLES.handed(tables)


def _slot_table(machine_design: MachineDesign) -> SlotTable:
    """:func:`slot_table`, made."""
    nominal = MachineParams(design=machine_design)
    postures = candidate_postures(machine_design)
    boxes = collision_boxes(nominal, postures, direct(nominal, postures))
    keep = clearance(nominal, postures, boxes) >= CLEARANCE
    postures = postures[keep]
    boxes = tuple(b[keep] for b in boxes)
    slots = slot_catalogue(machine_design)
    gauges = installed_on(nominal, install(list(slots), nominal))
    # Slot by slot in memory (C order): a planner gathers a stand's row at every posture,
    # or a slot's value at each of a few hundred postures, at every decision.
    tip = np.ascontiguousarray(np.moveaxis(exact_ray_distances(nominal, gauges, postures,
                                                               boxes), -1, 0))
    centre, rot, half = exact_target_boxes(gauges, boxes)
    pressed = np.ascontiguousarray(np.moveaxis(pressed_past_travel(gauges, centre, rot, half),
                                               -1, 0))
    near = np.ascontiguousarray(np.moveaxis(pressed_past_travel(gauges, centre, rot,
                                                                half + PRESS_MARGIN), -1, 0))
    zero = int(np.flatnonzero(np.all(postures == 0.0, axis=1))[0])
    change = np.zeros((len(slots), len(postures), len(ERROR_NAMES) + 4))
    at_zero = np.zeros((len(slots), len(ERROR_NAMES) + 4))
    reading = np.zeros((len(slots), len(postures)))
    for k, spec in enumerate(slots):
        design = _one_slot(spec, postures, machine_design)
        change[k], at_zero[k] = _change(design, np.zeros(len(ERROR_NAMES) + 4), zero)
        values = predict(np.zeros(len(ERROR_NAMES) + 4), design)
        reading[k] = values - values[zero]
    sign = np.array([g.sign for g in gauges], dtype=float)
    return SlotTable(postures, zero, tip, pressed, near, change, at_zero, sign, reading,
                     machine_design.gauge_travel)


def _one_slot(spec: GaugeSpec, postures: np.ndarray, machine_design: MachineDesign
              ) -> ReadingLayout:
    """The readings of one gauge at ``spec``'s slot at every one of ``postures``."""
    return ReadingLayout(("m",), (spec,), np.zeros(len(postures), dtype=int), postures,
                         machine_design)


def _change(layout: ReadingLayout, theta: np.ndarray, zero: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """The derivative (per unit of scale) of ``layout``'s readings' change since posture
    ``zero`` at parameters ``theta`` (P, 31), and of the reading at ``zero`` (31,)."""
    scale = default_scales(layout.space)
    rows = jacobian(theta, layout, np.ones(len(scale), bool), scale)
    return rows - rows[zero], rows[zero]


def changes_at(machine: MachineParams, stands: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """:attr:`SlotTable.change` and :attr:`SlotTable.at_zero` of ``machine``'s design's
    table linearised at ``machine`` (its errors) with each slot's stand installed with
    ``stands`` (S, 4) parameters (:data:`~orthoglide_env.instruments.stands.STAND_PARAMS`;
    None: as the technician aims it) in place of the nominal machine's: what the
    derivatives are at a machine's truth (a yardstick's, never a plan's; seconds).  The
    postures are the table's."""
    table = slot_table(machine.design)
    slots = slot_catalogue(machine.design)
    installed = np.zeros((len(slots), 4)) if stands is None else np.asarray(stands, float)
    if installed.shape != (len(slots), 4):
        raise ValueError(f"stands must be ({len(slots)}, 4), got {installed.shape}")
    change, at_zero = np.zeros_like(table.change), np.zeros_like(table.at_zero)
    for k, spec in enumerate(slots):
        theta = np.concatenate([machine.to_vector(), installed[k]])
        change[k], at_zero[k] = _change(_one_slot(spec, table.postures, machine.design),
                                        theta, table.zero)
    return change, at_zero
