"""Every command on a task of another suite that ends an episode on reaching its goal:
Gymnasium-Robotics' PointMaze with continuing_task=False, its constructor's arguments given with
--env-kwargs."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import TINY, dtd, read_metrics
from tests.smoke.explain.test_explore import explorer, get

pytestmark = pytest.mark.smoke

MAZE = ["--env", "PointMaze_UMaze-v3", "--env-kwargs", "continuing_task=False", "max_episode_steps=30"]


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
        assert run["legend"] == "red = goal, blue = current sub-goal"
        status, episode = get(url + "api/episode", json.dumps({"epoch": 2}).encode())
        assert status == 200, episode
        assert 1 <= episode["plan"]["steps"] <= 30
        process.terminate()
