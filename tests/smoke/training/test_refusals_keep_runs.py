"""A refused command changes nothing: a task refused at its first episode neither deletes the run
it was to replace (--force) nor leaves a half-made one; --resume takes every option typed, at its
default value too; SIGTERM stops training as Ctrl-C does; Dot-to-Dot's settings given to another
algorithm and the environment's arguments given twice are refused."""

from __future__ import annotations

import hashlib
import signal
from pathlib import Path

import pytest

from tests.helpers import TINY, dtd, read_metrics
from tests.smoke.training.test_faults import one_error_line, start_training

pytestmark = pytest.mark.smoke

REFUSED_TASK = "tests.goal_envs:PointGoalTerminating-v0"  # ends its episodes at step 4, goal or not


def fingerprint(run: Path) -> dict[str, str]:
    """Every file of a run directory and a digest of its bytes."""
    return {
        path.relative_to(run).as_posix(): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(run.rglob("*"))
        if path.is_file()
    }


def trained_run(tmp_path: Path, *extra: str) -> Path:
    run = tmp_path / "run"
    result = dtd("train", "--env", "FetchReach-v4", "--epochs", "1", *TINY, *extra, "--run-dir", run)
    assert result.returncode == 0, result.stderr
    return run


def test_a_task_refused_at_its_first_episode_does_not_delete_the_run_it_was_to_replace(tmp_path):
    run = trained_run(tmp_path)
    before = fingerprint(run)
    refused = dtd("train", "--env", REFUSED_TASK, "--epochs", "1", *TINY, "--force", "--run-dir", run)
    one_error_line(refused, 2, "ended an episode at step 4")
    assert fingerprint(run) == before
    assert sorted(path.name for path in run.iterdir()) == [
        "checkpoints",
        "config.json",
        "metrics.csv",
        "tensorboard",
    ]
    # The run is whole: it resumes.
    assert dtd("train", "--resume", run, "--epochs", "2").returncode == 0
    assert [row["epoch"] for row in read_metrics(run)] == ["1", "2"]
    # A forced start that gets through its first epoch replaces it, and keeps nothing of it.
    replaced = dtd(
        "train", "--env", "FetchReach-v4", "--seed", "3", "--epochs", "1", *TINY, "--force", "--run-dir", run
    )
    assert replaced.returncode == 0, replaced.stderr
    assert [row["epoch"] for row in read_metrics(run)] == ["1"]
    assert not (run / ".replaced").exists()


def test_a_task_refused_at_its_first_episode_leaves_no_run_behind(tmp_path):
    run = tmp_path / "runs" / "new"
    for _ in range(2):  # and so the same command again is refused for the same reason
        refused = dtd("train", "--env", REFUSED_TASK, "--epochs", "1", *TINY, "--run-dir", run)
        one_error_line(refused, 2, "ended an episode at step 4")
        assert not run.exists() and not run.parent.exists()


@pytest.mark.parametrize(
    ("given", "option"),
    [
        (["--learner", "ddpg"], "--learner"),
        (["--n-cycles", "50"], "--n-cycles"),
        (["--hidden-sizes", "256", "256", "256"], "--hidden-sizes"),
        (["--no-time-feature"], "--time-feature"),
        (["--algo", "dtd"], "--algo"),
    ],
)
def test_resume_refuses_an_option_given_at_its_default_that_is_not_the_runs(tmp_path, given, option):
    run = trained_run(tmp_path, "--learner", "tqc", "--time-feature")
    before = fingerprint(run)
    one_error_line(dtd("train", "--resume", run, *given), 2, f"{option} cannot change when resuming")
    assert fingerprint(run) == before


def test_resume_accepts_the_runs_own_values_given_again(tmp_path):
    run = trained_run(tmp_path, "--learner", "tqc", "--time-feature", "--env-kwargs", "reward_type=sparse")
    again = ["--learner", "tqc", "--time-feature", "--n-cycles", "2", "--hidden-sizes", "32", "32"]
    again += ["--algo", "her", "--env-kwargs", "reward_type='sparse'"]
    result = dtd("train", "--resume", run, *again, "--epochs", "2")
    assert result.returncode == 0, result.stderr
    assert [row["epoch"] for row in read_metrics(run)] == ["1", "2"]


def test_sigterm_stops_training_as_ctrl_c_does(tmp_path):
    run = tmp_path / "run"
    trainer = start_training(run)
    trainer.send_signal(signal.SIGTERM)
    _, stderr = trainer.communicate(timeout=120)
    assert trainer.returncode == 130, stderr
    assert stderr.strip().splitlines()[-1] == f"dtd: interrupted; continue with dtd train --resume {run}"
    assert "Traceback" not in stderr
    assert dtd("train", "--resume", run, "--epochs", str(len(read_metrics(run)) + 1)).returncode == 0


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (
            ["--algo", "her", "--high.learner", "tqc", "--segments", "3"],
            ["--high.learner, --segments", "--algo her"],
        ),
        (["--env-kwargs", "reward_type=sparse", "reward_type=dense"], ["gives reward_type twice"]),
        (["--env-kwargs", "junk=" + "x" * 100_000], ["junk='xxx", "(100,002 characters)"]),
    ],
)
def test_settings_that_would_mean_nothing_or_another_thing_are_refused_in_a_short_line(
    tmp_path, args, needles
):
    run = tmp_path / "run"
    result = dtd("train", "--env", "FetchReach-v4", "--epochs", "1", *TINY, *args, "--run-dir", run)
    line = one_error_line(result, 2, *needles)
    assert len(line) < 1000
    assert not run.exists()
