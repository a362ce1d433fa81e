"""Faults of the machine and of the run directory: a second trainer, a lock left by a killed
one, a full disk, unwritable and read-only paths, a config.json with a value of the wrong type,
an interrupted run, a run resumed after its end. Each is one line on stderr, and nothing
written before is lost."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dtd.cli import main
from dtd.training import atomic, run_lock
from dtd.training.checkpoint import load_checkpoint
from dtd.training.run_lock import LOCK_NAME
from tests.helpers import TINY, dtd, read_metrics, read_only

pytestmark = pytest.mark.smoke


def one_error_line(result: subprocess.CompletedProcess[str], code: int, *needles: str) -> str:
    assert result.returncode == code, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dtd: error: "), result.stderr
    assert "Traceback" not in result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def start_training(run: Path, *extra: str) -> subprocess.Popen[str]:
    """A trainer in the background that takes long enough to be caught in the act."""
    command = [sys.executable, "-m", "dtd", "train", "--env", "FetchReach-v4", "--epochs", "100000", *TINY]
    # Epoch lines go nowhere: a pipe nobody reads would fill and stop the trainer.
    command += ["--run-dir", str(run), *extra]
    process = subprocess.Popen(
        command,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        # Ctrl-C as in a terminal: a shell that started these tests in the background may
        # have left SIGINT ignored, and Python then never raises KeyboardInterrupt.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 600  # a guard against a hang, not a measure of speed
    while not (run / "metrics.csv").exists():  # past its set-up, into its epochs
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the trainer did not finish an epoch in time"
        time.sleep(0.2)
    return process


def test_a_second_trainer_on_a_run_is_refused_naming_the_first(tmp_path):
    run = tmp_path / "run"
    first = start_training(run)
    try:
        line = one_error_line(dtd("train", "--resume", run, "--epochs", "60"), 2, "being trained by process")
        assert str(first.pid) in line
        forced = dtd("train", "--env", "FetchReach-v4", *TINY, "--run-dir", run, "--force")
        one_error_line(forced, 2, f"process {first.pid}")
        # Readers still work while it trains.
        assert dtd("eval", run, "--episodes", "1").returncode == 0
    finally:
        first.send_signal(signal.SIGINT)
        _, stderr = first.communicate(timeout=60)
    assert first.returncode == 130
    assert f"continue with dtd train --resume {run}" in stderr
    assert not (run / LOCK_NAME).exists()


def test_a_lock_left_by_a_killed_trainer_does_not_block(tmp_path):
    run = tmp_path / "run"
    trainer = start_training(run)
    trainer.kill()
    trainer.wait()
    assert (run / LOCK_NAME).read_text().strip() == str(trainer.pid)  # left behind
    result = dtd("train", "--resume", run, "--epochs", str(len(read_metrics(run)) + 1))
    assert result.returncode == 0, result.stderr
    assert not (run / LOCK_NAME).exists()


def full_disk_on(name: str):
    """A writer for atomic writes that fails as a full disk does on files called ``name``."""
    real = atomic.open_for_writing

    class Full:
        def __init__(self, file):
            self.file = file

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __getattr__(self, attribute):
            return getattr(self.file, attribute)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.file.close()

    def opened(path: Path):
        file = real(path)
        return Full(file) if path.name.startswith(f".{name}.") else file

    return opened


def test_a_full_disk_is_one_line_and_the_last_checkpoint_stays(tmp_path, monkeypatch, capsys):
    run = tmp_path / "run"
    main(["train", "--env", "FetchReach-v4", "--epochs", "1", *TINY, "--run-dir", str(run)])
    capsys.readouterr()
    checkpoint_before = (run / "checkpoints" / "latest.pt").read_bytes()
    monkeypatch.setattr(atomic, "open_for_writing", full_disk_on("latest.pt"))
    with pytest.raises(SystemExit) as exited:
        main(["train", "--resume", str(run), "--epochs", "2", "--no-progress"])
    assert exited.value.code == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"dtd: error: no space left on device writing {run / 'checkpoints' / 'latest.pt'}"]
    assert (run / "checkpoints" / "latest.pt").read_bytes() == checkpoint_before
    assert len(read_metrics(run)) == 1
    assert not list((run / "checkpoints").glob(".*.tmp")) and not (run / LOCK_NAME).exists()

    monkeypatch.undo()
    main(["train", "--resume", str(run), "--epochs", "2", "--no-progress"])
    assert [int(row["epoch"]) for row in read_metrics(run)] == [1, 2]
    assert load_checkpoint(run / "checkpoints" / "latest.pt")["state"]["epoch"] == 2


def test_a_disk_full_before_the_run_starts_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    def full(fd, data, offset):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(run_lock.os, "pwrite", full)
    run = tmp_path / "run"
    with pytest.raises(SystemExit) as exited:
        main(["train", "--env", "FetchReach-v4", "--epochs", "1", *TINY, "--run-dir", str(run)])
    assert exited.value.code == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"dtd: error: no space left on device writing {run / LOCK_NAME}"]
    assert not run.exists()


def test_a_run_directory_that_cannot_be_written_is_refused_before_set_up(tmp_path):
    one_error_line(
        dtd("train", "--env", "FetchReach-v4", *TINY, "--run-dir", "/proc/no-such/run"),
        2,
        "cannot write to the run directory /proc/no-such/run",
    )
    blocked = tmp_path / "file"
    blocked.write_text("")
    inside_a_file = dtd("train", "--env", "FetchReach-v4", *TINY, "--run-dir", blocked / "run")
    one_error_line(inside_a_file, 2, "cannot write")
    one_error_line(dtd("sweep", "--env", "FetchReach-v4", "--out", blocked / "sweep"), 2, "cannot write")


def test_a_read_only_run_refuses_resume_and_report_in_one_line(tmp_path, reach_run):
    run = shutil.copytree(reach_run, tmp_path / "run")
    with read_only(run):
        resumed = dtd("train", "--resume", run, "--epochs", "5")
        one_error_line(resumed, 2, f"cannot write to the run directory {run}")
        one_error_line(dtd("report", run), 2, f"cannot write the report into {run}")
        one_error_line(dtd("render", run), 2, "cannot write rendered episodes")
        one_error_line(
            dtd("train", "--env", "FetchReach-v4", *TINY, "--run-dir", run / "inner"), 2, "cannot write"
        )
        assert dtd("eval", run, "--episodes", "1").returncode == 0  # reading needs no writing


@pytest.mark.parametrize("command", ["train --resume", "eval"])
def test_a_config_value_of_the_wrong_type_is_one_line(tmp_path, reach_run, command):
    run = shutil.copytree(reach_run, tmp_path / "run")
    payload = json.loads((run / "config.json").read_text())
    payload["config"]["epochs"] = "three"
    (run / "config.json").write_text(json.dumps(payload))
    one_error_line(dtd(*command.split(), run), 2, "config.json", "epochs must be an integer, got 'three'")


def test_resuming_a_finished_run_says_so_and_writes_nothing(tmp_path, reach_run):
    run = shutil.copytree(reach_run, tmp_path / "run")
    before = {path: path.stat().st_mtime_ns for path in run.rglob("*")}
    result = dtd("train", "--resume", run)
    assert result.returncode == 0, result.stderr
    assert "has already trained 3 epochs; nothing to do" in result.stderr
    assert json.loads(result.stdout)["epochs"] == 3
    assert {path: path.stat().st_mtime_ns for path in run.rglob("*")} == before


def test_an_unknown_checkpoint_name_lists_the_names(reach_run):
    one_error_line(dtd("eval", reach_run, "--checkpoint", "nosuch"), 2, "latest, best, first")


def train_on_test_env(env_id: str, run_dir: Path, *options: str) -> subprocess.CompletedProcess[str]:
    """`dtd train` on an environment of tests/goal_envs.py (importable from the repository)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[3])}
    command = [
        sys.executable,
        "-m",
        "dtd",
        "train",
        "--env",
        f"tests.goal_envs:{env_id}",
        "--epochs",
        "1",
        *TINY,
        *options,
    ]
    return subprocess.run([*command, "--run-dir", str(run_dir)], capture_output=True, text=True, env=env)


@pytest.mark.parametrize("collector", ["inline", "process"])
def test_an_episode_ended_for_another_reason_than_its_goal_is_refused_in_one_line(tmp_path, collector):
    # The same line and exit status whether episodes are collected inline or in a process.
    ended = train_on_test_env("PointGoalTerminating-v0", tmp_path / "ended", "--collector", collector)
    one_error_line(ended, 2, "ended an episode at step 4 of 10 for another reason than reaching its goal")
    assert "Traceback" not in ended.stderr and "collecting process" not in ended.stderr


def test_a_task_without_compute_terminated_that_runs_on_after_success_is_refused(tmp_path):
    # Without compute_terminated a task is taken to end its episodes on success; one that does
    # not is told how to say so.
    one_error_line(
        train_on_test_env("PointGoalUndeclared-v0", tmp_path / "undeclared", "--n-cycles", "10"),
        2,
        "did not end an episode at step",
        "returns False",
    )


def test_an_environment_that_reports_no_success_is_refused(tmp_path):
    one_error_line(
        train_on_test_env("PointGoalNoSuccess-v0", tmp_path / "silent"),
        2,
        "does not report info['is_success'] (or info['success'])",
    )
    assert not (tmp_path / "silent").exists()
    fine = train_on_test_env("PointGoal-v0", tmp_path / "fine")
    assert fine.returncode == 0, fine.stderr
