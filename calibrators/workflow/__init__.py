"""The real-machine workflow, one module per command: plan, session, fit, compensate,
verify."""
