"""Tasks of other suites: episodes that end when the goal is reached, 0/1 and dense rewards, and
constructor arguments given with --env-kwargs, through every command."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import TINY, read_metrics
from tests.smoke.explain.test_explore import explorer, get

pytestmark = pytest.mark.smoke

REPOSITORY = Path(__file__).parents[3]
ENDING = "tests.goal_envs:PointGoalEndsOnSuccess-v0"
MAZE = ["--env", "PointMaze_UMaze-v3", "--env-kwargs", "continuing_task=False", "max_episode_steps=30"]


def dtd(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``python -m dtd ARGS`` with the repository importable (for tests/goal_envs.py)."""
    env = {**os.environ, "PYTHONPATH": str(REPOSITORY), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    command = [sys.executable, "-m", "dtd", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, env=env, cwd=cwd, timeout=600)


def derived_spec(run_dir: Path) -> dict:
    return json.loads((run_dir / "config.json").read_text())["derived"]["spec"]


@pytest.mark.parametrize("algo", ["her", "dtd"])
def test_a_task_that_ends_on_its_goal_trains_evaluates_and_resumes(tmp_path, algo):
    run_dir = tmp_path / "run"
    result = dtd("train", "--env", ENDING, "--algo", algo, "--epochs", "2", *TINY, "--n-cycles", "6",
                 "--run-dir", run_dir)  # fmt: skip
    assert result.returncode == 0, result.stderr
    spec = derived_spec(run_dir)
    assert spec["ends_on_goal"] is True and spec["sparse_rewards"] == [0.0, 1.0]
    rows = read_metrics(run_dir)
    # Steps are those taken: episodes that reached their goal ended before the 20-step limit.
    assert [int(row["episodes"]) for row in rows] == [12, 24]
    assert int(rows[-1]["env_steps"]) < 24 * 20
    assert float(rows[-1]["train_success"]) > 0.0  # the task reported "success", not "is_success"
    result = dtd("eval", run_dir, "--episodes", "6", *(["--show-subgoals"] if algo == "dtd" else []))
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert 0.0 <= figures["success_rate"] <= 1.0
    result = dtd("train", "--resume", run_dir, "--epochs", "3", "--no-progress")
    assert result.returncode == 0, result.stderr
    assert len(read_metrics(run_dir)) == 3


def test_the_task_that_declares_no_compute_terminated_ends_on_success(tmp_path):
    run_dir = tmp_path / "run"
    result = dtd("train", "--env", "tests.goal_envs:PointGoalEndsUndeclared-v0", "--algo", "dtd", "--epochs",
                 "1", *TINY, "--n-cycles", "6", "--run-dir", run_dir)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert derived_spec(run_dir)["ends_on_goal"] is True
    assert int(read_metrics(run_dir)[-1]["env_steps"]) < 12 * 20


def test_a_dense_reward_is_not_clipped_and_has_no_reached_verdict(tmp_path):
    run_dir = tmp_path / "run"
    result = dtd("train", "--env", "tests.goal_envs:PointGoalDense-v0", "--algo", "dtd", "--epochs", "1",
                 *TINY, "--run-dir", run_dir)  # fmt: skip
    assert result.returncode == 0, result.stderr
    spec = derived_spec(run_dir)
    assert spec["sparse_rewards"] is None and spec["ends_on_goal"] is False
    row = read_metrics(run_dir)[-1]
    assert row["eval_subgoal_reached"] == "nan"


def test_the_observed_high_target_is_refused_where_episodes_end_on_the_goal(tmp_path):
    result = dtd("train", "--env", ENDING, "--algo", "dtd", "--high-target", "observed", *TINY,
                 "--run-dir", tmp_path / "run")  # fmt: skip
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "--high-target observed" in result.stderr and "bootstrap" in result.stderr


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        (["bogus"], "--env-kwargs takes KEY=VALUE items, got 'bogus'"),
        (["no_such_argument=1"], "refused --env-kwargs no_such_argument=1"),
    ],
)
def test_env_kwargs_that_cannot_work_are_one_line(tmp_path, kwargs, needle):
    result = dtd(
        "train", "--env", "FetchReach-v4", "--env-kwargs", *kwargs, *TINY, "--run-dir", tmp_path / "run"
    )
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and needle in result.stderr, result.stderr
    assert not (tmp_path / "run").exists()


@pytest.fixture(scope="module")
def maze_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny dtd run on Gymnasium-Robotics' PointMaze, episodes ended on reaching the goal."""
    run_dir = tmp_path_factory.mktemp("maze") / "run"
    result = dtd("train", *MAZE, "--algo", "dtd", "--epochs", "2", *TINY, "--run-dir", run_dir)
    assert result.returncode == 0, result.stderr
    return run_dir


def test_the_constructor_arguments_are_recorded_and_used_again(maze_run):
    config = json.loads((maze_run / "config.json").read_text())
    assert config["config"]["env_kwargs"] == ["continuing_task=False", "max_episode_steps=30"]
    spec = config["derived"]["spec"]
    # max_episode_steps reached gym.make; continuing_task=False the maze's compute_terminated.
    assert spec["horizon"] == 30 and spec["ends_on_goal"] is True and spec["sparse_rewards"] == [0.0, 1.0]
    result = dtd("eval", maze_run, "--episodes", "2")
    assert result.returncode == 0, result.stderr
    result = dtd("report", maze_run, "--episodes", "1", "--resolution", "8")
    assert result.returncode == 0, result.stderr
    assert "goal box" in (maze_run / "report.html").read_text()


def test_resume_makes_the_task_with_its_constructor_arguments(maze_run, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(maze_run, copy)
    (copy / ".trainer.lock").unlink(missing_ok=True)
    result = dtd("train", "--resume", copy, "--epochs", "3", "--no-progress")
    assert result.returncode == 0, result.stderr
    assert [int(row["epoch"]) for row in read_metrics(copy)] == [1, 2, 3]


def test_render_heatmap_and_export_run_on_the_maze(maze_run, tmp_path):
    result = dtd("render", maze_run, "--episodes", "1", "--out", tmp_path / "render")
    assert result.returncode == 0, result.stderr
    plans = json.loads((tmp_path / "render" / "plans.json").read_text())
    assert 1 <= plans[0]["steps"] <= 30
    assert (tmp_path / "render" / "episode-1.mp4").stat().st_size > 0
    # Planar goals: the map covers the goal box, from the task's own start and goal.
    result = dtd("heatmap", maze_run, "--out", tmp_path / "heat.png", "--resolution", "8")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "heat.png").stat().st_size > 0
    result = dtd("heatmap", maze_run, "--start", "1,1", "--out", tmp_path / "refused.png")
    assert result.returncode == 2 and "mapped from its own start and goal" in result.stderr
    result = dtd("export", maze_run, "--out", tmp_path / "onnx")
    assert result.returncode == 0, result.stderr
    policy = json.loads((tmp_path / "onnx" / "policy.json").read_text())
    assert policy["env_kwargs"] == {"continuing_task": False, "max_episode_steps": 30}
    code = re.search(r"```python\n(.*?)```", (tmp_path / "onnx" / "README.md").read_text(), re.S).group(1)
    blocked = "import sys\nsys.modules['dtd'] = None  # importing dtd would fail here\n"
    ran = subprocess.run([sys.executable, "-c", blocked + code], capture_output=True, text=True,
                         timeout=300, cwd=tmp_path / "onnx")  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    episode = json.loads(ran.stdout.strip().splitlines()[-1])
    assert 1 <= episode["steps"] <= 30 and episode["success"] in (0.0, 1.0)


def test_explore_plays_an_episode_of_the_maze(maze_run):
    with explorer(maze_run) as (url, process):
        status, run = get(url + "api/run")
        assert status == 200 and not run["map"] and "dtd heatmap" in run["no_map_reason"]
        status, episode = get(url + "api/episode", json.dumps({"epoch": 2}).encode())
        assert status == 200, episode
        assert 1 <= episode["plan"]["steps"] <= 30
        process.terminate()
