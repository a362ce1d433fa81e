"""The task's verdicts on goals, batched: the reward of reaching a goal, whether a goal is reached,
and where the task ends an episode for a goal (its own or one relabelled in hindsight).

Gymnasium-Robotics' Fetch and Hand tasks run every episode to its time limit; other suites end
an episode as soon as its goal is reached (the mazes with ``continuing_task=False``), and some
pay 0/1 or dense rewards instead of -1/0. What a task does is read from it once
(:func:`goal_verdicts`) and recorded in its :class:`~dtd.envs.spec.EnvSpec`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from dtd.errors import EnvError

RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""The task's reward of achieved goals (B, G) against goals (B, G): (B,) float32."""

GoalTest = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""A verdict on achieved goals (B, G) against goals (B, G): (B,) bool."""

SUCCESS_KEYS = ("is_success", "success")
"""Where a task reports its success in ``info``: Gymnasium-Robotics' Fetch and Hand tasks say
``is_success``, its mazes ``success``."""


SparseRewards = tuple[float, float] | None
"""The two rewards of a sparse task, (not reached, reached), e.g. (-1, 0) or (0, 1); None where
the reward takes more values (dense)."""


def return_bounds(sparse: SparseRewards, gamma: float) -> tuple[float, float] | None:
    """The range of discounted returns of per-step rewards between a sparse task's two, an
    episode ending (nothing after it) or running on for ever; None for a dense reward or a
    discount of 1, whose returns dtd does not bound."""
    if sparse is None or gamma >= 1.0:
        return None
    low, high = sparse
    return min(low, 0.0) / (1.0 - gamma), max(high, 0.0) / (1.0 - gamma)


@dataclasses.dataclass(frozen=True)
class GoalFunctions:
    """The task's batched verdicts on goals, as the agents use them."""

    reward: RewardFn
    reached: GoalTest | None
    """Whether each achieved goal reaches its goal by the task's own measure: the success
    reward of a sparse task, else the task's ``compute_terminated`` where it ends episodes on
    reaching the goal; None where neither tells (a dense reward on a task that runs on)."""
    terminal: GoalTest | None
    """Where the task would end an episode pursuing each goal: the transition to that achieved
    goal is terminal (nothing to bootstrap); None for a task that runs every episode to its
    time limit."""


def measure_rewards(
    env: gym.Env, goal_low: np.ndarray, goal_high: np.ndarray, quaternion: tuple[int, int] | None, env_id: str
) -> SparseRewards:
    """Whether the reward is sparse, and its two values, from the rewards of goals against
    themselves and of pairs drawn from the goal box (and the task's first reset): two values,
    the higher one every goal's against itself, is sparse."""
    rng = np.random.default_rng(0)
    first, _ = env.reset(seed=0)
    goal_dim = len(goal_low)
    drawn = rng.uniform(goal_low, goal_high, size=(256, goal_dim))
    if quaternion is not None:  # a rotation is a unit quaternion
        part = drawn[:, quaternion[0] : quaternion[1]]
        part /= np.linalg.norm(part, axis=-1, keepdims=True)
    achieved = np.concatenate([drawn, drawn[::-1], first["achieved_goal"].reshape(1, -1)])
    goals = np.concatenate([drawn, drawn, first["desired_goal"].reshape(1, -1)])
    compute_reward = env.unwrapped.compute_reward
    at_goal = np.asarray(compute_reward(drawn, drawn, None), dtype=np.float64)
    rewards = np.asarray(compute_reward(achieved, goals, None), dtype=np.float64)
    if not (np.all(np.isfinite(rewards)) and np.all(np.isfinite(at_goal))):
        raise EnvError(f"environment {env_id!r}: compute_reward gives rewards that are not finite")
    values = np.unique(np.concatenate([rewards, at_goal]))
    if len(values) == 2 and np.all(at_goal == values[1]):
        return float(values[0]) + 0.0, float(values[1]) + 0.0  # + 0.0: no negative zero
    if len(values) == 1:
        raise EnvError(
            f"environment {env_id!r}: compute_reward gives the same reward ({values[0]:g}) to every "
            "goal reached or not, so there is nothing to learn"
        )
    return None


def ends_on_goal(env: gym.Env, goal_example: np.ndarray, sparse: SparseRewards) -> bool:
    """Whether the task ends an episode when its goal is reached: its ``compute_terminated``
    says so of a goal reached exactly; without one, a task is taken to end on success (as
    suites without it do) where a sparse reward tells success, and to run to its time limit
    otherwise."""
    compute_terminated = _compute_terminated(env)
    if compute_terminated is None:
        return sparse is not None
    goal = goal_example.reshape(1, -1)
    return bool(np.any(compute_terminated(goal, goal, None)))


def goal_verdicts(env: gym.Env, sparse: SparseRewards, ends: bool) -> GoalFunctions:
    """The batched verdicts of ``env``'s task, whose rewards are ``sparse`` (None: dense) and
    which ends an episode on reaching its goal where ``ends``."""
    compute_reward = env.unwrapped.compute_reward

    def reward(achieved_goal: np.ndarray, goal: np.ndarray) -> np.ndarray:
        return np.asarray(compute_reward(achieved_goal, goal, None), dtype=np.float32)

    reached: GoalTest | None = None
    if sparse is not None:
        success_reward = np.float32(sparse[1])

        def reached_by_reward(achieved_goal: np.ndarray, goal: np.ndarray) -> np.ndarray:
            return reward(achieved_goal, goal) == success_reward

        reached = reached_by_reward
    compute_terminated = _compute_terminated(env)
    terminal: GoalTest | None = None
    if ends:
        terminal = _batched(compute_terminated) if compute_terminated is not None else reached
        reached = reached or terminal
    return GoalFunctions(reward=reward, reached=reached, terminal=terminal)


def _compute_terminated(env: gym.Env) -> Callable[..., Any] | None:
    """The task's ``compute_terminated``, where it defines one that answers."""
    method = getattr(env.unwrapped, "compute_terminated", None)
    if not callable(method):
        return None
    space = env.observation_space["desired_goal"]
    probe = np.zeros((1, int(np.prod(space.shape))))
    try:
        method(probe, probe, None)
    except NotImplementedError:  # Gymnasium-Robotics' GoalEnv declares it without a body
        return None
    except Exception as exc:
        raise EnvError(
            f"environment {env.spec.id if env.spec else env!r}: compute_terminated(achieved_goal, "
            f"desired_goal, info) fails on goals with info None ({exc}); dtd asks it of relabelled "
            "goals, which have no info"
        ) from exc
    return method


def _batched(compute_terminated: Callable[..., Any]) -> GoalTest:
    """``compute_terminated`` over a batch: called once where it answers per row (as its
    ``compute_reward`` does), row by row where it answers one verdict for the whole batch (as
    Gymnasium-Robotics' mazes do)."""

    def terminal(achieved_goal: np.ndarray, goal: np.ndarray) -> np.ndarray:
        count = len(goal)
        verdict = np.asarray(compute_terminated(achieved_goal, goal, None))
        if verdict.shape == (count,):
            return verdict.astype(bool)
        return np.array(
            [bool(compute_terminated(achieved_goal[i], goal[i], None)) for i in range(count)], dtype=bool
        )

    return terminal


def success_of(info: dict[str, Any]) -> float:
    """The task's success reported in a step's ``info``, 0 or 1 (0 where it reports none)."""
    for key in SUCCESS_KEYS:
        if key in info:
            return float(bool(info[key]))
    return 0.0
