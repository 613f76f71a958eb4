"""A lab episode's notebook: every reading written down, and the information it carries.

:class:`Record` is one reading (instrument, mounting, posture, value, when); a
:class:`Notebook` holds an episode's records, every installation (the truth, for scoring)
and the information sums of the records about the machine's errors, which the lab's
``information`` reward and its predicted TCP error (``info["predicted_tcp_rigid_mm"]``)
are made of.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from orthoglide_env.instruments.ballbar import BallbarSpec
from orthoglide_env.instruments.ballbar import sigma as ballbar_sigma
from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.instruments.gauges import Gauge, GaugeArray
from orthoglide_env.instruments.step_gauge import StepGaugeSpec
from orthoglide_env.instruments.step_gauge import sigma as step_gauge_sigma
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import ERROR_NAMES, MachineParams
from orthoglide_env.reading_model import (
    ParameterSpace,
    ReadingLayout,
    Spec,
    TrackerAxis,
    default_scales,
    jacobian,
    station_of,
)
from orthoglide_env.scoring.predicted import predicted_tcp_frames
from orthoglide_env.world.conditions import Conditions


@dataclass(frozen=True)
class Record:
    """One reading the lab wrote down: which instrument, which mounting, where, what."""

    spec: Spec  # a gauge's slot, or one coordinate of the tracker
    mounting: str
    rho: tuple[float, float, float]
    reading: float
    step: int
    time_s: float  # lab time when it was read
    temperature_c: float | None = None  # the room thermometer's reading then (C), if any

    @classmethod
    def written(cls, spec: Spec, mounting: str, rho: tuple[float, float, float],
                reading: float, step: int, time_s: float, temperature_c: float | None
                ) -> Record:
        """The record the lab writes, the same as ``Record(...)`` of these fields: its
        fields go straight into the instance's dict, neither one by one through the
        frozen class's ``object.__setattr__`` nor through a dict of keywords (half and a
        third of the cost of a record; a sweep's lab writes tens of thousands of them)."""
        out = object.__new__(cls)
        fields = out.__dict__
        fields["spec"] = spec
        fields["mounting"] = mounting
        fields["rho"] = rho
        fields["reading"] = reading
        fields["step"] = step
        fields["time_s"] = time_s
        fields["temperature_c"] = temperature_c
        return out


Estimator = Callable[[list[Record], float], MachineParams]


class Notebook:
    """One episode's lab notebook: its records, every installation (truth, for scoring),
    and the information the records carry about the machine's errors."""

    def __init__(self, gauge_sigma: float, tracker_sigma: float,
                 design: MachineDesign) -> None:
        self.records: list[Record] = []
        self._design = design
        self._installed: dict[str, Gauge] = {}
        #: The first installations, as mounting names and the row of a batch of gauge sets:
        #: turned into gauges when asked for (a sweep's scoring never asks).
        self._first: tuple[list[str], GaugeArray, int] | None = None
        self._gauge_sigma = weighting_sigma(gauge_sigma)
        self._tracker_sigma = tracker_sigma
        # The ballbar's scatter in a lab room: the information's weight of its readings.
        self._bar_sigma = ballbar_sigma(Conditions("lab"))
        self._probe_sigma = step_gauge_sigma(Conditions("lab"))
        # Per mounting: count, sum and sum of outer products of its Jacobian rows, names.
        self._sums: dict[str, tuple[int, Any, Any, tuple[str, ...]]] = {}
        self._informed = 0  # records already in the sums
        self._logdet = 0.0

    def install(self, names: list[str], gauges: GaugeArray, row: int) -> None:
        """The episode's first installations: ``names``' gauges are row ``row`` of
        ``gauges``."""
        self._installed, self._first = {}, (names, gauges, row)

    @property
    def installed(self) -> dict[str, Gauge]:
        """Every installation by mounting name, in mounting order (truth, for scoring)."""
        if self._first is not None:
            names, gauges, row = self._first
            self._first = None
            self._installed = dict(zip(names, gauges[row].to_gauges(), strict=True))
        return self._installed

    def _add_information(self, records: list[Record]) -> None:
        """Add the records' rows of the Jacobian (at the nominal machine, per unit of each
        parameter's scale, per unit of noise; one batched call) to their mountings' sums:
        the information of a mounting, its zero eliminated, is ``S2 - S1 S1^T / n``.  A
        mounting's records are summed together, each added in its turn to the sum before
        it as one at a time would (no pairwise summation, :func:`_outer_sum`): the same
        bits, without a mounting's columns worked out again for every record."""
        layout = ReadingLayout.of([r.mounting for r in records], [r.spec for r in records],
                                  np.array([r.rho for r in records]), self._design)
        space = layout.space
        rows = jacobian(np.zeros(len(space)), layout, np.ones(len(space), bool),
                        default_scales(space))
        for m, spec in enumerate(layout.specs):
            at = np.flatnonzero(layout.mounting == m)
            # The mounting's own columns: the machine's errors and its instrument's.
            mine = _mounting_columns(space, m)
            names = tuple(space.names[c] for c in mine)
            own = rows[np.ix_(at, mine)] / self._sigma(spec)
            n, s1, s2, _ = self._sums.get(space.mountings[m], (0, 0.0, 0.0, names))
            s1 = np.add.accumulate(np.concatenate(
                [np.broadcast_to(s1, (1, len(mine))), own]))[-1]
            s2 = _outer_sum(s2, own)
            self._sums[space.mountings[m]] = (n + len(at), s1, s2, names)

    def _sigma(self, spec: Spec) -> float:
        """The weight's sigma of a reading of ``spec``'s instrument."""
        return (self._tracker_sigma if isinstance(spec, TrackerAxis)
                else self._bar_sigma if isinstance(spec, BallbarSpec)
                else self._probe_sigma if isinstance(spec, StepGaugeSpec)
                else self._gauge_sigma)

    def information(self) -> tuple[np.ndarray, list[str]]:
        """The records' information about every parameter they involve, in units of each
        parameter's scale, and the parameters' names."""
        if self._informed < len(self.records):
            self._add_information(self.records[self._informed:])
        self._informed = len(self.records)
        names = list(ERROR_NAMES)
        for _, _, _, mine in self._sums.values():
            names += [n for n in mine if n not in names]
        info = np.zeros((len(names), len(names)))
        for n, s1, s2, mine in self._sums.values():
            idx = [names.index(x) for x in mine]
            info[np.ix_(idx, idx)] += s2 - np.outer(s1, s1) / n
        return info, names

    def update_logdet(self) -> float:
        """The gain in log det(I + F) since the last call."""
        info, _ = self.information()
        logdet = float(np.linalg.slogdet(np.eye(len(info)) + info)[1])
        gain, self._logdet = logdet - self._logdet, logdet
        return gain

    def predicted_tcp_rigid_mm(self) -> float:
        """TCP error RMS after the best-fit rigid motion that the records' information
        predicts (at the nominal machine, a priori sizes from the realistic preset)."""
        info, _ = self.information()
        n = len(ERROR_NAMES)
        scale = default_scales(ParameterSpace())  # the machine's errors'
        posterior = np.linalg.inv(np.eye(len(info)) + info)[:n, :n]
        covariance = posterior * np.outer(scale, scale)
        return predicted_tcp_frames(MachineParams(design=self._design), covariance).rigid.rms


def _outer_sum(start: np.ndarray | float, rows: np.ndarray) -> np.ndarray:
    """``start`` (k, k, symmetric; or 0.0) plus the outer product of each of ``rows`` (n, k)
    with itself, added one at a time in row order: the bits of ``np.add.accumulate`` over
    them, without its (n, k, k) arrays (most of an episode's predicted error).  A row's
    product is symmetric to the bit (a product does not depend on its factors' order), so
    every sum is too: the upper triangle is summed and mirrored."""
    k = rows.shape[1]
    i, j = np.triu_indices(k)
    total = np.array(np.broadcast_to(start, (k, k))[i, j])
    # In place, row by row: ``np.add.reduce`` over the rows may sum them pairwise.
    for product in rows[:, i] * rows[:, j]:
        total += product
    out = np.empty((k, k))
    out[i, j] = out[j, i] = total
    return out


def _mounting_columns(space: ParameterSpace, mounting: int) -> list[int]:
    """Columns of ``space`` a reading of ``mounting`` depends on: the machine's errors and
    its own instrument's parameters (a stand's four, a tracker station's three)."""
    names = space.names
    prefix = space.mountings[mounting]
    if isinstance(space.specs[mounting], TrackerAxis):
        prefix = station_of(prefix)
    return list(range(len(ERROR_NAMES))) + [
        c for c in range(len(ERROR_NAMES), len(names))
        if names[c].rsplit(".", 1)[0] == prefix]


def predicted_many(notebooks: Sequence[Notebook]) -> list[float]:
    """:meth:`Notebook.predicted_tcp_rigid_mm` of each notebook; notebooks whose
    information is not summed yet and whose records share a design share one computation
    (a fixed plan on many machines reads the same design on each)."""
    out: list[float] = []
    done: dict[tuple, tuple[Notebook, float]] = {}
    for book in notebooks:
        if book._informed:
            out.append(book.predicted_tcp_rigid_mm())
            continue
        # The information depends on every record's mounting and posture only (a lab's
        # mounting name holds its slot, hence its instrument).
        key = tuple((r.mounting, r.rho) for r in book.records)
        if key in done:
            first, value = done[key]
            book._sums, book._informed = dict(first._sums), first._informed
        else:
            value = book.predicted_tcp_rigid_mm()
            done[key] = (book, value)
        out.append(value)
    return out
