"""Exploration around a deterministic policy: Gaussian noise and random actions."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class ActionNoise:
    """Gaussian noise of std ``noise_eps * action_max``, then with probability ``random_eps``
    a uniformly random action instead."""

    noise_eps: float
    random_eps: float
    action_max: float

    def __call__(self, action: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        noisy = action + self.noise_eps * self.action_max * rng.standard_normal(action.shape)
        noisy = np.clip(noisy, -self.action_max, self.action_max)
        random_action = rng.uniform(-self.action_max, self.action_max, size=action.shape)
        take_random = rng.random(action.shape[0]) < self.random_eps
        return np.where(take_random[:, None], random_action, noisy).astype(np.float32)
