"""Moved to :mod:`calibrators.study.episodes`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.study import episodes

sys.modules[__name__] = episodes
