"""Fixtures shared by the test tiers."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import TINY, dtd


@pytest.fixture(scope="session")
def reach_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny HER run on FetchReach (3 epochs), shared by tests that only read it."""
    run_dir = tmp_path_factory.mktemp("runs") / "reach"
    result = dtd(
        "train", "--env", "FetchReach-v4", "--epochs", "3", "--seed", "7", *TINY, "--run-dir", run_dir
    )
    assert result.returncode == 0, result.stderr
    return run_dir


@pytest.fixture(scope="session")
def push_dtd_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny dtd run on FetchPush (2 epochs), shared by tests that only read it: it
    keeps checkpoints after epoch 1 and 2, and an agent-only snapshot of each."""
    run_dir = tmp_path_factory.mktemp("explain") / "push-dtd"
    args = ["train", "--env", "FetchPush-v4", "--algo", "dtd", "--epochs", "2", "--seed", "1", *TINY]
    result = dtd(*args, "--run-dir", run_dir)
    assert result.returncode == 0, result.stderr
    return run_dir
