"""Moved to :mod:`calibrators.planning.planner`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.planning import planner

sys.modules[__name__] = planner
