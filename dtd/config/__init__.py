"""The one typed source of configuration: defaults, ``--help`` text and logged settings.

Every field's docstring is its help text on the command line. Facts that follow from the
environment (dimensions, horizon, the default discount) live in :class:`dtd.envs.spec.EnvSpec`
and are never written back here. This package imports nothing of dtd but its errors, so every
part of dtd may use it.
"""

from dtd.config.choices import (
    Algo,
    Collection,
    Device,
    HighTarget,
    LearnerKind,
    Precision,
    Preset,
    RelabelWindow,
)
from dtd.config.plain import plain_data
from dtd.config.presets import (
    PAPER,
    PRESETS,
    TUNED,
    flat_items,
    preset_config,
    settings_apart,
    with_algorithm_defaults,
    with_settings,
)
from dtd.config.settings import (
    EVAL_SEED,
    HIGH_LEVEL_DEFAULTS,
    LOW_LEVEL_BATCH,
    LOW_LEVEL_DEFAULTS,
    LOW_LEVEL_N_STEP,
    DotToDotConfig,
    LearnerConfig,
    TrainConfig,
)
from dtd.config.stored import CONFIG_FORMAT, read_settings
from dtd.config.validation import required_env

__all__ = [
    "CONFIG_FORMAT",
    "EVAL_SEED",
    "HIGH_LEVEL_DEFAULTS",
    "LOW_LEVEL_BATCH",
    "LOW_LEVEL_DEFAULTS",
    "LOW_LEVEL_N_STEP",
    "PAPER",
    "PRESETS",
    "TUNED",
    "Algo",
    "Collection",
    "Device",
    "DotToDotConfig",
    "HighTarget",
    "LearnerConfig",
    "LearnerKind",
    "Precision",
    "Preset",
    "RelabelWindow",
    "TrainConfig",
    "flat_items",
    "plain_data",
    "preset_config",
    "read_settings",
    "required_env",
    "settings_apart",
    "with_algorithm_defaults",
    "with_settings",
]
