"""The time feature: the fraction of the episode left appended to the observation."""

import gymnasium as gym
import numpy as np
import pytest

import tests.goal_envs  # noqa: F401  (registers the test environments)
from dtd.envs.make import make_envs
from dtd.envs.time_feature import TimeFeature, as_observed
from dtd.errors import EnvError


def test_the_time_left_runs_from_one_at_reset_to_zero_at_the_time_limit():
    (env,), spec = make_envs("tests.goal_envs:PointGoal-v0", 1, time_feature=True)
    assert spec.obs_dim == 3 and env.observation_space["observation"].shape == (3,)
    observation, _ = env.reset(seed=0)
    seen = [observation["observation"][-1]]
    truncated = False
    while not truncated:
        observation, _, _, truncated, _ = env.step(np.zeros(2, np.float32))
        seen.append(observation["observation"][-1])
    np.testing.assert_allclose(seen, np.linspace(1.0, 0.0, 11))
    # The rest of the observation and the goals are the task's own.
    np.testing.assert_array_equal(observation["observation"][:2], observation["achieved_goal"])
    assert observation["desired_goal"].shape == (2,)
    assert env.observation_space["observation"].contains(observation["observation"])


def test_an_observation_read_from_the_simulator_gets_the_time_left_where_the_env_has_it():
    (env,), _ = make_envs("tests.goal_envs:PointGoal-v0", 1, time_feature=True)
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))
    raw = {"observation": np.zeros(2), "achieved_goal": np.zeros(2), "desired_goal": np.zeros(2)}
    assert as_observed(gym.wrappers.RecordEpisodeStatistics(env), raw)["observation"][-1] == pytest.approx(
        0.9
    )
    (plain,), _ = make_envs("tests.goal_envs:PointGoal-v0", 1)
    assert as_observed(plain, raw) is raw


def test_a_task_without_a_time_limit_is_refused():
    env = gym.make("tests.goal_envs:PointGoal-v0", max_episode_steps=None, disable_env_checker=True)
    env.spec.max_episode_steps = None  # as a task registered without one
    with pytest.raises(EnvError, match="time limit"):
        TimeFeature(env)
