"""Virtual Orthoglide: geometry, kinematics, PyBullet machine, gauges and Gymnasium env.

Importing the package registers ``OrthoglideCalibration-v0`` with Gymnasium.
"""

import gymnasium

ENV_ID = "OrthoglideCalibration-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="orthoglide_env.env:OrthoglideCalibrationEnv",
        max_episode_steps=500,
    )

__all__ = ["ENV_ID"]
