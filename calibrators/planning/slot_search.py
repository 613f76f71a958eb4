"""A certified bound of every plan of a lab with re-mounts counted whole: branch and bound
over the slot sets the stands stand at, per choice of set-ups.

:func:`~calibrators.planning.bound.held_design`'s ``B_r(E)`` bounds the plans that
re-mount ``r`` times and mount stands at the paper's slots and the set ``E`` beyond them;
the least ``B_r`` over the sets of at most ``r`` of the catalogue's slots bounds every plan
that re-mounts ``r`` times.  There are too many sets to solve each (``C(33, 5)`` is
237,336), and a convex problem over every slot at once is no tighter than the convex hull
of the plans' readings, which holds designs spread over every slot (mixtures of plans
each at other slots).  So the search branches on the slots and bounds each branch by a
convex problem (:func:`slot_visits`, one set-up's polytope):

* **A node** is the sets ``E`` with ``held <= E <= allowed`` and ``|E| <= r``.
* **Its first bound** is ``B_r(allowed)``: every slot of ``allowed`` on any visit, the
  budget less ``r`` whole re-mounts.  ``B_r`` only falls as slots are added (a larger
  polytope), so it is below every ``B_r(E)`` of the node.
* **Its second bound** holds ``held`` and lets the other allowed slots (``free``) be read
  at a price per reading.  A plan of the node mounts at most ``k = r - |held|`` of them,
  each read at most once a visit and on at most ``S / settle`` visits (``S`` the
  visits' seconds), so its readings of free slots number at most ``k S / settle``.
  Adding that count times a price ``p`` to the visits' seconds and ``p k S / settle`` to
  the budget (a surrogate of the two constraints) keeps every such plan a point, at any
  ``p >= 0``; ``p = 0`` is the first bound, and ``p`` the re-mount's time over the visits
  a slot can be read on (``share`` 1) prices a re-mount as the relaxation does, but
  whole re-mounts only ``k`` of them.
* **The children** of a node, lexicographically: the slots of ``free`` in the order of
  its design's readings, ``j1, j2, ...``; child ``i`` holds ``ji`` and allows ``allowed``
  less ``j1 .. j(i-1)``.  Their first bounds rise with ``i`` (fewer slots), so once one
  passes the target every later child does: the chain of first bounds is solved until
  then, and each child before it is bounded by its second bound and opened if that does
  not pass.  A node with ``|allowed| <= r`` (or ``r`` slots held) is one set: its ``B_r``.

Each problem is solved by :func:`~calibrators.planning.bound.solve` and stopped once its
certified value passes the target (the node is closed) or its design falls below it (the
node is opened): a search certifies "above the target" or finds a set below it, not the
least value.  Every closed node's certified value is below the optimum of its problem, so
the least of them is a certified bound of every plan of the search's ``r``.

:func:`least_remounts` gives the other end: a plan that re-mounts ``r`` or more times
spends ``r`` whole re-mounts, so ``B_r`` of every slot (no share, the stands free) bounds
every such plan, and it rises with ``r``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from calibrators.planning.bound import (
    BAR,
    BoundModel,
    Visits,
    dial_grid,
    problems,
    solve,
    start_slots,
)
from orthoglide_env.lab.operations import TIME, slot_catalogue
from orthoglide_env.lab.slot_table import slot_table
from orthoglide_env.model.design import MachineDesign

#: A choice of set-ups: the drives the laser is set up on, and the pivot or not.
Setup = tuple[tuple[int, ...], bool]


def slot_visits(design: MachineDesign, budget_s: float, instruments: tuple[str, ...],
                stands: int, setup: Setup, remounts: int, held: tuple[int, ...],
                free: tuple[int, ...], share: float = 1.0) -> Visits | None:
    """The polytope of a node (see the module): the plans with ``setup`` that re-mount
    ``remounts`` times and mount stands at the paper's slots, every slot of ``held`` and
    at most ``remounts - len(held)`` of ``free``; the budget less the re-mounts, and each
    reading of a free slot priced ``share`` times a re-mount over the visits a slot can be
    read on (0, or as many free slots as re-mounts left: every slot read freely).  None
    where the set-up and re-mounts leave no time."""
    if share < 0:
        raise ValueError(f"share must be at least 0, got {share}")
    mounts = remounts - len(held)
    if mounts < 0:
        raise ValueError(f"{len(held)} held slots need as many re-mounts, got {remounts}")
    start = start_slots(design, stands)
    if set(held) & set(free) or (set(held) | set(free)) & set(start):
        raise ValueError("held and free slots must be apart and beyond the paper's")
    left = budget_s - remounts * TIME.remount_s
    if not left > 0:
        return None
    found = [v for drives, pivot, v in problems(design, left, instruments, stands, False)
             if (drives, pivot) == setup]
    if not found:
        return None
    visits = found[0]
    if share == 0 or mounts >= len(free):
        return replace(visits, start=start + tuple(held) + tuple(free))
    price = share * TIME.remount_s * visits.settle_s / visits.seconds
    seconds = visits.seconds + price * mounts * visits.seconds / visits.settle_s
    # Visits prices a reading of a slot beyond ``start`` at remount_s settle / seconds.
    return replace(visits, seconds=seconds, start=start + tuple(held),
                   remount_s=price * seconds / visits.settle_s,
                   phases=(start + tuple(held) + tuple(free),))


@dataclass(frozen=True)
class Solved:
    """One node problem: ``lower`` its certified value, ``value`` its design's (mm^2; inf
    both where the set-up leaves no time), and the readings per slot of the design."""

    lower: float
    value: float
    per_slot: np.ndarray


@dataclass
class Search:
    """The branch and bound of one lab, budget and set-up against ``target`` (mm^2):
    ``model`` the lab's :class:`BoundModel`; ``universe`` the slots beyond the paper's a
    set may take (None: every slot a stand reads); ``progress`` gets a line per node."""

    model: BoundModel
    design: MachineDesign
    budget_s: float
    instruments: tuple[str, ...]
    setup: Setup
    target: float
    stands: int = 6
    share: float = 1.0
    progress: Callable[[str], None] = lambda line: None
    universe: tuple[int, ...] | None = None
    solves: int = 0

    @property
    def candidates(self) -> tuple[int, ...]:
        """The slots a set may take: ``universe``, or those beyond the paper's that a stand
        reads at some candidate posture."""
        if self.universe is not None:
            return tuple(sorted(self.universe))
        start = start_slots(self.design, self.stands)
        readable = np.flatnonzero((dial_grid(self.model) >= 0).any(axis=0))
        return tuple(int(s) for s in readable if s not in start)

    def bound(self, remounts: int, held: tuple[int, ...], free: tuple[int, ...],
              share: float = 0.0) -> Solved:
        """The node's problem (:func:`slot_visits`) solved until it is decided against
        the target."""
        visits = slot_visits(self.design, self.budget_s, self.instruments, self.stands,
                             self.setup, remounts, held, free, share)
        dials = np.flatnonzero(self.model.laser == -1)
        if visits is None:
            return Solved(np.inf, np.inf, np.zeros(0))
        drives, pivot = self.setup
        lasers = np.flatnonzero(np.isin(self.model.laser, drives))
        bars = np.flatnonzero(self.model.laser == BAR) if pivot else None
        lower, value, counts = solve(self.model, visits, lasers, self.target, bars,
                                     stop_below=self.target)
        self.solves += 1
        per_slot = np.bincount(self.model.label[dials, 0], counts[dials],
                               minlength=int(self.model.label[dials, 0].max()) + 1)
        return Solved(max(lower, 0.0), value, per_slot)

    def least_remounts(self, most: int) -> tuple[int | None, list[tuple[int, Solved]]]:
        """The fewest re-mounts ``R`` (up to ``most``) from which on ``B_R`` of every
        slot, the stands free, passes the target: every plan that re-mounts ``R`` or more
        times is above it.  Each ``r`` tried with its solution, in order; None if none."""
        tried = []
        every = self.candidates
        for r in range(most + 1):
            found = self.bound(r, (), every)
            tried.append((r, found))
            self.progress(f"r >= {r}: {_um(found.lower)} um certified "
                          f"(design {_um(found.value)})")
            if found.lower > self.target:
                return r, tried
        return None, tried

    def certify(self, remounts: int, cpu_s: float = np.inf) -> Certificate:
        """The branch and bound of the plans that re-mount ``remounts`` times, until every
        node is closed, a set's ``B`` is below the target, or ``cpu_s`` CPU seconds of this
        process have passed (the nodes left open are returned)."""
        out = Certificate(remounts)
        stop = time.process_time() + cpu_s
        every = self.candidates if remounts else ()
        root = self.bound(remounts, (), every)
        if root.lower > self.target:
            out.record(root.lower)
            return out
        stack: list[tuple[tuple[int, ...], tuple[int, ...], Solved]] = [((), every, root)]
        while stack:
            if time.process_time() > stop:
                out.open = [(held, allowed) for held, allowed, _ in stack]
                return out
            held, allowed, first = stack.pop()
            self._expand(out, stack, remounts, held, allowed, first)
            if out.below is not None:
                out.open = [(h, a) for h, a, _ in stack]
                return out
        return out

    def _expand(self, out: Certificate, stack: list, remounts: int, held: tuple[int, ...],
                allowed: tuple[int, ...], first: Solved) -> None:
        """Open the node (``held``, ``allowed``) whose first bound ``first`` is not above
        the target: its children's chain, each child closed, decided as one set, or
        pushed on ``stack``."""
        current, solved = allowed, first
        while True:
            free = tuple(s for s in current if s not in held)
            if len(current) <= remounts:
                # One set left, E = current: its own B_r, decided against the target.
                out.record(solved.lower)
                if solved.value <= self.target:
                    out.below = (current, solved)
                elif solved.lower <= self.target:
                    out.undecided.append((current, solved))
                return
            j = max(free, key=lambda s: (solved.per_slot[s] if s < len(solved.per_slot)
                                         else 0.0, -s))
            child = tuple(sorted((*held, j)))
            if len(child) == remounts:
                own = self.bound(remounts, child, ())
                out.record(own.lower)
                self.progress(f"r = {remounts}: set {child}: {_um(own.lower)} um "
                              f"(design {_um(own.value)}), {len(stack)} open")
                if own.value <= self.target:
                    out.below = (child, own)
                    return
                if own.lower <= self.target:
                    out.undecided.append((child, own))
            else:
                rest = tuple(s for s in current if s not in child)
                second = self.bound(remounts, child, rest, self.share)
                self.progress(f"r = {remounts}: held {child}, {len(rest)} free: "
                              f"{_um(second.lower)} um (design {_um(second.value)}), "
                              f"{len(stack)} open")
                if second.lower > self.target:
                    out.record(second.lower)
                else:
                    stack.append((child, current, solved))
            current = tuple(s for s in current if s != j)
            solved = self.bound(remounts, (), current)
            self.progress(f"r = {remounts}: held {held}, {len(current)} allowed: "
                          f"{_um(solved.lower)} um (design {_um(solved.value)})")
            if solved.lower > self.target:
                out.record(solved.lower)
                return


@dataclass
class Certificate:
    """What a search of the plans that re-mount ``remounts`` times found: ``least`` the
    least certified value of its closed nodes (mm^2: every plan it closed is above it);
    ``below`` a set whose ``B`` design is at or below the target (then no certificate);
    ``undecided`` sets within the solver's gap of the target; ``open`` the nodes (held,
    allowed) left when the search stopped.  Certified above the target when ``below`` is
    None and nothing is undecided or open."""

    remounts: int
    least: float = np.inf
    below: tuple[tuple[int, ...], Solved] | None = None
    undecided: list[tuple[tuple[int, ...], Solved]] = field(default_factory=list)
    open: list[tuple[tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)

    def record(self, lower: float) -> None:
        self.least = min(self.least, lower)

    @property
    def certified(self) -> bool:
        return self.below is None and not self.undecided and not self.open


def axis_cycle(model: BoundModel, design: MachineDesign, stands: int = 6
               ) -> np.ndarray | None:
    """The candidates of ``model`` with the axes renamed x to y, y to z and z to x (the
    index of each candidate's image; a laser on drive ``a`` goes to drive ``a + 1``), or
    None where a slot, posture or target has no image or the stands' first slots are not
    their own image."""
    rename = str.maketrans("xyz", "yzx")
    names = [spec.slot for spec in slot_catalogue(design)]
    slots = [names.index(n.translate(rename)) if n.translate(rename) in names else -1
             for n in names]
    start = start_slots(design, stands)
    if {slots[s] for s in start} != set(start):
        return None
    postures = slot_table(design).postures
    where = {tuple(np.round(p, 9)): k for k, p in enumerate(postures)}
    turned = [where.get(tuple(np.round(np.roll(p, 1), 9)), -1) for p in postures]
    index = {tuple(int(v) for v in label): i for i, label in enumerate(model.label)}
    image = []
    for slot, posture, target in model.label:
        if slot >= 0:
            key = ((slots[slot], turned[posture], -1) if slots[slot] >= 0
                   and turned[posture] >= 0 else None)
        elif slot == -1:
            key = (-1, (int(posture) + 1) % 3, int(target))
        else:
            return None  # the ballbar's circles are not renamed here
        if key is None or key not in index:
            return None
        image.append(index[key])
    return np.array(image)


def symmetric(model: BoundModel, image: np.ndarray, trials: int = 3, seed: int = 0,
              rtol: float = 1e-9) -> bool:
    """Whether ``f`` is the same at random designs and at their images under ``image``
    (:func:`axis_cycle`): then a set-up's search answers for its renamed set-ups too."""
    rng = np.random.default_rng(seed)
    for _ in range(trials):
        picked = rng.choice(len(image), min(300, len(image)), replace=False)
        counts = np.zeros(len(image))
        counts[picked] = rng.uniform(0.0, 5.0, len(picked))
        turned = np.zeros(len(image))
        turned[image[picked]] = counts[picked]
        if not np.isclose(model.value(turned), model.value(counts), rtol=rtol, atol=0.0):
            return False
    return True


def _um(value: float) -> str:
    return f"{1e3 * np.sqrt(value):.3f}"
