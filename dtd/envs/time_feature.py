"""The fraction of the episode left, 1 - t/T, as the observation's last entry: what a policy and
its critic need to tell a state early in an episode from the same state near its time limit."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from dtd.errors import EnvError


class TimeFeature(gym.Wrapper):
    """Appends 1 - t/T to ``observation`` (1 at reset, 0 at the time limit T), as RL Zoo's
    TimeFeatureWrapper does for the Fetch tasks; goals are left as they are."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        horizon = env.spec.max_episode_steps if env.spec is not None else None
        if not horizon:
            raise EnvError("--time-feature needs a time limit (max_episode_steps) on the environment")
        self.horizon = int(horizon)
        self.steps = 0
        space = env.observation_space["observation"]
        low = np.append(np.broadcast_to(space.low, space.shape).ravel(), 0.0)
        high = np.append(np.broadcast_to(space.high, space.shape).ravel(), 1.0)
        self.observation_space = gym.spaces.Dict(
            {**env.observation_space.spaces, "observation": gym.spaces.Box(low, high, dtype=space.dtype)}
        )

    def time_left(self) -> float:
        """The fraction of the episode left now."""
        return 1.0 - self.steps / self.horizon

    def observe(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``observation`` with the time left appended to its ``observation``."""
        return {
            **observation,
            "observation": np.append(np.ravel(observation["observation"]), self.time_left()),
        }

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self.steps = 0
        return self.observe(observation), info

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        return self.observe(observation), reward, terminated, truncated, info


def as_observed(env: gym.Env, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """An observation read from the simulator (e.g. after placing a block), as ``env`` shows
    it: with the time left appended where ``env`` has a time feature."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, TimeFeature):
            return env.observe(observation)
        env = env.env
    return observation
