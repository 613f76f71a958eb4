"""Moved to :mod:`calibrators.planning.slot_table`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.planning import slot_table

sys.modules[__name__] = slot_table
