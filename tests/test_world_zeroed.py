"""``benchmarks/world_excess.py --zero``: an effect's drawn values at zero, every other draw
the same, so that its rows pair machine by machine with the world where everything acts."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import fields

import numpy as np
import pytest
from conftest import ROOT

from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.truth import World

# Appended, not put first: the folder's statistics.py must not stand for the standard
# library's in this process.
sys.path.append(str(ROOT / "benchmarks"))
from world_excess import DRAWN, zeroed

STANDS = 6


def drawn(seed: int) -> World:
    """One machine's world under ``lab`` from its seed, then stands 0 and 2 re-mounted at
    minute 30 from the same stream."""
    stream = np.random.default_rng(seed)
    return World.draw(Conditions("lab"), stream, STANDS).mounted(stream, 1800.0, [0, 2])


@pytest.mark.parametrize("effects", [("warmup",), ("stands",), ("lead", "room", "dial")])
def test_zeroed_effects_draw_nothing_and_the_rest_the_same(effects: tuple[str, ...]) -> None:
    every = drawn(11)
    with zeroed(effects):
        some = drawn(11)
    gone = {f for e in effects for f in DRAWN[e]}
    for field in fields(World):
        if field.name == "conditions":
            continue
        value = np.asarray(getattr(some, field.name))
        if field.name in gone:
            assert not value.any(), field.name
            # The draw it replaces was not zero: the row would pair with nothing removed.
            assert np.asarray(getattr(every, field.name)).any(), field.name
        else:
            np.testing.assert_array_equal(value, getattr(every, field.name), err_msg=field.name)
    # Left, the draws are the world's again.
    np.testing.assert_array_equal(drawn(11).warm_amplitude, every.warm_amplitude)


def test_an_effect_of_fixed_sizes_is_refused() -> None:
    done = subprocess.run([sys.executable, "benchmarks/world_excess.py", "--zero",
                           "compliance"], capture_output=True, text=True, cwd=ROOT,
                          timeout=120, check=False)
    assert done.returncode == 2
    assert "--zero takes effects of" in done.stderr
