"""The Gymnasium faces of the lab."""
