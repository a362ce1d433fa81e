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
    ("cores", "collector", "expected"),
    [(1, "auto", (1, "inline")), (2, "auto", (2, "inline")), (3, "auto", (2, "process")),
     (16, "auto", (4, "process")), (2, "process", (1, "process")), (8, "inline", (4, "inline"))],
)  # fmt: skip
def test_automatic_threads_and_collector_fit_the_cores(monkeypatch, cores, collector, expected):
    monkeypatch.setattr(components, "usable_cores", lambda: cores)
    collection = Collection(collector)
    assert (
        components.resolved_threads(0, collection),
        components.resolved_collection(collection).value,
    ) == expected
    assert components.resolved_threads(3, collection) == 3  # given threads are kept
