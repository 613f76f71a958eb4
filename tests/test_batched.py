"""The gauge reading model and the collision test over a batch of machines: one numpy
pass gives exactly what each machine gives on its own.

Exactly means bitwise (NaN where NaN): every operation of the batched path is elementwise
or reduces over axes of one machine (a 3-vector, a box's 15 separating axes, a Newton step
that stops moving a posture once it has converged), so each number is made by the same
floating-point operations in the same order, whatever batch it sits in.  A tolerance
would also hide a row mixed up with its neighbour's, which the random machines below
would only shift by a few µm.
"""

from __future__ import annotations

import numpy as np
import pytest

from orthoglide_env.instruments.dial import (
    Status,
    pressed_past_travel,
    readings_from_distances,
    status_of,
)
from orthoglide_env.instruments.gauges import GaugeArray, spec_arrays
from orthoglide_env.instruments.rays import (
    exact_ray_distances,
    exact_target_boxes,
    target_boxes,
)
from orthoglide_env.instruments.slots import GaugeSpec, Part
from orthoglide_env.instruments.stands import (
    install,
    install_array,
    installation_errors,
    zero_gauges,
)
from orthoglide_env.lab.machines import ExactMachine
from orthoglide_env.model.boxes import collision_boxes
from orthoglide_env.model.collisions import PAIR_NAMES, collision_mask, collisions, pair_gaps
from orthoglide_env.model.design import PROTOTYPE
from orthoglide_env.model.errors import (
    PRESETS,
    MachineParams,
    random_machine,
)
from orthoglide_env.model.kinematics import UnreachableError, direct

GAUGES = 6
POSTURES = 12


def random_layout(rng: np.random.Generator) -> tuple[GaugeSpec, ...]:
    """Six gauges on random legs, axes and places along the legs."""
    specs = []
    for _ in range(GAUGES):
        leg = int(rng.integers(3))
        axis = (leg + 1 + int(rng.integers(2))) % 3
        specs.append(GaugeSpec(leg, axis, float(rng.uniform(0.05, 0.95))))
    return tuple(specs)


def crashing_machine(rng: np.random.Generator) -> MachineParams:
    """A realistic machine whose x-leg's R2 sits 4-12 mm off toward the y axis (outside
    the validity range): its couplers meet near the (60, 60, 60) corner, mostly."""
    m = random_machine(rng, "realistic", design=PROTOTYPE)
    shift = np.zeros((3, 3))
    shift[0, :2] = np.array([-1.0, 1.0]) * rng.uniform(4.0, 12.0)
    return MachineParams(drho=m.drho, dL=m.dL, axis_tilt=m.axis_tilt,
                         axis_offset=m.axis_offset, attach=m.attach + shift)


def far_machine(rng: np.random.Generator) -> MachineParams:
    """Every error between half its validity limit and the limit, random signs."""
    return MachineParams(**{
        key: rng.choice([-1.0, 1.0], shape) * rng.uniform(0.5, 1.0, shape) * limit
        for key, shape, (limit, _) in zip(
            ("drho", "dL", "axis_tilt", "axis_offset", "attach"),
            ((3,), (3,), (3, 2), (3, 2), (3, 3)),
            (PROTOTYPE.validity_range[k]
             for k in ("drho", "dL", "axis_tilt", "axis_offset", "attach")),
            strict=True)
    })


def reachable_postures(machine: MachineParams, rng: np.random.Generator) -> np.ndarray:
    """Small moves (gauges in contact or just past their travel), moves across the whole
    joint cube (gauges off their bars) and the crash corner; a posture the machine cannot
    be assembled in is replaced by Zero (the batch must be solvable as a whole)."""
    rho = np.vstack([rng.uniform(-15, 15, (5, 3)),
                     rng.uniform(PROTOTYPE.rho_min, PROTOTYPE.rho_max, (4, 3)),
                     rng.uniform(40, PROTOTYPE.rho_max, (3, 3))])
    for k, r in enumerate(rho):
        try:
            direct(machine, r)
        except UnreachableError:
            rho[k] = 0.0
    return rho


@pytest.fixture(scope="module")
def world() -> dict:
    """90 machines (60 realistic, 30 far from nominal), each with its own layout, travel
    and installation errors, gauges zeroed at Zero one machine at a time, and 12 postures
    per machine."""
    rng = np.random.default_rng(42)
    machines = [random_machine(rng, "realistic", design=PROTOTYPE) for _ in range(60)]
    machines += [far_machine(rng) for _ in range(15)]
    machines += [crashing_machine(rng) for _ in range(15)]
    gauge_sets = []
    for m in machines:
        layout = random_layout(rng)
        gauges = install(layout, m, travel=float(rng.uniform(4, 20)),
                         preset=PRESETS["realistic"], rng=rng)
        t0 = exact_ray_distances(m, gauges, np.zeros(3))
        # A random layout can aim a gauge where its ray is blocked at Zero: such a gauge
        # cannot be set up, so it is re-zeroed on a fictitious distance (its rows still
        # test the model: it reads something else at every posture).
        gauge_sets.append(zero_gauges(gauges, np.nan_to_num(t0, nan=gauges[0].travel / 2)))
    rho = np.stack([reachable_postures(m, rng) for m in machines])
    return {"machines": machines, "gauges": gauge_sets, "rho": rho,
            "batch": MachineParams.stack(machines), "array": GaugeArray.stack(gauge_sets)}


def test_ray_distances_status_and_readings_are_the_per_machine_ones(world: dict) -> None:
    t = exact_ray_distances(world["batch"], world["array"], world["rho"])
    status = status_of(world["array"], t)
    readings = readings_from_distances(world["array"], t)
    assert t.shape == status.shape == (len(world["machines"]), POSTURES, GAUGES)
    for k, (machine, gauges) in enumerate(zip(world["machines"], world["gauges"], strict=True)):
        one = exact_ray_distances(machine, gauges, world["rho"][k])
        np.testing.assert_array_equal(t[k], one)
        np.testing.assert_array_equal(status[k], status_of(gauges, one))
        np.testing.assert_array_equal(readings[k], readings_from_distances(gauges, one))
    # The sample exercises every outcome of a reading, each many times.
    counts = np.bincount(status.ravel(), minlength=len(Status))
    assert counts.min() >= 50, dict(zip([s.name for s in Status], counts, strict=True))


def test_overtravel_and_collision_flags_are_the_per_machine_ones(world: dict) -> None:
    batch, rho = world["batch"], world["rho"]
    boxes = collision_boxes(batch, rho, direct(batch, rho))
    pressed = pressed_past_travel(world["array"], *exact_target_boxes(world["array"], boxes))
    crashed = collision_mask(batch, rho)
    gaps = pair_gaps(batch, rho)
    assert crashed.shape == gaps.shape == (len(world["machines"]), POSTURES, len(PAIR_NAMES))
    for k, (machine, gauges) in enumerate(zip(world["machines"], world["gauges"], strict=True)):
        own = collision_boxes(machine, rho[k], direct(machine, rho[k]))
        np.testing.assert_array_equal(
            pressed[k], pressed_past_travel(gauges, *exact_target_boxes(gauges, own)))
        np.testing.assert_array_equal(crashed[k], collision_mask(machine, rho[k]))
        np.testing.assert_array_equal(gaps[k], pair_gaps(machine, rho[k]))
        for p in range(POSTURES):
            assert collisions(machine, rho[k, p]) == list(np.array(PAIR_NAMES)[crashed[k, p]])
    assert 100 <= pressed.sum() <= pressed.size - 100
    assert crashed.any(axis=-1).sum() >= 20


def test_a_set_of_bars_alone_boxes_them_as_a_set_with_every_part(world: dict) -> None:
    # Gauges all on bars skip the carriages' and the platform's boxes: each array the
    # same numbers, shape and layout as the bars' rows of a set that also holds a
    # carriage and a platform gauge (where every part's box is made and selected).
    batch, rho = world["batch"], world["rho"]
    bars = [GaugeSpec(leg, axis, at) for leg, axis, at in
            ((0, 1, 0.5), (0, 2, 0.3), (1, 0, 0.7), (1, 2, 0.5), (2, 0, 0.5), (2, 1, 0.9))]
    mixed = [*bars, GaugeSpec.carriage(0, 1), GaugeSpec.platform(2)]
    assert {s.part for s in mixed} == {Part.BAR, Part.CARRIAGE, Part.PLATFORM}
    p = direct(batch, rho)
    for tcp in (p, p[:1]):  # every machine's TCP, or one broadcast to all
        alone = target_boxes(batch, spec_arrays(bars), rho, tcp)
        among = target_boxes(batch, spec_arrays(mixed), rho, tcp)
        for own, every, tail in zip(alone, among, (1, 2, 1), strict=True):
            rows = every[(..., slice(0, len(bars)), *(slice(None),) * tail)]
            assert own.shape == rows.shape and own.flags.c_contiguous
            np.testing.assert_array_equal(own, rows)


def test_the_bounding_box_cull_decides_as_the_separating_axis_test(world: dict) -> None:
    # collision_mask sends only pairs whose bounding boxes overlap through the
    # separating-axis test; pair_gaps runs it on every pair.
    batch, rho = world["batch"], world["rho"]
    np.testing.assert_array_equal(collision_mask(batch, rho), pair_gaps(batch, rho) <= 0.0)


def test_batched_exact_machine_is_its_machines_one_by_one(world: dict) -> None:
    rho = world["rho"][:, 3]
    batch = ExactMachine(world["batch"], world["array"], rho)
    for k, (machine, gauges) in enumerate(zip(world["machines"], world["gauges"], strict=True)):
        one = ExactMachine(machine, gauges, rho[k])
        np.testing.assert_array_equal(batch.tcp()[k], one.tcp())
        np.testing.assert_array_equal(batch.encoders()[k], one.encoders())
        np.testing.assert_array_equal(batch.gauge_distances()[k], one.gauge_distances())
        np.testing.assert_array_equal(batch.collision_mask()[k], one.collision_mask())
        for part, own in zip(batch.target_boxes(), one.target_boxes(), strict=True):
            np.testing.assert_array_equal(part[k], own)


def test_installing_and_zeroing_a_batch_is_each_machine_alone() -> None:
    rng = np.random.default_rng(7)
    machines = [random_machine(rng, "realistic", design=PROTOTYPE) for _ in range(20)]
    layout = random_layout(rng)
    preset = PRESETS["realistic"]
    streams = [np.random.default_rng(s) for s in range(20)]
    errors = np.stack([installation_errors(GAUGES, preset, r) for r in streams])
    batch = install_array(layout, MachineParams.stack(machines), travel=8.0, errors=errors)
    streams = [np.random.default_rng(s) for s in range(20)]
    singles = [install(layout, m, travel=8.0, preset=preset, rng=r)
               for m, r in zip(machines, streams, strict=True)]
    zeroed = batch.zeroed(exact_ray_distances(MachineParams.stack(machines), batch, np.zeros(3)))
    for k, (machine, gauges) in enumerate(zip(machines, singles, strict=True)):
        assert _same(batch[k], GaugeArray.of(gauges))
        own = zero_gauges(gauges, exact_ray_distances(machine, gauges, np.zeros(3)))
        assert _same(zeroed[k], GaugeArray.of(own))


def test_a_gauge_array_converts_back_to_its_gauges(world: dict) -> None:
    gauges = world["gauges"][3]
    again = GaugeArray.of(gauges).to_gauges()
    assert [g.spec for g in again] == [g.spec for g in gauges]
    for a, b in zip(again, gauges, strict=True):
        np.testing.assert_array_equal(a.origin, b.origin)
        assert (a.sign, a.travel, a.zero) == (b.sign, b.travel, b.zero)
    array = world["array"]
    assert array.batch_shape == (len(world["machines"]),) and array.count == GAUGES
    swapped = array.with_rows(np.array([0, 5]), array[[5, 0]])
    assert _same(swapped[0], array[5]) and _same(swapped[5], array[0])
    assert _same(swapped[1], array[1])


def test_zeroing_names_the_machine_and_gauge_that_miss() -> None:
    machines = MachineParams.stack([MachineParams(), MachineParams()])
    gauges = install_array([GaugeSpec(0, 1), GaugeSpec(2, 0)], machines)
    t = np.array([[1.0, 2.0], [np.nan, 3.0]])
    with pytest.raises(ValueError, match=r"machine 1: x-leg/y.* do not touch"):
        gauges.zeroed(t)


def _same(a: GaugeArray, b: GaugeArray) -> bool:
    """Bitwise equality of two gauge sets."""
    return all(np.array_equal(getattr(a, name), getattr(b, name))
               for name in ("origin", "direction", "sign", "travel", "zero", "leg", "axis",
                            "at"))


@pytest.mark.parametrize("n", [6, 10, 20, 50, 200])
def test_the_median_interval_covers_at_its_level_and_no_wider(n: int) -> None:
    """The interval's order statistics k, n-1-k cover the median with probability
    1 - 2 P(B <= k), B ~ binomial(n, 1/2), whatever the distribution: at least 95 %, and
    the next narrower pair would fall below it.  Checked on the ranks (any continuous
    distribution maps onto them)."""
    from scipy import stats

    from calibrators.study.statistics import median_interval

    low, high = median_interval(np.arange(n))
    k = int(low)
    assert high == n - 1 - k
    assert 1 - 2 * stats.binom.cdf(k, n, 0.5) >= 0.95
    assert 1 - 2 * stats.binom.cdf(k + 1, n, 0.5) < 0.95


def test_too_few_values_bound_no_median() -> None:
    from calibrators.study.statistics import median_interval

    with pytest.raises(ValueError, match="5 values cannot bound a median at 95%"):
        median_interval(np.arange(5))
