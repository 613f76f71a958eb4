"""Moved to :mod:`calibrators.workflow.session`;
this path stays so that earlier scripts' imports work
(it is that module, not a copy)."""

import sys

from calibrators.workflow import session

sys.modules[__name__] = session
