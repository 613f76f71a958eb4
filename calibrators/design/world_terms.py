"""Moved to :mod:`calibrators.planning.world_terms`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.planning import world_terms

sys.modules[__name__] = world_terms
