"""Moved to :mod:`orthoglide_env.wrappers` (the public wrappers' module); this path stays so
that earlier scripts' imports work (it is that module, not a copy)."""

import sys

from orthoglide_env import wrappers

sys.modules[__name__] = wrappers
