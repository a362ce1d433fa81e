"""The indexed joint reads give the environments' observations exactly."""

import gymnasium as gym
import numpy as np
import pytest

from dtd.envs.joint_reads import IndexedJointReads
from dtd.envs.make import make_env, register_robotics_envs


@pytest.mark.parametrize("env_id", ["FetchPush-v4", "FetchPickAndPlace-v4", "HandManipulateBlock-v1"])
def test_observations_are_the_librarys_own(env_id):
    register_robotics_envs()
    ours, theirs = make_env(env_id), gym.make(env_id, disable_env_checker=True)
    assert isinstance(ours.unwrapped._utils, IndexedJointReads)
    assert not isinstance(theirs.unwrapped._utils, IndexedJointReads)
    rng = np.random.default_rng(0)
    for episode in range(2):
        first_ours, _ = ours.reset(seed=episode)
        first_theirs, _ = theirs.reset(seed=episode)
        for key in first_ours:
            assert np.array_equal(first_ours[key], first_theirs[key])
        for _ in range(30):
            action = rng.uniform(-1, 1, size=ours.action_space.shape).astype(np.float32)
            step_ours, step_theirs = ours.step(action), theirs.step(action)
            for key in step_ours[0]:
                assert step_ours[0][key].dtype == step_theirs[0][key].dtype
                assert np.array_equal(step_ours[0][key], step_theirs[0][key]), key
            assert step_ours[1:4] == step_theirs[1:4]
