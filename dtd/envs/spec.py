"""Describing a goal-conditioned environment once (:class:`EnvSpec`): its dimensions, horizon,
goal box and batched reward; an environment that is not goal-conditioned is refused."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np

from dtd.envs.goals import SUCCESS_KEYS, GoalFunctions, ends_on_goal, goal_verdicts, measure_rewards
from dtd.errors import EnvError

GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")


@dataclasses.dataclass(frozen=True)
class EnvSpec:
    """What the agents need to know of an environment, derived once from it."""

    env_id: str
    obs_dim: int
    goal_dim: int
    action_dim: int
    action_max: float
    """Actions lie in [-action_max, action_max] in every dimension."""
    horizon: int
    """Steps per episode (the environment's time limit), T."""
    goal_low: tuple[float, ...]
    """Lower corner of the box goals (and so sub-goals) are kept in."""
    goal_high: tuple[float, ...]
    """Upper corner of that box."""
    quaternion: tuple[int, int] | None = None
    """Goal entries [start, stop) that hold a unit quaternion (a rotation), if any."""
    sparse_rewards: tuple[float, float] | None = None
    """The task's two rewards, (goal not reached, reached), e.g. (-1, 0) or (0, 1); None for a
    dense reward (measured: :func:`dtd.envs.goals.measure_rewards`)."""
    ends_on_goal: bool = False
    """Whether the task ends an episode as soon as its goal is reached (its compute_terminated,
    or success where it defines none); else every episode runs to the time limit."""

    def default_gamma(self) -> float:
        """The reference discount 1 - 1/T."""
        return 1.0 - 1.0 / self.horizon


def env_spec(env: gym.Env, env_id: str) -> EnvSpec:
    """Check that ``env`` is goal-conditioned and describe it; raise :class:`EnvError` if not."""
    space = env.observation_space
    if not isinstance(space, gym.spaces.Dict) or not all(k in space.spaces for k in GOAL_KEYS):
        raise EnvError(
            f"environment {env_id!r} is not goal-conditioned: its observations must be dicts "
            f"with keys {', '.join(GOAL_KEYS)}"
        )
    if not all(isinstance(space[k], gym.spaces.Box) for k in GOAL_KEYS):
        raise EnvError(f"environment {env_id!r}: observation, achieved_goal and desired_goal must be Boxes")
    if space["achieved_goal"].shape != space["desired_goal"].shape:
        raise EnvError(f"environment {env_id!r}: achieved_goal and desired_goal differ in shape")
    if not callable(getattr(env.unwrapped, "compute_reward", None)):
        raise EnvError(f"environment {env_id!r} is not goal-conditioned: it has no compute_reward")
    action_space = env.action_space
    if not isinstance(action_space, gym.spaces.Box):
        raise EnvError(f"environment {env_id!r} needs continuous (Box) actions")
    high = np.asarray(action_space.high, dtype=np.float64)
    if (
        not np.all(np.isfinite(high))
        or not np.allclose(action_space.low, -high)
        or not np.allclose(high, high.flat[0])
    ):
        raise EnvError(f"environment {env_id!r} needs actions in a symmetric box [-m, m]")
    horizon = env.spec.max_episode_steps if env.spec is not None else None
    if not horizon:
        raise EnvError(f"environment {env_id!r} has no time limit (max_episode_steps)")
    goal_dim = int(np.prod(space["desired_goal"].shape))
    quaternion = _quaternion_part(env, goal_dim)
    _check_batched_reward(env, env_id, goal_dim)
    goal_low, goal_high = goal_bounds(env, quaternion)
    sparse = measure_rewards(env, goal_low, goal_high, quaternion, env_id)
    ends = ends_on_goal(env, goal_low, sparse)
    spec = EnvSpec(
        env_id=env_id,
        obs_dim=int(np.prod(space["observation"].shape)),
        goal_dim=goal_dim,
        action_dim=int(np.prod(action_space.shape)),
        action_max=float(high.flat[0]),
        horizon=int(horizon),
        goal_low=tuple(goal_low.tolist()),
        goal_high=tuple(goal_high.tolist()),
        quaternion=quaternion,
        sparse_rewards=sparse,
        ends_on_goal=ends,
    )
    _check_success_reported(env, spec)
    return spec


def _quaternion_part(env: gym.Env, goal_dim: int) -> tuple[int, int] | None:
    # The in-hand manipulation tasks' goals are a position then a rotation quaternion.
    if goal_dim == 7 and hasattr(env.unwrapped, "target_rotation"):
        return (3, 7)
    return None


def goal_bounds(
    env: gym.Env, quaternion: tuple[int, int] | None, resets: int = 50
) -> tuple[np.ndarray, np.ndarray]:
    """A box holding the task's goals: the goal space's own bounds where finite, else the
    range of goals and achieved goals over ``resets`` seeded resets, widened by a tenth of
    that range on each side. A coordinate that no goal varies (FetchPush's table height) is
    pinned, and one where every reset puts the object at the same value with no goal below
    it (FetchPickAndPlace's block resting on the table) is not widened below that value:
    a sub-goal off the table or inside it could never be reached."""
    space = env.observation_space["desired_goal"]
    low = np.asarray(space.low, dtype=np.float64).ravel().copy()
    high = np.asarray(space.high, dtype=np.float64).ravel().copy()
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        goals, achieved = [], []
        for seed in range(resets):
            first, _ = env.reset(seed=seed)
            goals.append(first["desired_goal"].ravel())
            achieved.append(first["achieved_goal"].ravel())
        seen_low = np.minimum(np.min(goals, axis=0), np.min(achieved, axis=0))
        seen_high = np.maximum(np.max(goals, axis=0), np.max(achieved, axis=0))
        margin = 0.1 * (seen_high - seen_low)
        lowest_achieved = np.min(achieved, axis=0)
        resting = (np.ptp(achieved, axis=0) < 1e-6) & (np.min(goals, axis=0) >= lowest_achieved - 1e-6)
        low = np.where(np.isfinite(low), low, seen_low - np.where(resting, 0.0, margin))
        high = np.where(np.isfinite(high), high, seen_high + margin)
    if quaternion is not None:
        low[quaternion[0] : quaternion[1]] = -1.0
        high[quaternion[0] : quaternion[1]] = 1.0
    return low, high


def _check_batched_reward(env: gym.Env, env_id: str, goal_dim: int) -> None:
    goals = np.zeros((2, goal_dim))
    try:
        rewards = np.asarray(env.unwrapped.compute_reward(goals, goals, None))
    except Exception as exc:
        raise EnvError(f"environment {env_id!r}: compute_reward fails on a batch of goals ({exc})") from exc
    if rewards.shape != (2,):
        raise EnvError(f"environment {env_id!r}: compute_reward must return one reward per goal of a batch")


def _check_success_reported(env: gym.Env, spec: EnvSpec) -> None:
    # Success is the task's own verdict at the last step; without it every episode would count 0.
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
    if not any(key in info for key in SUCCESS_KEYS):
        raise EnvError(
            f"environment {spec.env_id!r} does not report info['is_success'] (or info['success']), "
            "which is what dtd counts as success"
        )


def goal_functions(env: gym.Env, spec: EnvSpec) -> GoalFunctions:
    """The task's batched reward, reached and terminal verdicts on goals, as ``spec`` found it."""
    return goal_verdicts(env, spec.sparse_rewards, spec.ends_on_goal)
