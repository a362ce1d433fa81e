"""A faster read of the robot's joints for Gymnasium-Robotics' MuJoCo environments.

Their observations start with ``mujoco_utils.robot_get_obs``, which looks every robot joint
up by name, one at a time, at every step: about a fifth of FetchPush's step time. The
environments call it through their ``_utils`` attribute; :func:`read_joints_by_index` puts
:class:`IndexedJointReads` there, which returns the same arrays from index arrays computed
once. Everything else is the library's own.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

_ONE_DIMENSIONAL = (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)


class IndexedJointReads:
    """Stands in for the ``mujoco_utils`` module inside one environment."""

    def __init__(self, utils: ModuleType) -> None:
        self._utils = utils
        self._indices: dict[int, tuple[np.ndarray, np.ndarray] | None] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._utils, name)

    def robot_get_obs(self, model: Any, data: Any, joint_names: Any) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities of the joints whose names start with ``robot``, as the
        library returns them."""
        key = id(joint_names)
        if key not in self._indices:
            self._indices[key] = _robot_joint_indices(model, data, joint_names)
        indices = self._indices[key]
        if indices is None:  # a case the index arrays do not reproduce exactly
            return self._utils.robot_get_obs(model, data, joint_names)
        qpos_index, qvel_index = indices
        return data.qpos[qpos_index], data.qvel[qvel_index]


def _robot_joint_indices(model: Any, data: Any, joint_names: Any) -> tuple[np.ndarray, np.ndarray] | None:
    if data.qpos is None or not joint_names:
        return None
    ids = [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        for name in joint_names
        if name.startswith("robot")
    ]
    # The library squeezes a stack of per-joint arrays: one value per joint gives a flat
    # vector, for two joints or more.
    if len(ids) < 2 or any(i < 0 or model.jnt_type[i] not in _ONE_DIMENSIONAL for i in ids):
        return None
    return np.array(model.jnt_qposadr[ids]), np.array(model.jnt_dofadr[ids])


def read_joints_by_index(env: gym.Env) -> None:
    """Give ``env`` the indexed joint reads if it is a Gymnasium-Robotics MuJoCo environment."""
    base = env.unwrapped
    utils = getattr(base, "_utils", None)
    if isinstance(utils, ModuleType) and callable(getattr(utils, "robot_get_obs", None)):
        base._utils = IndexedJointReads(utils)
