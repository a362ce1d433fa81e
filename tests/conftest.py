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
