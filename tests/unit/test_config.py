"""Configuration: defaults, validation, round trips, presets and settings by name."""

import dataclasses
import re

import pytest

from dtd.config import (
    CONFIG_FORMAT,
    Algo,
    DotToDotConfig,
    LearnerConfig,
    Preset,
    RelabelWindow,
    TrainConfig,
    flat_items,
    preset_config,
    read_settings,
    required_env,
    with_algorithm_defaults,
    with_settings,
)
from dtd.errors import ConfigError

VALID = TrainConfig(env="FetchReach-v4")


def test_defaults_are_the_reference_settings_but_where_tuned():
    c = TrainConfig()
    assert (c.n_cycles, c.episodes_per_cycle, c.updates_per_cycle, c.test_episodes) == (50, 2, 40, 10)
    assert (c.buffer_size, c.replay_k, c.noise_eps, c.random_eps) == (1_000_000, 4, 0.2, 0.3)
    learner = c.learner
    assert learner.hidden_sizes == (256, 256, 256) and learner.batch_size is None  # the algorithm's
    assert c.dtd.high.batch_size == 256
    assert (learner.actor_lr, learner.critic_lr, learner.polyak, learner.action_l2) == (1e-3, 1e-3, 0.95, 1.0)
    assert (learner.norm_clip, learner.obs_clip, learner.norm_eps) == (5.0, 200.0, 0.01)
    assert learner.gamma is None and learner.clip_return


@pytest.mark.parametrize(
    ("change", "flag"),
    [
        ({"epochs": 0}, "--epochs"),
        ({"n_cycles": -1}, "--n-cycles"),
        ({"random_eps": 1.5}, "--random-eps"),
        ({"learner": LearnerConfig(actor_lr=-1e-3)}, "--actor-lr"),
        ({"learner": LearnerConfig(gamma=1.5)}, "--gamma"),
        ({"learner": LearnerConfig(polyak=float("nan"))}, "--polyak"),
        ({"learner": LearnerConfig(hidden_sizes=(0,))}, "--hidden-sizes"),
    ],
)
def test_invalid_settings_name_their_option(change, flag):
    with pytest.raises(ConfigError, match=flag):
        dataclasses.replace(VALID, **change)


def test_a_run_needs_its_environment_given():
    assert TrainConfig().env is None  # the settings may leave it unset until a run starts
    with pytest.raises(ConfigError, match="--env is required"):
        required_env(None)
    with pytest.raises(ConfigError, match="--env must be given"):
        TrainConfig(env=" ")


def test_the_low_levels_batch_is_the_algorithms_unless_given():
    batch = {algo: TrainConfig(algo=algo).low_learner.batch_size for algo in Algo}
    assert batch == {Algo.her: 1024, Algo.ddpg: 1024, Algo.dtd: 256}
    given = TrainConfig(algo=Algo.dtd, learner=LearnerConfig(batch_size=512))
    assert given.low_learner == given.learner
    assert preset_config(Preset.paper, algo=Algo.her).low_learner.batch_size == 256
    assert TrainConfig(algo=Algo.dtd).dtd.high.batch_size == 256
    # Written in, the choices make a run that left them open equal to one that gave them.
    her = TrainConfig(algo=Algo.her)
    assert with_algorithm_defaults(her) == with_algorithm_defaults(
        TrainConfig(algo=Algo.her, n_step=1, learner=LearnerConfig(batch_size=1024))
    )
    assert with_algorithm_defaults(her) != her


def test_n_step_is_the_algorithms_unless_given_and_one_for_runs_written_before_it():
    n_step = {algo: TrainConfig(algo=algo).low_n_step for algo in Algo}
    assert n_step == {Algo.her: 1, Algo.ddpg: 1, Algo.dtd: 3}
    assert TrainConfig(algo=Algo.dtd, n_step=5).low_n_step == 5
    assert preset_config(Preset.paper, algo=Algo.dtd).low_n_step == 1
    written = TrainConfig(algo=Algo.dtd).to_dict()
    assert written["n_step"] is None and TrainConfig.from_dict(written).n_step is None
    # An earlier dtd wrote 0 for "the algorithm's" (format 1); given now, a 0 is a 0.
    assert read_settings({**written, "n_step": 0}, 1).n_step is None
    with pytest.raises(ConfigError, match="--n-step must be at least 1"):
        TrainConfig.from_dict({**written, "n_step": 0})
    old_learner = {**written["learner"], "batch_size": 0}
    assert read_settings({**written, "learner": old_learner}, 1).learner.batch_size is None
    del written["n_step"]  # a config.json from before the setting existed
    assert read_settings(written, 1).n_step == 1
    assert read_settings(written, CONFIG_FORMAT).n_step is None  # written now: the default
    with pytest.raises(ConfigError, match=r"--batch-size must be at least 1 \(left out: the algorithm's\)"):
        dataclasses.replace(VALID, learner=LearnerConfig(batch_size=0))
    with pytest.raises(ConfigError, match=r"--n-step must be at least 1 \(left out"):
        dataclasses.replace(VALID, n_step=0)
    with pytest.raises(ConfigError, match=r"--high\.batch-size must be at least 1, got None"):
        dataclasses.replace(VALID, dtd=DotToDotConfig(high=LearnerConfig(batch_size=None)))
    with pytest.raises(ConfigError, match=r"--high\.batch-size must be at least 1"):
        dataclasses.replace(VALID, dtd=DotToDotConfig(high=LearnerConfig(batch_size=0)))


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
    assert changed.dtd.high.polyak == 0.9 and changed.learner.polyak == VALID.learner.polyak
    assert changed.collector.value == "inline" and changed.env == VALID.env
    for bad in ("nope=1", "learner.nope=1", "updates_per_cycle", "epochs.x=1"):
        with pytest.raises(ConfigError):
            with_settings(VALID, [bad])


def test_paper_preset_is_the_reference_and_options_override_it():
    paper = preset_config(Preset.paper, env="FetchPush-v4", seed=3)
    assert (paper.preset, paper.env, paper.seed) == (Preset.paper, "FetchPush-v4", 3)
    assert (paper.n_cycles, paper.episodes_per_cycle, paper.updates_per_cycle) == (50, 2, 40)
    assert (paper.replay_k, paper.noise_eps, paper.random_eps, paper.buffer_size) == (4, 0.2, 0.3, 1_000_000)
    learner = paper.learner
    assert learner.hidden_sizes == (256, 256, 256) and learner.batch_size == 256
    assert (learner.actor_lr, learner.critic_lr, learner.polyak, learner.action_l2) == (1e-3, 1e-3, 0.95, 1.0)
    assert learner.gamma is None and learner.clip_return
    assert paper.dtd.low_relabel_window is RelabelWindow.segment and paper.dtd.high_updates_per_cycle == 40
    assert paper.dtd.subgoal_sigma == 0.05 and TrainConfig().dtd.subgoal_sigma == 0.1
    assert TrainConfig.from_dict(paper.to_dict()) == paper
    assert preset_config(Preset.tuned) == TrainConfig()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"epochs": "three"}, "epochs must be an integer, got 'three'"),
        ({"epochs": 2.5}, "epochs must be an integer, got 2.5"),
        ({"seed": True}, "seed must be an integer, got True"),
        ({"noise_eps": "0.2"}, "noise_eps must be a number, got '0.2'"),
        ({"env": 5}, "env must be a string, got 5"),
        ({"learner": {"hidden_sizes": [64, "wide"]}}, "learner.hidden_sizes must be a list of integers"),
        ({"dtd": {"high": {"clip_return": 1}}}, "high.clip_return must be true or false, got 1"),
        ({"learner": [1, 2]}, "learner must be a mapping of settings"),
        ({"algo": "ppo"}, "unknown algo 'ppo'"),
    ],
)
def test_a_stored_value_of_the_wrong_type_names_its_setting(data, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        TrainConfig.from_dict(data)


def test_stored_values_take_their_types():
    config = TrainConfig.from_dict({"noise_eps": 1, "learner": {"hidden_sizes": [64, 64], "gamma": None}})
    assert config.noise_eps == 1.0 and isinstance(config.noise_eps, float)
    assert config.learner.hidden_sizes == (64, 64) and config.learner.gamma is None
    assert config.learner.batch_size is None and config.dtd.high.batch_size == 256  # each level's defaults


def test_dot_to_dots_settings_are_one_group_read_also_from_runs_written_flat():
    config = dataclasses.replace(VALID, algo=Algo.dtd, dtd=DotToDotConfig(segments=3, high_replay_k=2))
    data = config.to_dict()
    assert data["dtd"]["segments"] == 3 and data["dtd"]["high"]["batch_size"] == 256
    assert "segments" not in data and "high" not in data
    assert TrainConfig.from_dict(data) == config
    # config.json of a run written before the settings were grouped: the same configuration.
    flat = {name: value for name, value in data.items() if name != "dtd"} | data["dtd"]
    assert read_settings(flat, 1) == config
    with pytest.raises(ConfigError, match=r"high\.batch_size must be an integer"):
        read_settings({**flat, "high": {**data["dtd"]["high"], "batch_size": "x"}}, 1)
    with pytest.raises(ConfigError, match="unknown setting"):
        read_settings(flat, CONFIG_FORMAT)  # written now, a flat setting is unknown
    with pytest.raises(ConfigError, match=r"unknown setting.*segmints"):
        TrainConfig.from_dict({**data, "dtd": {**data["dtd"], "segmints": 3}})
    # Option names stay as they were: no dtd. prefix anywhere a setting is named.
    flat_names = flat_items(config)
    assert flat_names["segments"] == 3 and flat_names["high.batch_size"] == 256 and "dtd" not in flat_names
    named = with_settings(config, ["segments=4", "high.batch_size=64", "high_target=observed"])
    assert (named.dtd.segments, named.dtd.high.batch_size) == (4, 64)
    assert named.dtd.high_target.value == "observed"
