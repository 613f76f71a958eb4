"""The PyBullet cross-check of a comparison: the exact and PyBullet labs, stepped in
lockstep with the same agent on the same machine, agree within the project's 1 um."""

from __future__ import annotations

from calibrators.study.compare import Config
from calibrators.study.crosscheck import verify_pybullet


def test_the_two_labs_agree_step_by_step() -> None:
    gaps = verify_pybullet(Config(agents=("paper",), estimators=("paper6",), seed=3), 1)
    assert gaps["steps"] > 10  # the paper's procedure, every posture of it
    assert gaps["reading_mm"] < 1e-3
    assert gaps["tcp_mm"] < 1e-3
