"""The lab: its operations and time table, and the engine that runs them on arrays."""
