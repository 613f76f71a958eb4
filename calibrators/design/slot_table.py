"""Moved to :mod:`orthoglide_env.lab.slot_table`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from orthoglide_env.lab import slot_table

sys.modules[__name__] = slot_table
