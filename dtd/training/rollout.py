"""Running whole episodes on a set of environments stepped side by side; learns nothing."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from dtd.agents.interface import Agent
from dtd.agents.records import Episodes
from dtd.envs.goals import GoalTest, success_of
from dtd.envs.spec import EnvSpec, goal_functions
from dtd.errors import EnvError

StepHook = Callable[[int, np.ndarray], None]
"""Called with t and the (B, goal_dim) goals the policy pursues from the state at t: before
acting at each step t (the environments hold the state at t), and once more after the last step,
at t = the longest episode's length (T where an episode ran to the time limit)."""


def run_episodes(
    envs: Sequence[gym.Env],
    agent: Agent,
    spec: EnvSpec,
    explore: bool,
    rng: np.random.Generator,
    on_step: StepHook | None = None,
) -> Episodes:
    """One episode on each environment, acting in lock-step with batched policy calls;
    ``on_step`` sees every state (e.g. to render it).

    An episode ends at the time limit, where the task truncates it, or where the task ends it
    on reaching its goal (``spec.ends_on_goal``); an environment whose episode has ended is
    not stepped again, and its arrays are padded (see :class:`Episodes`). An end that the
    task's own verdict on the goal does not explain is refused (:class:`EnvError`).
    """
    count, horizon = len(envs), spec.horizon
    obs = np.zeros((count, horizon + 1, spec.obs_dim), dtype=np.float32)
    achieved = np.zeros((count, horizon + 1, spec.goal_dim), dtype=np.float32)
    actions = np.zeros((count, horizon, spec.action_dim), dtype=np.float32)
    step_goals = np.zeros((count, horizon, spec.goal_dim), dtype=np.float32)
    desired = np.zeros((count, spec.goal_dim), dtype=np.float32)
    success = np.zeros(count, dtype=np.float32)
    length = np.full(count, horizon, dtype=np.int64)
    terminal = goal_functions(envs[0], spec).terminal

    for i, env in enumerate(envs):
        first, _ = env.reset()
        obs[i, 0] = first["observation"].ravel()
        achieved[i, 0] = first["achieved_goal"].ravel()
        desired[i] = first["desired_goal"].ravel()

    infos: list[dict[str, Any]] = [{} for _ in envs]
    running = np.ones(count, dtype=bool)
    t = 0
    while t < horizon and running.any():
        step_goals[:, t] = agent.step_goal(obs[:, t], achieved[:, t], desired, t, explore, rng)
        if on_step is not None:
            on_step(t, step_goals[:, t])
        actions[:, t] = agent.act(obs[:, t], step_goals[:, t], explore, rng)
        ended = np.zeros(count, dtype=bool)
        for i in np.flatnonzero(running):
            action = actions[i, t].reshape(envs[i].action_space.shape)
            step_obs, _, terminated, truncated, infos[i] = envs[i].step(action)
            obs[i, t + 1] = step_obs["observation"].ravel()
            achieved[i, t + 1] = step_obs["achieved_goal"].ravel()
            ended[i] = bool(terminated)
            if terminated or truncated:
                running[i] = False
                length[i] = t + 1
        stepped = ended | running | (length == t + 1)
        _check_ends(spec, terminal, achieved[stepped, t + 1], desired[stepped], ended[stepped], t + 1)
        idle = ~stepped
        obs[idle, t + 1], achieved[idle, t + 1] = obs[idle, t], achieved[idle, t]
        t += 1
    if on_step is not None:
        on_step(t, step_goals[:, max(t - 1, 0)])
    for i in np.flatnonzero(length < horizon):  # padding: the end repeated, no action
        end = length[i]
        obs[i, end + 1 :], achieved[i, end + 1 :] = obs[i, end], achieved[i, end]
        actions[i, end:] = 0.0
        step_goals[i, end:] = step_goals[i, end - 1]
    for i, info in enumerate(infos):
        success[i] = success_of(info)
    return Episodes(obs, achieved, actions, step_goals, desired, success, length)


def _check_ends(
    spec: EnvSpec,
    terminal: GoalTest | None,
    achieved_goal: np.ndarray,
    goal: np.ndarray,
    ended: np.ndarray,
    step: int,
) -> None:
    """Refuse episodes whose end (or its absence) after ``step`` steps is not the task's verdict
    on the goal: dtd learns from tasks that end an episode only on reaching its goal. At the time
    limit any end is the limit's (a transition that bootstraps, as it always did)."""
    if not len(goal) or step >= spec.horizon:
        return
    reached = terminal(achieved_goal, goal) if terminal is not None else np.zeros(len(goal), dtype=bool)
    if np.any(ended & ~reached):
        because = (
            "its compute_terminated says the goal was not reached there"
            if spec.ends_on_goal
            else "it ends no episode on reaching its goal, by its compute_terminated or its reward"
        )
        raise EnvError(
            f"environment {spec.env_id!r} ended an episode at step {step} of {spec.horizon} for "
            f"another reason than reaching its goal ({because}); dtd learns from episodes that run "
            "to the time limit or end when their goal is reached"
        )
    if np.any(reached & ~ended):
        raise EnvError(
            f"environment {spec.env_id!r} did not end an episode at step {step} where its goal was "
            "reached by its own verdict (its compute_terminated, or success where it defines none, "
            "which dtd takes as the end): an environment whose episodes run to the time limit says so "
            "by a compute_terminated(achieved_goal, desired_goal, info) that returns False, as "
            "Gymnasium-Robotics' Fetch and Hand tasks do"
        )


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
    """Success (the task's ``is_success`` where the episode ended), final distance to the goal, and
    the agent's own figures of these episodes."""
    return {
        "success": float(np.mean(episodes.success, dtype=np.float64)),
        "final_distance": float(np.mean(episodes.final_distance(), dtype=np.float64)),
        **agent.episode_metrics(episodes),
    }
