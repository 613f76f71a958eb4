"""Moved to :mod:`calibrators.workflow.verify`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.workflow import verify

sys.modules[__name__] = verify
