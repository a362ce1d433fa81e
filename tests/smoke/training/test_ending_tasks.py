"""Tasks of other suites' mould (tests/goal_envs.py): episodes that end when the goal is reached,
0/1 and dense rewards, and constructor arguments that cannot work."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers import TINY, dtd, read_metrics

pytestmark = pytest.mark.smoke

ENDING = "tests.goal_envs:PointGoalEndsOnSuccess-v0"


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
