"""The real-machine workflow as a Python API, one module per command: plan, session, fit,
compensate, verify.

Each stage is staged as FIGAROH stages a calibration: configure, run, verify.

* **Configure**: a class takes every parameter at construction and checks it there
  (``ValueError`` naming the parameter, or the file it came from): :class:`plan.Plan`,
  :class:`session.Session`, :class:`fit.Fit`, :class:`compensate.Compensate`, and for the
  paper's third experiment :class:`verify.VerificationPlan` and :class:`verify.Verify`.
* **Run**: ``.run()`` makes the stage's result, a dataclass that carries itself as JSON
  (``to_dict()``, ``from_dict()``) and writes its files into a folder (``write(folder)``,
  the paths written): :class:`plan.Procedure` (``plan.json``, ``readings.csv``; its
  printable page is :func:`page.write_page`'s), :class:`fit.Calibration`
  (``estimate.json``), :class:`compensate.Controller` (joint offsets, tables,
  ``machine.json``, ``commands.csv``), :class:`verify.Verification`
  (``verification.json``).  A session's result is its readings, a
  :class:`~calibrators.measurements.Measurements` (``to_dict``/``from_dict``;
  :meth:`session.Session.write` puts it into a folder).
* **Verify**: the estimate is held against readings it was not fitted on
  (:mod:`~calibrators.workflow.verify`).

The ``orthoglide`` commands of the same names are argument tables over these classes.
The modules load on first use (``from calibrators import workflow; workflow.plan``), so
that importing the package costs nothing.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: The workflow's modules: its stages, the readings sheet's checks and the printable page.
MODULES: tuple[str, ...] = ("plan", "session", "fit", "compensate", "verify", "page")


def __getattr__(name: str) -> ModuleType:
    if name in MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = list(MODULES)
