"""Presets and settings by name: the reference (paper) settings, ``NAME=VALUE`` overrides, the
flat view of a configuration by option names, and the algorithm's choices written in."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from typing import Any

from dtd.config.settings import (
    DOT_TO_DOT_FIELDS,
    HighTarget,
    LearnerConfig,
    Precision,
    Preset,
    RelabelWindow,
    TrainConfig,
)
from dtd.errors import ConfigError


def with_algorithm_defaults(config: TrainConfig) -> TrainConfig:
    """``config`` with what its algorithm chooses where it is unset written in
    (:attr:`TrainConfig.low_learner`, :attr:`TrainConfig.low_n_step`): the settings by which two
    runs are compared, one that left a choice to the algorithm and one that gave it alike."""
    return dataclasses.replace(config, learner=config.low_learner, n_step=config.low_n_step)


def flat_items(config: TrainConfig) -> dict[str, Any]:
    """Settings keyed by their option names without dashes: the low level's learner settings
    and Dot-to-Dot's unprefixed, the high level's as ``high.<name>``."""
    flat = config.to_dict()
    flat.update(flat.pop("learner"))
    flat.update(flat.pop("dtd"))
    flat.update({f"high.{name}": value for name, value in flat.pop("high").items()})
    return flat


def settings_apart(config: TrainConfig, other: TrainConfig) -> set[str]:
    """The settings (by their names in :func:`flat_items`) whose values differ between ``config``
    and ``other``."""
    theirs = flat_items(other)
    return {name for name, value in flat_items(config).items() if value != theirs[name]}


TUNED = TrainConfig()
"""The defaults: the reference settings except where docs/tuning.md measured better."""

_REFERENCE_LEARNER = dict(
    hidden_sizes=(256, 256, 256),
    layer_norm=False,
    actor_lr=1e-3,
    critic_lr=1e-3,
    batch_size=256,
    polyak=0.95,
    action_l2=1.0,
    gamma=None,
    clip_return=True,
    norm_clip=5.0,
    obs_clip=200.0,
    norm_eps=0.01,
    xavier_init=True,
    actor_after_critic=False,
)

PAPER = dataclasses.replace(
    TUNED,
    preset=Preset.paper,
    n_cycles=50,
    episodes_per_cycle=2,
    updates_per_cycle=40,
    test_episodes=10,
    buffer_size=1_000_000,
    replay_k=4,
    past_goal_share=0.0,
    n_step=1,
    noise_eps=0.2,
    random_eps=0.3,
    collect_ahead=False,
    precision=Precision.float32,
    learner=dataclasses.replace(TUNED.learner, **_REFERENCE_LEARNER),
    dtd=dataclasses.replace(
        TUNED.dtd,
        segments=2,
        subgoal_sigma=0.05,
        # Dot-to-Dot as the paper describes it: near goals for the low level, both levels
        # updated alike in each training phase.
        low_relabel_window=RelabelWindow.segment,
        high_updates_per_cycle=40,
        high_target=HighTarget.bootstrap,
        high_actor_last_segment=True,
        high=dataclasses.replace(TUNED.dtd.high, xavier_init=True, actor_after_critic=False),
    ),
)
"""The reference settings (OpenAI baselines' HER, which the paper keeps): its hyperparameters,
initialisation, update order and collection after the updates. One difference stays: one
worker, where the reference averaged 19."""

PRESETS = {Preset.tuned: TUNED, Preset.paper: PAPER}


def preset_config(preset: Preset, **settings: Any) -> TrainConfig:
    """The configuration ``preset`` starts from, with ``settings`` (fields) on top."""
    return dataclasses.replace(PRESETS[preset], **settings)


LEARNER_FIELDS = frozenset(field.name for field in dataclasses.fields(LearnerConfig))


def setting_path(name: str) -> str:
    """A setting's dotted path in the configuration's data, from its name as its option has
    it: the low level's learner settings (``batch_size``, ``learner``) under ``learner.``,
    Dot-to-Dot's (``segments``, ``high.batch_size``) under ``dtd.``."""
    if "." not in name and name in LEARNER_FIELDS:
        return f"learner.{name}"
    if name.split(".")[0] in DOT_TO_DOT_FIELDS:
        return f"dtd.{name}"
    return name


def with_settings(config: TrainConfig, settings: Sequence[str]) -> TrainConfig:
    """``config`` with ``NAME=VALUE`` settings applied: NAME is a field of TrainConfig, a
    learner's as ``learner.<name>`` or ``high.<name>`` (the low level's also by its option's
    name alone, e.g. ``batch_size``, ``learner`` for its kind), VALUE is JSON, or else a string."""
    data = config.to_dict()
    for setting in settings:
        name, equals, value = setting.partition("=")
        if not equals or not name:
            raise ConfigError(f"a setting is NAME=VALUE, got {setting!r}")
        *parents, leaf = setting_path(name.replace("-", "_")).split(".")
        target = data
        for parent in parents:
            if not isinstance(target.get(parent), dict):
                raise ConfigError(f"unknown setting {name!r}")
            target = target[parent]
        if leaf not in target:
            raise ConfigError(f"unknown setting {name!r}")
        try:
            target[leaf] = json.loads(value)
        except json.JSONDecodeError:
            target[leaf] = value
    return TrainConfig.from_dict(data)  # a 0 given is a 0, refused as its option is
