"""Configuration validation and round trips; checkpoint files that cannot be read."""

import dataclasses

import pytest
import torch

from dtd import runs
from dtd.checkpoint import FORMAT_VERSION, load_checkpoint, save_atomic
from dtd.config import (
    Algo,
    Collection,
    LearnerConfig,
    Preset,
    RelabelWindow,
    TrainConfig,
    preset_config,
    with_algorithm_batch,
    with_settings,
)
from dtd.errors import CheckpointError, ConfigError
from dtd.runs import resumed_config

VALID = TrainConfig(env="FetchReach-v4")


def test_defaults_are_the_reference_settings_but_where_tuned():
    c = TrainConfig()
    assert (c.n_cycles, c.episodes_per_cycle, c.updates_per_cycle, c.test_episodes) == (50, 2, 40, 10)
    assert (c.buffer_size, c.replay_k, c.noise_eps, c.random_eps) == (1_000_000, 4, 0.2, 0.3)
    learner = c.learner
    assert learner.hidden_sizes == (256, 256, 256) and learner.batch_size == 0  # the algorithm's
    assert c.high.batch_size == 256
    assert (learner.actor_lr, learner.critic_lr, learner.polyak, learner.action_l2) == (1e-3, 1e-3, 0.95, 1.0)
    assert (learner.norm_clip, learner.obs_clip, learner.norm_eps) == (5.0, 200.0, 0.01)
    assert learner.gamma is None and learner.clip_return


@pytest.mark.parametrize(
    ("change", "flag"),
    [
        ({"epochs": 0}, "--epochs"),
        ({"n_cycles": -1}, "--n-cycles"),
        ({"random_eps": 1.5}, "--random-eps"),
        ({"env": None}, "--env"),
        ({"learner": LearnerConfig(actor_lr=-1e-3)}, "--actor-lr"),
        ({"learner": LearnerConfig(gamma=1.5)}, "--gamma"),
        ({"learner": LearnerConfig(polyak=float("nan"))}, "--polyak"),
        ({"learner": LearnerConfig(hidden_sizes=(0,))}, "--hidden-sizes"),
    ],
)
def test_invalid_settings_name_their_option(change, flag):
    with pytest.raises(ConfigError, match=flag):
        dataclasses.replace(VALID, **change).validate()


def test_the_low_levels_batch_is_the_algorithms_unless_given():
    batch = {algo: with_algorithm_batch(TrainConfig(algo=algo)).learner.batch_size for algo in Algo}
    assert batch == {Algo.her: 1024, Algo.ddpg: 1024, Algo.dtd: 256}
    given = TrainConfig(algo=Algo.dtd, learner=LearnerConfig(batch_size=512))
    assert with_algorithm_batch(given) == given
    assert with_algorithm_batch(preset_config(Preset.paper, algo=Algo.her)).learner.batch_size == 256
    assert with_algorithm_batch(TrainConfig(algo=Algo.dtd)).high.batch_size == 256
    with pytest.raises(ConfigError, match="--batch-size must be at least 0"):
        dataclasses.replace(VALID, learner=LearnerConfig(batch_size=-1)).validate()
    with pytest.raises(ConfigError, match=r"--high\.batch-size must be at least 1"):
        dataclasses.replace(VALID, high=LearnerConfig(batch_size=0)).validate()


def test_dict_round_trip():
    config = dataclasses.replace(VALID, algo=Algo.ddpg, learner=LearnerConfig(hidden_sizes=(64, 64)))
    assert TrainConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ConfigError, match="typo"):
        TrainConfig.from_dict({**config.to_dict(), "typo": 1})


def test_settings_by_name_reach_both_learners_and_unknown_names_are_refused():
    changed = with_settings(
        VALID, ["updates_per_cycle=80", "learner.batch_size=512", "high.polyak=0.9", "collector=inline"]
    )
    assert changed.updates_per_cycle == 80 and changed.learner.batch_size == 512
    assert changed.high.polyak == 0.9 and changed.learner.polyak == VALID.learner.polyak
    assert changed.collector.value == "inline" and changed.env == VALID.env
    for bad in ("nope=1", "learner.nope=1", "updates_per_cycle", "epochs.x=1"):
        with pytest.raises(ConfigError):
            with_settings(VALID, [bad])


def test_resume_takes_the_stored_settings_and_allows_more_epochs():
    stored = dataclasses.replace(VALID, seed=3, n_cycles=7)
    given = TrainConfig(epochs=80)
    assert resumed_config(stored, given) == dataclasses.replace(stored, epochs=80)
    assert resumed_config(stored, TrainConfig(env="FetchReach-v4", seed=3)) == stored
    with pytest.raises(ConfigError, match="--seed cannot change"):
        resumed_config(stored, TrainConfig(seed=4))


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


def test_paper_preset_is_the_reference_and_options_override_it():
    paper = preset_config(Preset.paper, env="FetchPush-v4", seed=3)
    assert (paper.preset, paper.env, paper.seed) == (Preset.paper, "FetchPush-v4", 3)
    assert (paper.n_cycles, paper.episodes_per_cycle, paper.updates_per_cycle) == (50, 2, 40)
    assert (paper.replay_k, paper.noise_eps, paper.random_eps, paper.buffer_size) == (4, 0.2, 0.3, 1_000_000)
    learner = paper.learner
    assert learner.hidden_sizes == (256, 256, 256) and learner.batch_size == 256
    assert (learner.actor_lr, learner.critic_lr, learner.polyak, learner.action_l2) == (1e-3, 1e-3, 0.95, 1.0)
    assert learner.gamma is None and learner.clip_return
    assert paper.low_relabel_window is RelabelWindow.segment and paper.high_updates_per_cycle == 40
    assert paper.subgoal_sigma == 0.05 and TrainConfig().subgoal_sigma == 0.1
    assert TrainConfig.from_dict(paper.to_dict()) == paper
    assert preset_config(Preset.tuned) == TrainConfig()


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
    monkeypatch.setattr(runs, "usable_cores", lambda: cores)
    collection = Collection(collector)
    assert (runs.resolved_threads(0, collection), runs.resolved_collection(collection).value) == expected
    assert runs.resolved_threads(3, collection) == 3  # given threads are kept
