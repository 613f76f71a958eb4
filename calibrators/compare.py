"""Moved to :mod:`calibrators.study.compare`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.study import compare

sys.modules[__name__] = compare
