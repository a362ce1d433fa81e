"""The task's verdicts on goals: the reward measured sparse or dense, where episodes end, the
return bounds that follow, and constructor arguments read from the command line."""

from __future__ import annotations

import numpy as np
import pytest

import tests.goal_envs  # noqa: F401  (registers the test tasks)
from dtd.envs.goals import return_bounds, success_of
from dtd.envs.make import env_kwargs, make_envs
from dtd.envs.spec import goal_functions
from dtd.errors import EnvError


def spec_and_goals(name: str):
    envs, spec = make_envs(f"tests.goal_envs:{name}", 1)
    return spec, goal_functions(envs[0], spec)


@pytest.mark.parametrize(
    ("name", "sparse", "ends"),
    [
        ("PointGoal-v0", (-1.0, 0.0), False),  # compute_terminated answers False: runs on
        ("PointGoalEndsOnSuccess-v0", (0.0, 1.0), True),  # 0/1, compute_terminated
        ("PointGoalEndsUndeclared-v0", (-1.0, 0.0), True),  # no compute_terminated: success ends
        ("PointGoalDense-v0", None, False),
    ],
)
def test_the_reward_and_the_episode_end_are_read_from_the_task(name, sparse, ends):
    spec, _ = spec_and_goals(name)
    assert spec.sparse_rewards == sparse and spec.ends_on_goal is ends


def test_verdicts_are_batched_and_per_goal():
    near, far = np.array([[0.0, 0.0], [0.0, 0.0]]), np.array([[0.05, 0.0], [1.0, 0.0]])
    _, goals = spec_and_goals("PointGoalEndsOnSuccess-v0")
    assert goals.reward(near, far).tolist() == [1.0, 0.0]
    assert goals.reached(near, far).tolist() == [True, False]
    assert goals.terminal(near, far).tolist() == [True, False]
    _, running = spec_and_goals("PointGoal-v0")
    assert running.terminal is None and running.reached(near, far).tolist() == [True, False]
    _, dense = spec_and_goals("PointGoalDense-v0")
    assert dense.terminal is None and dense.reached is None


def test_a_compute_terminated_that_answers_once_for_a_batch_is_asked_row_by_row():
    # As Gymnasium-Robotics' mazes: one bool for the whole batch.
    envs, spec = make_envs("PointMaze_UMaze-v3", 1, {"continuing_task": False})
    goals = goal_functions(envs[0], spec)
    achieved = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0]])
    goal = np.array([[0.1, 0.0], [2.0, 0.0], [1.0, 1.3]])
    assert goals.terminal(achieved, goal).tolist() == [True, False, True]
    envs[0].close()


def test_return_bounds_follow_the_sparse_rewards():
    assert return_bounds((-1.0, 0.0), 0.98) == pytest.approx((-50.0, 0.0))
    assert return_bounds((0.0, 1.0), 0.9) == pytest.approx((0.0, 10.0))
    assert return_bounds(None, 0.98) is None and return_bounds((-1.0, 0.0), 1.0) is None


def test_success_is_read_under_either_key():
    assert success_of({"is_success": 1.0}) == 1.0 and success_of({"success": True}) == 1.0
    assert success_of({}) == 0.0


def test_env_kwargs_read_json_python_and_text():
    assert env_kwargs(["continuing_task=False", "reward_type=dense", "max_episode_steps=100"]) == {
        "continuing_task": False,
        "reward_type": "dense",
        "max_episode_steps": 100,
    }
    assert env_kwargs(['maze_map=[[1, "g"], [0, 1]]', "flag=true", "none=None"]) == {
        "maze_map": [[1, "g"], [0, 1]],
        "flag": True,
        "none": None,
    }
    for bad in ["novalue", "=3", "two words=1"]:
        with pytest.raises(EnvError, match="KEY=VALUE"):
            env_kwargs([bad])
