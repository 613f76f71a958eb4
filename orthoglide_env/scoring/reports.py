"""What a score reports: the TCP error's RMS and maximum in each of the three frames."""

from __future__ import annotations

from dataclasses import asdict, dataclass

#: The frames a TCP error is reported in, headline last.
FRAMES: tuple[str, ...] = ("raw", "translation", "rigid")


class _Plain:
    """A result that scripts read as nested dicts of numbers (mm): :meth:`to_dict`."""

    def to_dict(self) -> dict:
        return asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class ErrorStats(_Plain):
    """RMS and maximum (mm) of the TCP error's length over the targets."""

    rms: float
    max: float


@dataclass(frozen=True)
class FrameErrors(_Plain):
    """One TCP error in the three frames of :data:`FRAMES`: as a dict, ``{"raw": {"rms",
    "max"}, "translation": {...}, "rigid": {...}}`` in mm."""

    raw: ErrorStats
    translation: ErrorStats
    rigid: ErrorStats


@dataclass(frozen=True)
class ScoreReport(_Plain):
    """Parameter errors (estimate - truth, mm) and TCP errors over the workspace grid,
    before and after compensation, over the same targets."""

    drho_error: list[float]
    dL_error: list[float]
    tcp_before: FrameErrors
    tcp_after: FrameErrors
    n_targets: int
    n_skipped: int

