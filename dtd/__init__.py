"""dtd: train and explain hierarchical goal-conditioned agents (Dot-to-Dot, HER, DDPG).

The public API, for scripts and notebooks::

    from dtd import TrainConfig, Algo, train, evaluate_run, load_agent

    config = TrainConfig(env="FetchPush-v4", algo=Algo.dtd, epochs=40)
    state = train(config, run_dir="runs/push-dtd-0")
    figures = evaluate_run("runs/push-dtd-0", episodes=100)
    agent, env = load_agent("runs/push-dtd-0")

Names are imported when first used, so that ``import dtd`` (and the command line's help) does
not load torch or MuJoCo.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# Frames are drawn offscreen: without a display, MuJoCo is told to use EGL (set before MuJoCo
# is first imported; a MUJOCO_GL chosen by the user is kept).
if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    os.environ.setdefault("MUJOCO_GL", "egl")

_PUBLIC = {
    "Algo": "dtd.config",
    "DotToDotConfig": "dtd.config",
    "LearnerConfig": "dtd.config",
    "Preset": "dtd.config",
    "TrainConfig": "dtd.config",
    "preset_config": "dtd.config",
    "with_settings": "dtd.config",
    "DtdError": "dtd.errors",
    "TrainState": "dtd.training.checkpoint",
    "train": "dtd.training.lifecycle",
    "train_for_steps": "dtd.training.lifecycle",
    "LoadedRun": "dtd.training.trained_run",
    "evaluate_run": "dtd.training.trained_run",
    "load_agent": "dtd.training.trained_run",
    "load_run": "dtd.training.trained_run",
}

__all__ = [
    "Algo",
    "DotToDotConfig",
    "DtdError",
    "LearnerConfig",
    "LoadedRun",
    "Preset",
    "TrainConfig",
    "TrainState",
    "evaluate_run",
    "load_agent",
    "load_run",
    "preset_config",
    "train",
    "train_for_steps",
    "with_settings",
]

if TYPE_CHECKING:
    from dtd.config import (
        Algo,
        DotToDotConfig,
        LearnerConfig,
        Preset,
        TrainConfig,
        preset_config,
        with_settings,
    )
    from dtd.errors import DtdError
    from dtd.training.checkpoint import TrainState
    from dtd.training.lifecycle import train, train_for_steps
    from dtd.training.trained_run import LoadedRun, evaluate_run, load_agent, load_run


def __getattr__(name: str) -> Any:
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'dtd' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_PUBLIC])
