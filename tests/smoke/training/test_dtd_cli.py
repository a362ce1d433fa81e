"""Dot-to-Dot from the command line: its metrics, its plans, resume and determinism."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
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


def test_a_hand_run_places_poses_and_reports_their_angles(tmp_path):
    from dtd.agents.rotations import angle_between
    from dtd.envs.make import make_env
    from dtd.envs.spec import env_spec

    run_dir = tmp_path / "hand"
    name = "HandManipulateBlockRotateZ-v1"
    args = [
        "--env",
        name,
        "--algo",
        "dtd",
        "--seed",
        "3",
        *TINY,
        "--epochs",
        "2",
        "--subgoal-rotation-angle",
        "60",
    ]
    result = dtd("train", *args, "--run-dir", run_dir)
    assert result.returncode == 0, result.stderr
    for row in read_metrics(run_dir):
        for split in ("train", "eval"):
            assert 0.0 < float(row[f"{split}_subgoal_angle_from_start"]) <= 180.0
            assert 0.0 <= float(row[f"{split}_subgoal_angle_from_goal"]) <= 180.0
            assert np.isfinite(float(row[f"{split}_subgoal_progress"]))
    result = dtd("eval", run_dir, "--episodes", "3", "--show-subgoals")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert "goal_angle" in figures["subgoal_placement"][0]
    assert "deg from the start" in result.stdout and "goal angle (deg)" in result.stdout
    # Sub-goals a trained high level chose over whole episodes: unit quaternions in the goal box.
    result = dtd("render", run_dir, "--episodes", "2", "--width", "64", "--height", "64")
    assert result.returncode == 0, result.stderr
    env = make_env(name)
    spec = env_spec(env, name)
    env.close()
    for plan in json.loads((run_dir / "render" / "plans.json").read_text()):
        subgoals = np.array(plan["subgoals"])
        assert np.allclose(np.linalg.norm(subgoals[:, 3:], axis=-1), 1.0, atol=1e-5)
        assert np.all(subgoals >= np.array(spec.goal_low) - 1e-6)
        assert np.all(subgoals <= np.array(spec.goal_high) + 1e-6)
        start_to_subgoal = np.degrees(angle_between(np.array(plan["start"])[3:], subgoals[:, 3:]))
        assert np.allclose(plan["angles"]["start_to_subgoal"], start_to_subgoal, atol=0.06)
    result = dtd("report", run_dir, "--episodes", "1")
    assert result.returncode == 0, result.stderr
    page = (run_dir / "report.html").read_text()
    assert "No heatmap: this task's goal is the block's orientation" in page
    assert "&deg; from the start" in page
