"""One trial of a comparison (an agent and an estimator on one machine): what it scored,
and its line of the trials file."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from calibrators.estimators.base import leaves
from orthoglide_env.model.errors import ERROR_NAMES


@dataclass(frozen=True)
class Trial:
    """One agent and one estimator on one machine."""

    agent: str
    estimator: str
    machine: int
    failed: str = ""  # why, when the estimate could not be made
    time_s: float = float("nan")
    readings: int = 0
    tcp_before: dict[str, float] = field(default_factory=dict)  # frame -> RMS mm
    tcp_after: dict[str, float] = field(default_factory=dict)
    predicted_rigid_mm: float = float("nan")
    #: The estimator's chi-square test rejects its model on these readings (None: the
    #: estimator has no such test, or the trial failed).
    chi2_rejected: bool | None = None
    z: list[float] = field(default_factory=list)
    error: list[float] = field(default_factory=list)  # estimate - truth, 27 errors
    std: list[float] = field(default_factory=list)  # reported, NaN where fixed
    curve: list[list[float]] = field(default_factory=list)  # [seconds, rigid RMS mm]
    warnings: list[str] = field(default_factory=list)  # the estimate's
    #: The kinds of fault that acted in the episode (a lab with faults; the truth).
    faults: list[str] = field(default_factory=list)

    @property
    def key(self) -> tuple[str, str, int]:
        return self.agent, self.estimator, self.machine

    @property
    def names(self) -> tuple[str, ...]:
        """The machine errors that ``error`` and ``std`` hold, in order (none if failed)."""
        return ERROR_NAMES if self.error else ()

    def to_json(self) -> str:
        """One line of strict JSON: ``names`` beside ``error`` and ``std``, and ``null``
        where a number is not one (NaN: the std of an error the fit held fixed, or what a
        failed trial never had)."""
        data = {**asdict(self), "names": list(self.names)}
        if not self.faults:
            del data["faults"]  # a line as a lab without faults always wrote it
        return json.dumps(leaves(data, lambda v: None if v != v else v), allow_nan=False)

    @classmethod
    def from_json(cls, line: str) -> Trial:
        """A line of :meth:`to_json`, or of an earlier version (NaN for null, no
        ``names``)."""
        data = json.loads(line)
        names = data.pop("names", None)
        # A trial holds None nowhere else.
        rejected = data.pop("chi2_rejected", None)
        trial = cls(**leaves(data, lambda v: float("nan") if v is None else v),
                    chi2_rejected=rejected)
        if names is not None and tuple(names) != trial.names:
            raise ValueError("the trial's error names are not this version's machine errors")
        return trial
