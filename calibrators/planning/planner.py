"""The planner's public names in one place, for earlier scripts: the planner now lives in
:mod:`calibrators.planning.belief` (what an experiment knows), :mod:`~calibrators.planning.
pricing` (what each move costs and gains) and :mod:`~calibrators.planning.search` (the
greedy choice).  ``Step`` and ``Options`` are the earlier names of
:class:`PlannedOperation` and :class:`PricedMoves`."""

from calibrators.planning.belief import (
    CRITERIA,
    N_MACHINE,
    N_STAND,
    SPREAD_SLACK,
    ZERO_SCALE,
    Belief,
    PlannedOperation,
    rigid_factor,
    rigid_weight,
)
from calibrators.planning.pricing import (
    BOUND_SLACK,
    FIRST_PRICED,
    WORLD_SHORTLIST,
    Options,
    PricedMoves,
    Pricer,
)
from calibrators.planning.search import (
    LOOKAHEAD_MOVES,
    REMOUNT_CHECK_S,
    SCREENED,
    Planner,
    greedy_plan,
)

#: The earlier name of :class:`PlannedOperation` (not the procedure's
#: :class:`calibrators.workflow.plan.Step`).
Step = PlannedOperation

__all__ = [
    "BOUND_SLACK", "CRITERIA", "FIRST_PRICED", "LOOKAHEAD_MOVES", "N_MACHINE", "N_STAND",
    "REMOUNT_CHECK_S", "SCREENED", "SPREAD_SLACK", "WORLD_SHORTLIST", "ZERO_SCALE", "Belief",
    "Options", "PlannedOperation", "Planner", "PricedMoves", "Pricer", "Step", "greedy_plan",
    "rigid_factor", "rigid_weight",
]
