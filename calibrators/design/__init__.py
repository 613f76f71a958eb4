"""Moved to :mod:`calibrators.planning` (experiment planning on the linearised model);
its modules' old paths stay so that earlier scripts' imports work."""
