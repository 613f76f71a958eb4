"""Moved to :mod:`calibrators.workflow.compensate`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.workflow import compensate

sys.modules[__name__] = compensate
