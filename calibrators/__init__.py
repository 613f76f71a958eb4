"""Calibration strategies."""
