"""Virtual Orthoglide: geometry, kinematics, PyBullet machine, gauges and Gymnasium env.

Importing the package registers ``OrthoglideCalibration-v0`` with Gymnasium, with a native
vector env (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point",
backend="exact")``, :mod:`orthoglide_env.vector`).
"""

import gymnasium

ENV_ID = "OrthoglideCalibration-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="orthoglide_env.env:OrthoglideCalibrationEnv",
        vector_entry_point="orthoglide_env.vector:OrthoglideCalibrationVectorEnv",
        max_episode_steps=500,
    )

__all__ = ["ENV_ID"]
