"""Virtual Orthoglide: geometry, kinematics, PyBullet machine, gauges and Gymnasium envs.

Importing the package registers ``OrthoglideCalibration-v0`` (move and read), with a native
vector env (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point",
backend="exact")``, :mod:`orthoglide_env.envs.calibration_vector`), and
``OrthoglideLab-v0`` (the whole
lab: gauge handling, stands, tracker, a clock), with a native vector env too
(:mod:`orthoglide_env.envs.lab_vector`), with Gymnasium.  :class:`MachineDesign`
describes a machine's nominal dimensions (the prototype's by default).
"""

import gymnasium

from orthoglide_env.model.design import MachineDesign

ENV_ID = "OrthoglideCalibration-v0"
LAB_ENV_ID = "OrthoglideLab-v0"
FLAT_LAB_ENV_ID = "OrthoglideLabFlat-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID, entry_point="orthoglide_env.envs.calibration:OrthoglideCalibrationEnv",
        vector_entry_point="orthoglide_env.envs.calibration_vector:OrthoglideCalibrationVectorEnv",
        max_episode_steps=500)
if LAB_ENV_ID not in gymnasium.registry:
    # No step limit: an episode ends on the agent's stop or the lab's time budget.
    gymnasium.register(id=LAB_ENV_ID, entry_point="orthoglide_env.envs.lab:OrthoglideLabEnv",
                       vector_entry_point="orthoglide_env.envs.lab_vector:OrthoglideLabVectorEnv")
if FLAT_LAB_ENV_ID not in gymnasium.registry:
    # The lab with one Box of actions and one of observations, for off-the-shelf learners.
    gymnasium.register(id=FLAT_LAB_ENV_ID, entry_point="orthoglide_env.envs.wrappers:flat_lab_env")

__all__ = ["ENV_ID", "FLAT_LAB_ENV_ID", "LAB_ENV_ID", "MachineDesign"]
