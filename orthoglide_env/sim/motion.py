"""How a simulated machine moves between postures: the motion modes every back-end accepts
(the exact model's and PyBullet's), checked in one place."""

from __future__ import annotations

MOTION_MODES: tuple[str, ...] = ("quasi-static", "dynamic")


def check_motion_mode(mode: str) -> None:
    """Refuse a motion mode no back-end has, naming the ones there are."""
    if mode not in MOTION_MODES:
        raise ValueError(f"unknown motion mode '{mode}'; choose from {list(MOTION_MODES)}")
