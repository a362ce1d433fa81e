"""Episodes that end before the time limit: lengths, padding, success where they ended, and
ends the task's verdict does not explain refused."""

from __future__ import annotations

import numpy as np
import pytest

import tests.goal_envs  # noqa: F401  (registers the test tasks)
from dtd.envs.make import make_envs
from dtd.errors import EnvError
from dtd.explain.render import key_frames
from dtd.training.rollout import run_episodes


class StraightToTheGoal:
    """Steps toward the goal at full speed, or stands still (``still``)."""

    def __init__(self, still: bool = False) -> None:
        self.still = still

    def step_goal(self, obs, achieved_goal, desired_goal, t, explore, rng):
        return desired_goal

    def act(self, obs, goal, explore, rng):
        if self.still:
            return np.zeros_like(goal)
        direction = goal - obs
        return direction / np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-9) * 0.99


def test_episodes_end_where_the_goal_is_reached_and_are_padded_with_their_end():
    envs, spec = make_envs("tests.goal_envs:PointGoalEndsOnSuccess-v0", 3)
    for seed, env in enumerate(envs):
        env.reset(seed=seed)
    seen: list[int] = []
    episodes = run_episodes(
        envs, StraightToTheGoal(), spec, False, np.random.default_rng(0), lambda t, g: seen.append(t)
    )
    length = episodes.length
    assert np.all(length < spec.horizon) and np.all(episodes.success == 1.0)
    assert seen == list(range(int(length.max()) + 1))  # every state, then the last once more
    for i, end in enumerate(length):
        # The goal reached at the last step; past it, the end repeated and no action.
        assert np.linalg.norm(episodes.achieved_goal[i, end] - episodes.desired_goal[i]) <= 0.1
        assert np.linalg.norm(episodes.achieved_goal[i, end - 1] - episodes.desired_goal[i]) > 0.1
        assert np.all(episodes.obs[i, end:] == episodes.obs[i, end])
        assert np.all(episodes.achieved_goal[i, end:] == episodes.achieved_goal[i, end])
        assert np.all(episodes.action[i, end:] == 0.0) and np.any(episodes.action[i, :end] != 0.0)
    assert np.allclose(
        episodes.final_distance(),
        np.linalg.norm(episodes.achieved_goal[np.arange(3), length] - episodes.desired_goal, axis=-1),
    )


def test_an_episode_that_never_reaches_its_goal_runs_to_the_limit():
    envs, spec = make_envs("tests.goal_envs:PointGoalEndsOnSuccess-v0", 2)
    for seed, env in enumerate(envs):
        env.reset(seed=seed)
    episodes = run_episodes(envs, StraightToTheGoal(still=True), spec, False, np.random.default_rng(0))
    assert episodes.length.tolist() == [spec.horizon] * 2 and np.all(episodes.success == 0.0)


def test_an_end_that_is_not_the_goal_is_refused():
    envs, spec = make_envs("tests.goal_envs:PointGoalTerminating-v0", 1)
    with pytest.raises(EnvError, match="ended an episode at step 4 of 10 for another reason"):
        run_episodes(envs, StraightToTheGoal(still=True), spec, False, np.random.default_rng(0))


def test_key_frames_stop_at_the_episodes_end():
    bounds = np.array([0, 10, 20])
    assert key_frames(20, bounds, True)[-1][0] == 20
    # Ended at step 7, inside the first segment: no frame for a segment it never began.
    frames = key_frames(7, bounds, True)
    assert [frame for frame, _ in frames] == [0, 7]
