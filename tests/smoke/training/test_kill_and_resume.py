"""kill -9 at any moment of training, then --resume: as if the run had never stopped."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import TINY, dtd, read_metrics, without_times

pytestmark = pytest.mark.smoke

ARGS = ["--env", "FetchReach-v4", "--epochs", "5", "--seed", "3", *TINY]


def start(run_dir: Path, algo: str = "her") -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "dtd", "train", *ARGS, "--algo", algo, "--run-dir", str(run_dir)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def finished_epochs(run_dir: Path) -> int:
    try:
        return len((run_dir / "metrics.csv").read_text().strip().splitlines()) - 1
    except FileNotFoundError:
        return 0


def kill_when(process: subprocess.Popen[bytes], ready, extra_delay: float) -> None:
    deadline = time.monotonic() + 240
    while not ready():
        assert process.poll() is None, "training ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.01)
    time.sleep(extra_delay)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[dict[str, str]]]:
    reference = {}
    for algo in ("her", "dtd"):
        run_dir = tmp_path_factory.mktemp("kill") / algo
        assert dtd("train", *ARGS, "--algo", algo, "--run-dir", run_dir).returncode == 0
        reference[algo] = without_times(read_metrics(run_dir))
    return reference


@pytest.mark.parametrize(
    ("algo", "label", "ready_epochs", "extra_delay"),
    [
        ("her", "during the first epoch", 0, 0.1),
        ("her", "after two epochs", 2, 0.0),
        ("her", "a moment later", 2, 0.4),
        ("dtd", "a moment later", 2, 0.3),
    ],
)
def test_resume_after_kill_9_matches_an_uninterrupted_run(
    tmp_path, uninterrupted, algo, label, ready_epochs, extra_delay
):
    run_dir = tmp_path / "run"
    process = start(run_dir, algo)
    if ready_epochs:
        kill_when(process, lambda: finished_epochs(run_dir) >= ready_epochs, extra_delay)
    else:
        kill_when(process, lambda: (run_dir / "config.json").exists(), extra_delay)
    assert process.returncode == -signal.SIGKILL, label
    killed_at = finished_epochs(run_dir)
    assert killed_at < 5, "the run finished before the kill"

    result = dtd("train", "--resume", run_dir, "--no-progress")
    assert result.returncode == 0, result.stderr
    assert without_times(read_metrics(run_dir)) == uninterrupted[algo]
    assert not list(run_dir.rglob("*.tmp"))
