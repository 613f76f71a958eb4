"""Moved to :mod:`calibrators.workflow.plan`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.workflow import plan

sys.modules[__name__] = plan
