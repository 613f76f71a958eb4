"""The certified search over the stands' slot sets (calibrators.planning.slot_search): its
node bounds are below every set of the node, and it agrees with taking every set in turn.

On a quarter hour with dials alone (seconds a problem) and a universe of four slots beyond
the paper's, so that every set can be solved."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

from calibrators.planning.bound import held_design, lab_model, solve
from calibrators.planning.slot_search import (
    Search,
    axis_cycle,
    slot_visits,
    symmetric,
)
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.world.conditions import Conditions

LAB = Conditions("lab")
BUDGET = 900.0
DIALS = ("dial",)
#: Slots beyond the paper's: across the x leg near its platform end (where optimal's plans
#: re-mount), the y leg's, the z leg's and the x carriage.
UNIVERSE = (0, 15, 23, 30)
SETUP = ((), False)


def _optimum(visits) -> tuple[float, float]:
    """A node problem's certified value and its design's (mm^2)."""
    model = lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, DIALS, 6)
    lower, value, _ = solve(model, visits, np.zeros(0, dtype=int))
    return lower, value


@pytest.fixture(scope="module")
def every_set() -> dict[tuple[int, ...], tuple[float, float]]:
    """B_2(E) of every set of two slots of the universe: certified value and design's."""
    out = {}
    for slots in itertools.combinations(UNIVERSE, 2):
        found = held_design(PROTOTYPE, LAB, SIGMA, BUDGET, DIALS, slots, 2)
        out[slots] = (found.bound.bound_mm ** 2, found.bound.design_mm ** 2)
    return out


@pytest.mark.slow
def test_a_node_bound_is_below_every_set_of_the_node(every_set):
    # The node: slot 0 held, 15, 23 and 30 free, two re-mounts.  Its sets are {0, j}; each
    # bound of the node (every free slot read freely, share 0, or a free slot's readings
    # priced, the surrogate) is a relaxation of each, so its certified value is below each
    # set's design (a value of a point of that set's problem): no tolerance needed.
    sets = [every_set[(0, j)][1] for j in (15, 23, 30)]
    for share in (0.0, 1.0, 4.0):
        visits = slot_visits(PROTOTYPE, BUDGET, DIALS, 6, SETUP, 2, (0,), (15, 23, 30),
                             share)
        lower, _ = _optimum(visits)
        assert lower <= min(sets)
    # With as many free slots as re-mounts left, the node is one set's own problem.
    visits = slot_visits(PROTOTYPE, BUDGET, DIALS, 6, SETUP, 2, (0,), (15,), 4.0)
    lower, value = _optimum(visits)
    assert lower <= every_set[(0, 15)][1] and every_set[(0, 15)][0] <= value
    with pytest.raises(ValueError, match="re-mounts"):
        slot_visits(PROTOTYPE, BUDGET, DIALS, 6, SETUP, 1, (0, 15), (), 1.0)
    assert slot_visits(PROTOTYPE, BUDGET, DIALS, 6, SETUP, 8, (), UNIVERSE) is None


@pytest.mark.slow
def test_the_search_agrees_with_every_set_taken_in_turn(every_set):
    model = lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, DIALS, 6)
    best = min(every_set, key=lambda s: every_set[s][1])
    lowest = min(lower for lower, _ in every_set.values())
    # A target below every set's certified value: the search closes every node.
    below = Search(model, PROTOTYPE, BUDGET, DIALS, SETUP, 0.99 * lowest, share=4.0,
                   universe=UNIVERSE)
    found = below.certify(2)
    assert found.certified and found.least > 0.99 * lowest
    # A target above the best set's design: the search finds a set whose design is below
    # it (the best set, or another as good).
    above = Search(model, PROTOTYPE, BUDGET, DIALS, SETUP, 1.01 * every_set[best][1],
                   share=4.0, universe=UNIVERSE)
    found = above.certify(2)
    assert found.below is not None and not found.certified
    slots, solved = found.below
    assert solved.value <= 1.01 * every_set[best][1]
    assert every_set[tuple(sorted(slots))][0] <= 1.01 * every_set[best][1]


def test_the_lab_is_the_same_with_the_axes_renamed():
    # What lets the search take the laser on x for y and z: f at a design and at its
    # image agree to the rounding of a Cholesky solve.
    model = lab_model(PROTOTYPE, LAB, SIGMA, 3600.0, ("dial", "interferometer"), 6)
    image = axis_cycle(model, PROTOTYPE)
    assert image is not None and sorted(image) == list(range(len(image)))
    assert symmetric(model, image)
    # A design and its image differ: the check is not of a design with itself.
    assert not np.array_equal(image, np.arange(len(image)))
    # A model whose candidates are not renamed onto themselves fails the check.
    shifted = np.roll(image, 1)
    assert not symmetric(model, shifted)
