"""Moved to :mod:`calibrators.study.engines`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.study import engines

sys.modules[__name__] = engines
