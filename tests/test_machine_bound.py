"""The bound at a machine (calibrators.planning.bound.machine_bound_model): the nominal
bound at the nominal machine, below every plan at its machine, and another bound at a
realistic machine."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import DIAL_SIGMA as SIGMA

from calibrators.agents.paper import REPETITIONS, paper_plan
from calibrators.planning.bound import (
    Design,
    best_design,
    bound_model,
    lab_model,
    machine_bound_model,
    plan_counts,
)
from calibrators.study.episodes import machine_seed
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.lab.operations import PAPER_SLOTS
from orthoglide_env.lab.slot_table import changes_at, slot_table
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import MachineParams, random_machine
from orthoglide_env.world.conditions import Conditions

LAB = Conditions("lab")
BUDGET = 3600.0
NOMINAL = MachineParams(design=PROTOTYPE)


@pytest.fixture(scope="module")
def realistic() -> MachineParams:
    """Machine 0 of a comparison seeded 1 on the realistic preset (as the lab draws it)."""
    return random_machine(machine_seed(1, 0), "realistic", design=PROTOTYPE)


@pytest.fixture(scope="module")
def nominal_design() -> Design:
    return best_design(PROTOTYPE, LAB, SIGMA, BUDGET)


@pytest.fixture(scope="module")
def machine_design(realistic) -> Design:
    return best_design(PROTOTYPE, LAB, SIGMA, BUDGET, machine=realistic)


def test_the_nominal_machines_model_is_the_nominal_model():
    # The same derivatives, the same weight: the same arithmetic, so equal to rounding.
    at = machine_bound_model(NOMINAL, LAB, SIGMA, True)
    nominal = bound_model(PROTOTYPE, LAB, SIGMA, True)
    scale = np.abs(nominal.rows).max()
    assert np.allclose(at.rows, nominal.rows, rtol=0, atol=1e-12 * scale)
    assert np.allclose(at.factor, nominal.factor, rtol=0,
                       atol=1e-12 * np.abs(nominal.factor).max())
    assert np.array_equal(at.label, nominal.label)
    assert np.array_equal(at.laser, nominal.laser)


@pytest.mark.slow
def test_the_bound_at_the_nominal_machine_is_the_nominal_bound(nominal_design):
    at = best_design(PROTOTYPE, LAB, SIGMA, BUDGET, machine=NOMINAL).bound
    found = nominal_design.bound
    # Each certified value is below the optimum and each design's above it, so the two
    # optima agree to the certificates.
    assert at.bound_mm <= found.design_mm and found.bound_mm <= at.design_mm


@pytest.mark.slow
def test_plans_at_a_machine_lie_above_its_bound(realistic, nominal_design, machine_design):
    model = lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, ("dial",), len(PAPER_SLOTS), realistic)
    certified = machine_design.bound.bound_mm**2
    # The nominal bound's design is a point of the machine's problem (the same
    # candidates and visits), and so are the paper's readings: both lie above its
    # certified bound (f - gap is below f of every feasible design).
    assert model.value(nominal_design.counts) >= certified
    legs = tuple(spec.leg for spec in PAPER_LAYOUT)
    paper = [dict(a) for a in paper_plan(legs, (True,) * len(legs), REPETITIONS, PROTOTYPE)]
    counts = plan_counts(model, PROTOTYPE, PAPER_SLOTS, (True,) * len(PAPER_SLOTS), paper)
    assert model.value(counts) >= certified
    # The machine's own design is worth no less at the machine than at the nominal one
    # there: the nominal design there is no better than the machine's best found.
    assert machine_design.bound.design_mm**2 <= model.value(nominal_design.counts)


@pytest.mark.slow
def test_a_realistic_machines_bound_is_not_the_nominal_one(nominal_design, machine_design):
    # Certified intervals [bound, design] of the two optima that do not meet: the
    # machine's geometry moves the bound by more than the solver's certificates.
    at, found = machine_design.bound, nominal_design.bound
    assert at.bound_mm > found.design_mm or at.design_mm < found.bound_mm


def test_a_bound_at_a_machine_refuses_what_it_cannot_model(realistic):
    with pytest.raises(ValueError, match="ballbar"):
        lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, ("dial", "ballbar"), 6, realistic)
    other = MachineParams(design=replace(PROTOTYPE, gauge_travel=PROTOTYPE.gauge_travel + 1))
    with pytest.raises(ValueError, match="design"):
        lab_model(PROTOTYPE, LAB, SIGMA, BUDGET, ("dial",), 6, other)
    with pytest.raises(ValueError, match="stands"):
        changes_at(realistic, np.zeros((len(slot_table(PROTOTYPE).tip), 3)))
