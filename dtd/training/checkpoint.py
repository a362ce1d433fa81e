"""Checkpoints as plain data, written atomically: a crash leaves the old file or the new one."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch

from dtd.config import TrainConfig
from dtd.envs.spec import EnvSpec
from dtd.errors import CheckpointError
from dtd.training.atomic import write_atomic

# 2: learners save their action head (motor commands or sub-goals) apart from the actor.
# 3: exploration draws from a generator of its own, saved with the collector's environments.
FORMAT_VERSION = 3
READABLE_VERSIONS = frozenset({2, 3})
"""Versions whose agents load; a run resumes only from the current version."""


def save_atomic(path: Path, state: dict[str, Any]) -> None:
    """Write ``state`` (plus the format version) to ``path`` atomically."""
    write_atomic(path, lambda file: torch.save({"format_version": FORMAT_VERSION, **state}, file))


def load_checkpoint(path: Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save_atomic`, or raise :class:`CheckpointError`."""
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {path}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise CheckpointError(f"checkpoint {path} is corrupt or unreadable ({type(exc).__name__})") from exc
    if not isinstance(state, dict) or "format_version" not in state:
        raise CheckpointError(f"{path} is not a dtd checkpoint")
    if state["format_version"] not in READABLE_VERSIONS:
        raise CheckpointError(
            f"checkpoint {path} has format version {state['format_version']}; "
            f"this dtd reads versions {', '.join(map(str, sorted(READABLE_VERSIONS)))}"
        )
    return state


@contextlib.contextmanager
def restoring(path: Path) -> Iterator[None]:
    """Report a checkpoint whose contents do not fit what loads them as a :class:`CheckpointError`."""
    try:
        yield
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise CheckpointError(
            f"checkpoint {path} does not fit this run ({type(exc).__name__}: {exc})"
        ) from exc


def check_checkpoint(snapshot: dict[str, Any], config: TrainConfig, spec: EnvSpec, path: Path) -> None:
    """Refuse a checkpoint written for another environment or agent."""
    if snapshot.get("env_id") != config.env or snapshot.get("algo") != config.algo.value:
        raise CheckpointError(
            f"checkpoint {path} belongs to a {snapshot.get('algo')} run on {snapshot.get('env_id')}, "
            f"not to this {config.algo.value} run on {config.env}"
        )
    dims = ("obs_dim", "goal_dim", "action_dim", "horizon")
    stored = snapshot.get("spec") or {}
    if any(stored.get(name) != getattr(spec, name) for name in dims):
        raise CheckpointError(f"checkpoint {path} was written for an environment of other dimensions")
