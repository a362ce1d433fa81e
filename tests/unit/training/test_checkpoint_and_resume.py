"""Checkpoint files that cannot be read; what a resumed run keeps and may change; the thread
count and collector chosen for the machine."""

import dataclasses

import pytest
import torch

from dtd.config import Collection, Preset, TrainConfig, preset_config
from dtd.errors import CheckpointError, ConfigError
from dtd.training import components
from dtd.training.checkpoint import FORMAT_VERSION, load_checkpoint, save_atomic
from dtd.training.lifecycle import resumed_config

VALID = TrainConfig(env="FetchReach-v4")


def test_checkpoint_round_trip_and_errors(tmp_path):
    path = tmp_path / "c.pt"
    save_atomic(path, {"x": torch.arange(3), "n": 5})
    state = load_checkpoint(path)
    assert state["n"] == 5 and state["format_version"] == FORMAT_VERSION
    assert [p.name for p in tmp_path.iterdir()] == ["c.pt"]  # no temporary file left

    with pytest.raises(CheckpointError, match="no checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")
    path.write_bytes(path.read_bytes()[:50])
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(path)
    torch.save({"format_version": 99}, path)
    with pytest.raises(CheckpointError, match="format version 99"):
        load_checkpoint(path)


def test_resume_takes_the_stored_settings_and_allows_more_epochs():
    stored = dataclasses.replace(VALID, seed=3, n_cycles=7)
    given = TrainConfig(epochs=80)
    assert resumed_config(stored, given) == dataclasses.replace(stored, epochs=80)
    assert resumed_config(stored, TrainConfig(env="FetchReach-v4", seed=3)) == stored
    with pytest.raises(ConfigError, match="--seed cannot change"):
        resumed_config(stored, TrainConfig(seed=4))


def test_resuming_keeps_the_runs_preset():
    paper = preset_config(Preset.paper, env="FetchReach-v4")
    # `dtd train --resume RUN --epochs 80`: given = the tuned defaults with more epochs
    resumed = resumed_config(paper, dataclasses.replace(TrainConfig(), epochs=80))
    assert resumed == dataclasses.replace(paper, epochs=80)
    # `--resume RUN --preset paper --epochs 80` says the same
    assert resumed_config(paper, preset_config(Preset.paper, epochs=80)) == resumed
    with pytest.raises(ConfigError, match="--preset"):
        resumed_config(TrainConfig(env="FetchReach-v4"), preset_config(Preset.paper))


@pytest.mark.parametrize(
    ("cores", "threads", "collector", "expected"),
    [(1, 1, "auto", "inline"), (2, 1, "auto", "process"), (2, 2, "auto", "inline"),
     (16, 4, "auto", "process"), (8, 1, "inline", "inline"), (1, 1, "process", "process")],
)  # fmt: skip
def test_episodes_are_collected_beside_the_learner_where_a_core_is_free(
    monkeypatch, cores, threads, collector, expected
):
    monkeypatch.setattr(components, "usable_cores", lambda: cores)
    assert components.resolved_collection(Collection(collector), threads).value == expected


def test_one_torch_thread_unless_asked_for_more(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    # However many cores the process may use (as usable_cores asks the system).
    monkeypatch.setattr(components.os, "sched_getaffinity", lambda _: set(range(16)), raising=False)
    monkeypatch.setattr(components.os, "cpu_count", lambda: 16)
    assert components.usable_cores() == 16
    assert components.resolved_threads(0) == 1
    assert components.resolved_threads(3) == 3  # given threads are kept
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert components.resolved_threads(0) == 2  # the user's OpenMP setting is kept
    assert components.resolved_threads(3) == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "many")
    assert components.resolved_threads(0) == 1
