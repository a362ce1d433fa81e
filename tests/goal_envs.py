"""Small goal-conditioned environments for tests, registered on import (``tests.goal_envs:Id``).

A point on a plane moves by a tenth of its action per step toward a goal; success is being
within 0.1 of it. By default episodes run to the time limit and say so by a ``compute_terminated``
that answers False, as Gymnasium-Robotics' Fetch tasks do. Variants: one whose episodes end at a
fixed step whatever the goal (a failure, not the goal: refused), one that does not report
``info["is_success"]``, one whose goal lies farther than half an episode can travel (so that a
two-segment agent succeeds only when its first sub-goal leads toward the goal), and tasks from
other suites' mould: ended on reaching the goal with 0/1 rewards and a ``compute_terminated``
(as Gymnasium-Robotics' mazes with ``continuing_task=False``), ended on success without one
(-1/0 rewards), a dense reward, and success reported as ``info["success"]``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


class PointGoalEnv(gym.Env):
    """A point moved toward a goal; goal-conditioned as Gymnasium-Robotics' tasks are."""

    def __init__(
        self,
        terminate_at: int | None = None,
        report_success: bool = True,
        goal_distance: tuple[float, float] | None = None,
        end_on_success: bool = False,
        define_terminated: bool = True,
        reward_type: str = "minus_one",
        success_key: str = "is_success",
    ) -> None:
        box = gym.spaces.Box(-5.0, 5.0, (2,), dtype=np.float64)
        self.observation_space = gym.spaces.Dict(
            {"observation": box, "achieved_goal": box, "desired_goal": box}
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.terminate_at = terminate_at
        self.report_success = report_success
        self.goal_distance = goal_distance
        self.end_on_success = end_on_success
        self.define_terminated = define_terminated
        self.reward_type = reward_type
        self.success_key = success_key
        self.position = np.zeros(2)
        self.goal = np.zeros(2)
        self.steps = 0

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        distance = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        if self.reward_type == "zero_one":
            return (distance <= 0.1).astype(np.float32)
        if self.reward_type == "dense":
            return -distance.astype(np.float32)
        return -(distance > 0.1).astype(np.float32)

    def compute_terminated(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any
    ) -> np.ndarray:
        if not self.define_terminated:  # as Gymnasium-Robotics' GoalEnv declares it, without a body
            raise NotImplementedError
        distance = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        return (distance <= 0.1) & self.end_on_success

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self.position = self.np_random.uniform(-0.5, 0.5, 2)
        if self.goal_distance is None:
            self.goal = self.np_random.uniform(-0.5, 0.5, 2)
        else:
            angle = self.np_random.uniform(0.0, 2.0 * np.pi)
            distance = self.np_random.uniform(*self.goal_distance)
            self.goal = self.position + distance * np.array([np.cos(angle), np.sin(angle)])
        self.steps = 0
        return self._observation(), {}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        # At most 0.1 per step in any direction.
        action = np.asarray(action, dtype=np.float64)
        self.position = self.position + 0.1 * action / max(1.0, float(np.linalg.norm(action)))
        self.steps += 1
        reward = float(self.compute_reward(self.position, self.goal, None))
        success = bool(np.linalg.norm(self.position - self.goal) <= 0.1)
        terminated = self.terminate_at is not None and self.steps >= self.terminate_at
        terminated = terminated or (self.end_on_success and success)
        info = {self.success_key: float(success)} if self.report_success else {}
        return self._observation(), reward, terminated, False, info

    def _observation(self) -> dict[str, np.ndarray]:
        return {
            "observation": self.position.copy(),
            "achieved_goal": self.position.copy(),
            "desired_goal": self.goal.copy(),
        }


gym.register("PointGoal-v0", entry_point=PointGoalEnv, max_episode_steps=10)
gym.register(
    "PointGoalTerminating-v0", entry_point=PointGoalEnv, max_episode_steps=10, kwargs={"terminate_at": 4}
)
gym.register(
    "PointGoalNoSuccess-v0", entry_point=PointGoalEnv, max_episode_steps=10, kwargs={"report_success": False}
)
gym.register(
    "PointGoalFar-v0", entry_point=PointGoalEnv, max_episode_steps=10, kwargs={"goal_distance": (0.7, 0.9)}
)
gym.register(
    "PointGoalEndsOnSuccess-v0",
    entry_point=PointGoalEnv,
    max_episode_steps=20,
    kwargs={"end_on_success": True, "reward_type": "zero_one", "success_key": "success"},
)
gym.register(
    "PointGoalEndsUndeclared-v0",
    entry_point=PointGoalEnv,
    max_episode_steps=20,
    kwargs={"end_on_success": True, "define_terminated": False},
)
gym.register(
    "PointGoalDense-v0", entry_point=PointGoalEnv, max_episode_steps=10, kwargs={"reward_type": "dense"}
)
gym.register(
    "PointGoalUndeclared-v0",
    entry_point=PointGoalEnv,
    max_episode_steps=10,
    kwargs={"define_terminated": False},
)
