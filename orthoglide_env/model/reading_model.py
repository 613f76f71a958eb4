"""Moved to :mod:`orthoglide_env.reading_model`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from orthoglide_env import reading_model

sys.modules[__name__] = reading_model
