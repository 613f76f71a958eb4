"""Estimators: what is fitted to an experiment's readings (model, parameter set, solver)."""
