"""Small goal-conditioned environments for tests, registered on import (``tests.goal_envs:Id``).

A point on a plane moves by a tenth of its action per step toward a goal; success is being
within 0.1 of it. Variants: one whose episodes end early (terminated), one that does not
report ``info["is_success"]``, and one whose goal lies farther than half an episode can travel,
so that a two-segment agent succeeds only when its first sub-goal leads toward the goal.
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
    ) -> None:
        box = gym.spaces.Box(-5.0, 5.0, (2,), dtype=np.float64)
        self.observation_space = gym.spaces.Dict(
            {"observation": box, "achieved_goal": box, "desired_goal": box}
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.terminate_at = terminate_at
        self.report_success = report_success
        self.goal_distance = goal_distance
        self.position = np.zeros(2)
        self.goal = np.zeros(2)
        self.steps = 0

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        distance = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        return -(distance > 0.1).astype(np.float32)

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
        terminated = self.terminate_at is not None and self.steps >= self.terminate_at
        info = {"is_success": float(reward == 0.0)} if self.report_success else {}
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
