"""Virtual Orthoglide: geometry, kinematics, PyBullet machine, gauges and Gymnasium envs.

Importing the package registers ``OrthoglideCalibration-v0`` (move and read), with a native
vector env (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point",
backend="exact")``, :mod:`orthoglide_env.envs.calibration_vector`), and
``OrthoglideLab-v0`` (the whole
lab: gauge handling, stands, tracker, a clock), with a native vector env too
(:mod:`orthoglide_env.envs.lab_vector`), with Gymnasium.  :class:`MachineDesign`
describes a machine's nominal dimensions (the prototype's by default).

The package itself imports neither Gymnasium nor SciPy nor PyBullet: the model, the
instruments and the command line's ``--help`` start in the time NumPy takes.  The envs
are registered the moment Gymnasium is imported (at once when it already is), so
``import orthoglide_env`` then ``gymnasium.make(...)`` works in either import order.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
import warnings
from types import ModuleType

from orthoglide_env.model.design import MachineDesign

ENV_ID = "OrthoglideCalibration-v0"
LAB_ENV_ID = "OrthoglideLab-v0"
#: The lab whose spaces carry the interferometer (its ``align`` operation and reading).
LAB_V1_ENV_ID = "OrthoglideLab-v1"
#: The lab whose spaces also carry the ballbar (its ``pivot`` operation and reading).
LAB_V2_ENV_ID = "OrthoglideLab-v2"
#: The lab whose spaces also carry the step gauge (its ``place`` operation and reading).
LAB_V3_ENV_ID = "OrthoglideLab-v3"
#: The lab whose moves choose whether to read the interferometer (the action's ``laser``).
LAB_V4_ENV_ID = "OrthoglideLab-v4"
FLAT_LAB_ENV_ID = "OrthoglideLabFlat-v0"
DESIGN_LAB_ENV_ID = "OrthoglideLabDesign-v0"
#: The design view whose observation also tells how the present posture has been read.
DESIGN_LAB_V1_ENV_ID = "OrthoglideLabDesign-v1"
#: The design view that observes the readings taken at every posture instead of the
#: predicted error's spectrum.
DESIGN_LAB_V2_ENV_ID = "OrthoglideLabDesign-v2"


def _register(gymnasium: ModuleType) -> None:
    """Register the envs with ``gymnasium`` (once: a second call changes nothing)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(
            id=ENV_ID, entry_point="orthoglide_env.envs.calibration:OrthoglideCalibrationEnv",
            vector_entry_point=(
                "orthoglide_env.envs.calibration_vector:OrthoglideCalibrationVectorEnv"),
            max_episode_steps=500)
    if LAB_ENV_ID not in gymnasium.registry:
        # No step limit: an episode ends on the agent's stop or the lab's time budget.
        gymnasium.register(
            id=LAB_ENV_ID, entry_point="orthoglide_env.envs.lab:OrthoglideLabEnv",
            vector_entry_point="orthoglide_env.envs.lab_vector:OrthoglideLabVectorEnv")
    if LAB_V1_ENV_ID not in gymnasium.registry:
        # v1 adds the interferometer to v0's spaces; v0 is not out of date (it stays the
        # lab of every lab without one), so Gymnasium's note that a v1 exists is not said.
        warnings.filterwarnings("ignore", message=f".*{LAB_ENV_ID} is out of date")
        gymnasium.register(
            id=LAB_V1_ENV_ID, entry_point="orthoglide_env.envs.lab:OrthoglideLabV1Env",
            vector_entry_point="orthoglide_env.envs.lab_vector:OrthoglideLabV1VectorEnv")
    if LAB_V2_ENV_ID not in gymnasium.registry:
        # v2 adds the ballbar to v1's spaces; v1 stays the lab of a lab without one.
        warnings.filterwarnings("ignore", message=f".*{LAB_V1_ENV_ID} is out of date")
        gymnasium.register(
            id=LAB_V2_ENV_ID, entry_point="orthoglide_env.envs.lab:OrthoglideLabV2Env",
            vector_entry_point="orthoglide_env.envs.lab_vector:OrthoglideLabV2VectorEnv")
    if LAB_V3_ENV_ID not in gymnasium.registry:
        # v3 adds the step gauge to v2's spaces; v2 stays the lab of a lab without one.
        warnings.filterwarnings("ignore", message=f".*{LAB_V2_ENV_ID} is out of date")
        gymnasium.register(
            id=LAB_V3_ENV_ID, entry_point="orthoglide_env.envs.lab:OrthoglideLabV3Env",
            vector_entry_point="orthoglide_env.envs.lab_vector:OrthoglideLabV3VectorEnv")
    if LAB_V4_ENV_ID not in gymnasium.registry:
        # v4 lets a move leave the laser unread; v3 stays the lab of the step gauge alone.
        warnings.filterwarnings("ignore", message=f".*{LAB_V3_ENV_ID} is out of date")
        gymnasium.register(
            id=LAB_V4_ENV_ID, entry_point="orthoglide_env.envs.lab:OrthoglideLabV4Env",
            vector_entry_point="orthoglide_env.envs.lab_vector:OrthoglideLabV4VectorEnv")
    if FLAT_LAB_ENV_ID not in gymnasium.registry:
        # The lab with one Box of actions and one of observations, for off-the-shelf
        # learners.
        gymnasium.register(id=FLAT_LAB_ENV_ID,
                           entry_point="orthoglide_env.wrappers:flat_lab_env")
    if DESIGN_LAB_ENV_ID not in gymnasium.registry:
        # The lab as an experiment's design: the planner's candidate operations, masked.
        gymnasium.register(id=DESIGN_LAB_ENV_ID,
                           entry_point="orthoglide_env.wrappers:design_lab_env",
                           vector_entry_point="orthoglide_env.wrappers:DesignLabVector")
    # v1 adds the readings at the present posture to v0's observation, v2 observes the
    # readings' counts in place of v1's spectrum. Each older view stays what a shipped
    # policy plays, so Gymnasium's note that a newer version exists is not said.
    for version, (env_id, older) in {1: (DESIGN_LAB_V1_ENV_ID, DESIGN_LAB_ENV_ID),
                                     2: (DESIGN_LAB_V2_ENV_ID, DESIGN_LAB_V1_ENV_ID)}.items():
        if env_id not in gymnasium.registry:
            warnings.filterwarnings("ignore", message=f".*{older} is out of date")
            gymnasium.register(id=env_id, entry_point="orthoglide_env.wrappers:design_lab_env",
                               vector_entry_point="orthoglide_env.wrappers:DesignLabVector",
                               kwargs={"version": version})


class _RegisterOnImport(importlib.abc.MetaPathFinder):
    """Finds Gymnasium for the import system once, and registers the envs as soon as its
    module has run: Gymnasium has no plugin hook of its own (1.x), and importing it here
    would cost every user of the model a tenth of a second and a second package."""

    def find_spec(self, fullname: str, path: object = None, target: object = None
                  ) -> importlib.machinery.ModuleSpec | None:
        if fullname != "gymnasium":
            return None
        sys.meta_path.remove(self)  # the finders after this one find it, exactly once
        spec = importlib.util.find_spec(fullname)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module: ModuleType) -> None:
            run(module)
            _register(module)

        spec.loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


if "gymnasium" in sys.modules:
    _register(sys.modules["gymnasium"])
elif not any(isinstance(f, _RegisterOnImport) for f in sys.meta_path):
    sys.meta_path.insert(0, _RegisterOnImport())

__all__ = ["DESIGN_LAB_ENV_ID", "DESIGN_LAB_V1_ENV_ID", "DESIGN_LAB_V2_ENV_ID", "ENV_ID",
           "FLAT_LAB_ENV_ID", "LAB_ENV_ID", "LAB_V1_ENV_ID", "LAB_V2_ENV_ID", "LAB_V3_ENV_ID",
           "LAB_V4_ENV_ID", "MachineDesign"]
