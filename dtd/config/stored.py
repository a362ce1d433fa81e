"""Settings as a run stores them in config.json: the format written now, and one step of
migration from each older format to the next."""

from __future__ import annotations

from typing import Any

from dtd.config.settings import DOT_TO_DOT_FIELDS, TrainConfig
from dtd.errors import ConfigError

SETTINGS_BEFORE_THEIR_KEY = {"n_step": 1, "explore_snapshots": 0, "precision": "float32"}
"""Settings whose default changed after runs were written without them: a ``config.json``
without the key was written when the run used this value."""

CONFIG_FORMAT = 2
"""The format of the settings a run writes (config.json's ``format``). Format 1 is every
config.json written before the key existed."""


def read_settings(data: Any, version: int = 1) -> TrainConfig:
    """Settings a run stored in format ``version``, brought to :data:`CONFIG_FORMAT` one step at
    a time, then read as :meth:`TrainConfig.from_dict` reads them."""
    if not isinstance(version, int) or not 1 <= version <= CONFIG_FORMAT:
        raise ConfigError(
            f"settings of format {version!r}; this dtd reads formats 1 to {CONFIG_FORMAT} "
            "(a newer dtd wrote them?)"
        )
    for step in range(version, CONFIG_FORMAT):
        data = MIGRATIONS[step](data)
    return TrainConfig.from_dict(data)


def _from_format_1(data: Any) -> Any:
    """Format 1 to 2: a key the run did not write takes the value runs used before it existed
    (:data:`SETTINGS_BEFORE_THEIR_KEY`), a batch or n-step of 0 (an earlier "the algorithm's")
    is unset, and Dot-to-Dot's settings written among the others go under ``dtd``."""
    if not isinstance(data, dict):
        return data
    return _grouped(_unset_zeros({**SETTINGS_BEFORE_THEIR_KEY, **data}))


MIGRATIONS = {1: _from_format_1}
"""Each older format's step to the next."""


def _unset_zeros(data: dict[str, Any]) -> dict[str, Any]:
    """Configuration data with the algorithm's batch and n-step unset where an earlier dtd wrote
    0 for them."""
    learner = data.get("learner")
    if isinstance(learner, dict) and learner.get("batch_size") == 0:
        data = {**data, "learner": {**learner, "batch_size": None}}
    return {**data, "n_step": None} if data.get("n_step") == 0 else data


def _grouped(data: dict[str, Any]) -> dict[str, Any]:
    """Configuration data with Dot-to-Dot's settings under ``dtd``, where a run written before
    they were grouped has them among the others."""
    flat = {name: data[name] for name in DOT_TO_DOT_FIELDS if name in data}
    if not flat:
        return data
    rest = {name: value for name, value in data.items() if name not in flat}
    group = rest.get("dtd", {})
    return {**rest, "dtd": {**flat, **group} if isinstance(group, dict) else group}
