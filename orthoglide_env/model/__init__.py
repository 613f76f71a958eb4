"""The machine's model: nominal design, geometric errors, exact kinematics, collisions."""
