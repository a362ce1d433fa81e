"""Running whole episodes on a set of environments stepped side by side; learns nothing."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from dtd.agents.interface import Agent
from dtd.agents.records import Episodes
from dtd.envs.spec import EnvSpec
from dtd.errors import EnvError

StepHook = Callable[[int, np.ndarray], None]
"""Called with t and the (B, goal_dim) goals the policy pursues from the state at t: before
acting at each step t (the environments hold the state at t), and once more at t = T."""


def run_episodes(
    envs: Sequence[gym.Env],
    agent: Agent,
    spec: EnvSpec,
    explore: bool,
    rng: np.random.Generator,
    on_step: StepHook | None = None,
) -> Episodes:
    """One episode on each environment, acting in lock-step with batched policy calls;
    ``on_step`` sees every state (e.g. to render it)."""
    count, horizon = len(envs), spec.horizon
    obs = np.zeros((count, horizon + 1, spec.obs_dim), dtype=np.float32)
    achieved = np.zeros((count, horizon + 1, spec.goal_dim), dtype=np.float32)
    actions = np.zeros((count, horizon, spec.action_dim), dtype=np.float32)
    step_goals = np.zeros((count, horizon, spec.goal_dim), dtype=np.float32)
    desired = np.zeros((count, spec.goal_dim), dtype=np.float32)
    success = np.zeros(count, dtype=np.float32)

    for i, env in enumerate(envs):
        first, _ = env.reset()
        obs[i, 0] = first["observation"].ravel()
        achieved[i, 0] = first["achieved_goal"].ravel()
        desired[i] = first["desired_goal"].ravel()

    infos: list[dict[str, Any]] = [{} for _ in envs]
    for t in range(horizon):
        step_goals[:, t] = agent.step_goal(obs[:, t], achieved[:, t], desired, t, explore, rng)
        if on_step is not None:
            on_step(t, step_goals[:, t])
        actions[:, t] = agent.act(obs[:, t], step_goals[:, t], explore, rng)
        for i, env in enumerate(envs):
            step_obs, _, terminated, _, infos[i] = env.step(actions[i, t].reshape(env.action_space.shape))
            if terminated and t + 1 < horizon:
                raise EnvError(
                    f"environment {spec.env_id!r} ended an episode at step {t + 1} of {horizon}; dtd "
                    "learns from episodes that run to the time limit (as Gymnasium-Robotics' tasks do)"
                )
            obs[i, t + 1] = step_obs["observation"].ravel()
            achieved[i, t + 1] = step_obs["achieved_goal"].ravel()
    if on_step is not None:
        on_step(horizon, step_goals[:, -1])
    for i, info in enumerate(infos):
        success[i] = float(info.get("is_success", 0.0))
    return Episodes(obs, achieved, actions, step_goals, desired, success)


def run_many(
    envs: Sequence[gym.Env], agent: Agent, spec: EnvSpec, count: int, explore: bool, rng: np.random.Generator
) -> Episodes:
    """``count`` episodes, in batches of at most one per environment."""
    batches = []
    remaining = count
    while remaining > 0:
        used = envs[: min(remaining, len(envs))]
        batches.append(run_episodes(used, agent, spec, explore, rng))
        remaining -= len(used)
    return concatenate(batches)


def concatenate(batches: Sequence[Episodes]) -> Episodes:
    """One batch of episodes from several."""
    return Episodes(*(np.concatenate(parts) for parts in zip(*batches, strict=True)))


def episode_figures(agent: Agent, episodes: Episodes) -> dict[str, float]:
    """Success (the task's ``is_success`` at the last step), final distance to the goal, and
    the agent's own figures of these episodes."""
    return {
        "success": float(np.mean(episodes.success, dtype=np.float64)),
        "final_distance": float(np.mean(episodes.final_distance(), dtype=np.float64)),
        **agent.episode_metrics(episodes),
    }
