"""Experiment design on the linearised model."""
