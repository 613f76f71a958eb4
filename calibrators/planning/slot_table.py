"""Moved to :mod:`orthoglide_env.lab.slot_table` (the lab's candidate operations, which the
env's design wrappers offer as actions); this path stays so that earlier scripts' imports
work (it is that module, not a copy)."""

import sys

from orthoglide_env.lab import slot_table

sys.modules[__name__] = slot_table
