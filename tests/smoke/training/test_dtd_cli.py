"""Dot-to-Dot from the command line: its metrics, its plans, resume and determinism."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers import TINY, dtd, read_metrics, without_times

pytestmark = pytest.mark.smoke

DTD = ["--env", "FetchPush-v4", "--algo", "dtd", "--seed", "5", *TINY]


@pytest.fixture(scope="module")
def push_dtd(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir = tmp_path_factory.mktemp("dtd") / "push"
    result = dtd("train", *DTD, "--epochs", "3", "--run-dir", run_dir)
    assert result.returncode == 0, result.stderr
    return run_dir


def test_dtd_logs_both_levels_and_its_sub_goals(push_dtd):
    rows = read_metrics(push_dtd)
    assert len(rows) == 3
    columns = ["eval_success", "eval_subgoal_reached", "train_subgoal_reached", "subgoal_eps",
               "high_critic_loss", "high_actor_loss", "high_q_mean", "eval_subgoal_from_start",
               "eval_subgoal_from_goal", "train_subgoal_from_start", "train_subgoal_from_goal",
               "eval_subgoal_progress", "eval_subgoal_off_line", "train_subgoal_progress",
               "train_subgoal_off_line"]  # fmt: skip
    for column in columns:
        assert all(row[column] != "" for row in rows), column
    # The hand-over starts at 1 and decays: 2 cycles x 2 episodes per epoch over 30 epochs.
    eps = [float(row["subgoal_eps"]) for row in rows]
    assert eps[0] < 1.0 and eps[0] > eps[1] > eps[2] > 0.1


def test_eval_shows_the_plan_of_each_episode(push_dtd):
    result = dtd("eval", push_dtd, "--episodes", "2", "--show-subgoals")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    figures = json.loads(lines[-1])
    assert figures["algo"] == "dtd" and figures["episodes"] == 2
    assert 0.0 <= figures["subgoal_reached"] <= 1.0
    placement = figures["subgoal_placement"]
    assert sum(group["episodes"] for group in placement) <= 2
    assert all(len(group["progress"]) == len(group["off_line"]) == 1 for group in placement)
    text = "\n".join(lines[:-1])
    assert "sub-goals along the way" in text
    assert text.count("episode ") == 2 and text.count("segment 0: sub-goal") == 2
    assert text.count("segment 1: sub-goal") == 2 and text.count("goal     (") == 2
    # The last sub-goal is the goal itself.
    for block in text.split("episode ")[1:]:
        last = block.split("segment 1: sub-goal ")[1].split("  reached")[0]
        assert f"goal     {last}" in block


def test_show_subgoals_needs_a_high_level(reach_run):
    result = dtd("eval", reach_run, "--show-subgoals")
    assert result.returncode == 2
    assert "needs a dtd run" in result.stderr and "Traceback" not in result.stderr


def test_dtd_resume_and_determinism(push_dtd, tmp_path):
    # Where the episodes are collected changes nothing, and may change when resuming.
    short = tmp_path / "short"
    assert dtd("train", *DTD, "--epochs", "2", "--collector", "process", "--run-dir", short).returncode == 0
    result = dtd("train", "--resume", short, "--epochs", "3", "--collector", "inline", "--no-progress")
    assert result.returncode == 0, result.stderr
    assert without_times(read_metrics(short)) == without_times(read_metrics(push_dtd))
    inline = tmp_path / "inline"
    assert dtd("train", *DTD, "--epochs", "3", "--collector", "inline", "--run-dir", inline).returncode == 0
    assert without_times(read_metrics(inline)) == without_times(read_metrics(push_dtd))


def test_dtd_settings_are_checked(tmp_path):
    result = dtd("train", *DTD, "--segments", "1", "--run-dir", tmp_path / "r")
    assert result.returncode == 2 and "--segments must be at least 2" in result.stderr
    result = dtd("train", *DTD, "--segments", "60", "--run-dir", tmp_path / "r")
    assert result.returncode == 2 and "--segments must be at most the horizon (50)" in result.stderr
    result = dtd("train", *DTD, "--high.actor-lr", "0", "--run-dir", tmp_path / "r")
    assert result.returncode == 2 and "--high.actor-lr must be > 0" in result.stderr
    assert not (tmp_path / "r").exists()


def test_a_trained_high_level_can_be_queried_at_any_sub_goal(push_dtd):
    import numpy as np

    from dtd.agents.dot_to_dot import DotToDotAgent
    from dtd.training.trained_run import load_agent

    agent, env = load_agent(push_dtd)
    assert isinstance(agent, DotToDotAgent)
    observation, _ = env.reset(seed=0)
    grid = np.stack(np.meshgrid(np.linspace(1.1, 1.5, 4), np.linspace(0.5, 1.0, 3)), -1).reshape(-1, 2)
    candidates = np.column_stack([grid, np.full(len(grid), 0.425)])
    values = agent.subgoal_values(observation, observation["desired_goal"], candidates)
    assert values.shape == (12,) and np.all(np.isfinite(values))
    env.close()
