"""Typed records that travel between rollout, replay and learner."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Episodes(NamedTuple):
    """A batch of B whole episodes of at most T steps, as collected side by side.

    Episode b ran ``length[b]`` steps (T, or fewer where the task ended it sooner); past them
    its arrays are padding that repeats its last observation, achieved goal and goal (zero
    actions), so that index T is its end: padding is never sampled as experience.
    """

    obs: np.ndarray
    """(B, T+1, obs_dim) observations, the last one after the final step."""
    achieved_goal: np.ndarray
    """(B, T+1, goal_dim) achieved goals, aligned with ``obs``."""
    action: np.ndarray
    """(B, T, action_dim) actions taken."""
    step_goal: np.ndarray
    """(B, T, goal_dim) the goal the acting policy was given at each step."""
    desired_goal: np.ndarray
    """(B, goal_dim) the task's goal."""
    success: np.ndarray
    """(B,) the task's ``is_success`` at the step the episode ended, 0 or 1."""
    length: np.ndarray
    """(B,) steps each episode ran, 1 to T."""

    @property
    def count(self) -> int:
        """Number of episodes B."""
        return self.obs.shape[0]

    def final_distance(self) -> np.ndarray:
        """(B,) Euclidean distance between the last achieved goal and the task's goal."""
        return np.linalg.norm(self.achieved_goal[:, -1] - self.desired_goal, axis=-1)


class Batch(NamedTuple):
    """Transitions sampled for one update of a learner."""

    obs: np.ndarray
    goal: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    """(N,) reward of reaching ``goal`` on the step to ``next_obs``."""
    next_obs: np.ndarray
    next_action: np.ndarray | None = None
    """Where given (rows of ``next_action_given``), the action that follows ``next_obs`` is
    known and is used for bootstrapping instead of the target actor's."""
    next_action_given: np.ndarray | None = None
    next_value: np.ndarray | None = None
    """Where given (rows of ``next_value_given``), the value of ``next_obs`` is known from what
    followed it and replaces the target critic's estimate in the target."""
    next_value_given: np.ndarray | None = None
    terminal: np.ndarray | None = None
    """Where given, (N,) whether the task ends the episode pursuing ``goal`` on this step (or
    the steps summed into ``reward``): its target is the reward alone, with no value after it."""
    discount: np.ndarray | None = None
    """Where given, each row's discount of the value of ``next_obs`` (for n-step returns),
    instead of the learner's gamma."""
    actor_rows: np.ndarray | None = None
    """Where given, the rows the actor learns from (states where the policy chooses); all rows
    without it."""
