"""Estimators: what is fitted to an experiment's readings (model, parameter set, solver).

``get_estimator(NAME, **config)`` hands out a named estimator of the catalogue
(:mod:`calibrators.estimators.catalogue`), configured; its ``fit(measurements)`` returns
an :class:`~calibrators.estimators.base.Estimate`.
"""

from calibrators.estimators.base import Estimate, Estimator
from calibrators.estimators.catalogue import CATALOGUE, get_estimator

__all__ = ["CATALOGUE", "Estimate", "Estimator", "get_estimator"]
