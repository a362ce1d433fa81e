"""Bad input: one clear line on stderr, exit status 2, no traceback, nothing on disk destroyed."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

from tests.helpers import TINY, dtd

pytestmark = pytest.mark.smoke


def tree_digest(root: Path) -> dict[str, str]:
    """Content hash of every file below ``root``."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in root.rglob("*")
        if p.is_file()
    }


def assert_refused(result, *needles: str) -> None:
    assert result.returncode == 2, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("dtd: error: ")
    for needle in needles:
        assert needle in lines[0]
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--env", "FetchPsh-v4"], ["unknown environment id 'FetchPsh-v4'", "did you mean FetchPush-v4"]),
        (["--env", "CartPole-v1"], ["not goal-conditioned"]),
        (["--env", "no_such_module:Thing-v0"], ["cannot import module 'no_such_module'"]),
        (["--env", "FetchReach-v4", "--actor-lr", "-0.001"], ["--actor-lr must be > 0"]),
        (["--env", "FetchReach-v4", "--epochs", "0"], ["--epochs must be at least 1"]),
        (["--env", "FetchReach-v4", "--buffer-size", "10"], ["--buffer-size must hold one episode"]),
        ([], ["--env is required"]),
    ],
)
def test_bad_training_settings(tmp_path, args, needles):
    result = dtd("train", *args, "--run-dir", tmp_path / "run", "--no-progress")
    assert_refused(result, *needles)
    assert not (tmp_path / "run").exists()


def test_an_existing_run_is_neither_overwritten_nor_mixed(reach_run):
    before = tree_digest(reach_run)
    result = dtd("train", "--env", "FetchReach-v4", *TINY, "--run-dir", reach_run)
    assert_refused(result, "already holds a run", "--resume", "--force")
    assert tree_digest(reach_run) == before


def test_force_replaces_an_existing_run(tmp_path, reach_run):
    run = tmp_path / "forced"
    shutil.copytree(reach_run, run)
    result = dtd("train", "--env", "FetchReach-v4", "--epochs", "1", *TINY, "--run-dir", run, "--force")
    assert result.returncode == 0, result.stderr
    assert len((run / "metrics.csv").read_text().strip().splitlines()) == 2  # header + 1 epoch


def test_resume_refuses_to_change_the_run(reach_run):
    before = tree_digest(reach_run)
    assert_refused(dtd("train", "--resume", reach_run, "--seed", "99"), "--seed cannot change")
    assert tree_digest(reach_run) == before


def test_missing_run_and_missing_checkpoint(tmp_path, reach_run):
    assert_refused(dtd("eval", tmp_path / "nothing"), "no run in")
    assert_refused(dtd("train", "--resume", tmp_path / "nothing"), "no run in")
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(reach_run / "config.json", bare / "config.json")
    assert_refused(dtd("eval", bare), "no checkpoint at")
    assert_refused(dtd("eval", reach_run, "--checkpoint", tmp_path / "nope.pt"), "no checkpoint at")


def test_corrupt_checkpoint(tmp_path, reach_run):
    run = tmp_path / "corrupt"
    shutil.copytree(reach_run, run)
    latest = run / "checkpoints" / "latest.pt"
    latest.write_bytes(latest.read_bytes()[: latest.stat().st_size // 2])
    before = tree_digest(run)
    assert_refused(dtd("eval", run), "corrupt")
    assert_refused(dtd("train", "--resume", run), "corrupt")
    assert tree_digest(run) == before


def test_checkpoint_from_another_environment(tmp_path, reach_run):
    push = tmp_path / "push"
    result = dtd("train", "--env", "FetchPush-v4", "--epochs", "1", "--seed", "7", *TINY, "--run-dir", push)
    assert result.returncode == 0, result.stderr
    foreign = push / "checkpoints" / "latest.pt"
    assert_refused(dtd("eval", reach_run, "--checkpoint", foreign), "FetchPush-v4", "FetchReach-v4")

    run = tmp_path / "mixed"
    shutil.copytree(reach_run, run)
    shutil.copy(foreign, run / "checkpoints" / "latest.pt")
    before = tree_digest(run)
    assert_refused(dtd("train", "--resume", run, "--epochs", "5"), "belongs to a her run on FetchPush-v4")
    assert tree_digest(run) == before


def test_bad_eval_settings(reach_run):
    assert_refused(dtd("eval", reach_run, "--episodes", "0"), "--episodes must be at least 1")


def test_checkpoint_that_does_not_fit_the_agent(tmp_path, reach_run):
    import torch

    run = tmp_path / "misfit"
    shutil.copytree(reach_run, run)
    latest = run / "checkpoints" / "latest.pt"
    state = torch.load(latest, weights_only=True)
    del state["agent"]["learner"]["actor"]
    torch.save(state, latest)
    before = tree_digest(run)
    assert_refused(dtd("eval", run), "does not fit this run")
    assert_refused(dtd("train", "--resume", run, "--epochs", "5"), "does not fit this run")
    assert tree_digest(run) == before


def test_a_sweep_refused_leaves_no_directory(tmp_path):
    out = tmp_path / "sweep"
    result = dtd("sweep", "--env", "FetchReach-v4", "--algos", "her", *TINY, "--parallel", "-1", "--out", out)
    assert_refused(result, "--parallel must be 0 (one per core) or more, got -1")
    assert not out.exists()
