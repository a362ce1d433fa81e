"""Checkpoints as plain data, written atomically (a crash leaves the old file or the new one),
and read back as a typed :class:`Checkpoint`.

A run keeps two kinds: a whole checkpoint (latest.pt, best.pt, first.pt, a worker's shard),
from which training continues exactly, and an agent-only snapshot of an epoch (the networks
that act and the high level's critic, no optimiser, no replay), which ``dtd explore`` shows.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import torch

from dtd.agents.interface import Agent
from dtd.config import TrainConfig
from dtd.envs.spec import EnvSpec
from dtd.errors import CheckpointError
from dtd.training.atomic import write_atomic
from dtd.training.recorder import Row

# 2: learners save their action head (motor commands or sub-goals) apart from the actor.
# 3: exploration draws from a generator of its own, saved with the collector's environments.
FORMAT_VERSION = 3
READABLE_VERSIONS = frozenset({2, 3})
"""Versions whose agents load; a run resumes only from the current version."""


@dataclasses.dataclass
class TrainState:
    """Counters of a run, saved in every checkpoint."""

    epoch: int = 0
    """Epochs finished."""
    env_steps: int = 0
    updates: int = 0
    episodes: int = 0
    wall_s: float = 0.0
    best_eval_success: float = -1.0
    history: list[Row] = dataclasses.field(default_factory=list)


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """One checkpoint file's contents.

    ``counters`` are a whole checkpoint's :class:`TrainState` as plain data, or an agent-only
    snapshot's epoch, env steps and evaluation success; ``config`` and ``rng`` are a whole
    checkpoint's (None in a snapshot)."""

    env_id: str
    algo: str
    spec: Mapping[str, Any]
    """The :class:`EnvSpec` of the task it was trained on, as plain data."""
    counters: Mapping[str, Any]
    agent: Mapping[str, Any]
    """The agent's state: :meth:`Agent.state_dict` (whole) or :meth:`Agent.explaining_state`."""
    config: Mapping[str, Any] | None = None
    rng: Mapping[str, Any] | None = None
    """The random state of replay sampling, torch, the collector and the evaluation envs."""
    worker: int = 0
    """The data-parallel worker that wrote it."""
    format_version: int = FORMAT_VERSION

    @property
    def whole(self) -> bool:
        """Whether training can continue from it (an agent-only snapshot cannot)."""
        return self.rng is not None

    @property
    def epoch(self) -> int:
        return int(self.counters["epoch"])

    @property
    def env_steps(self) -> int:
        return int(self.counters.get("env_steps", -1))

    @property
    def eval_success(self) -> float | None:
        """The evaluation success of its epoch, where it records one."""
        if "eval_success" in self.counters:
            return self.counters["eval_success"]
        history = self.counters.get("history") or [{}]
        return history[-1].get("eval_success")

    def train_state(self) -> TrainState:
        """A whole checkpoint's counters."""
        return TrainState(**self.counters)

    def acting_agent_state(self) -> dict[str, Any]:
        """The agent's state without its replay: what acting and explaining need."""
        return {name: value for name, value in self.agent.items() if name != "buffer"}

    def load_agent(self, agent: Agent, path: Path) -> None:
        """Put this checkpoint's networks (not its replay) into ``agent``; a state that does
        not fit is a :class:`CheckpointError` naming ``path``."""
        with restoring(path):
            if self.whole:
                agent.load_state_dict(self.acting_agent_state())
            else:
                agent.load_explaining_state(dict(self.agent))

    def check_fits(self, config: TrainConfig, spec: EnvSpec, path: Path) -> None:
        """Refuse a checkpoint written for another environment or agent."""
        if self.env_id != config.env or self.algo != config.algo.value:
            raise CheckpointError(
                f"checkpoint {path} belongs to a {self.algo} run on {self.env_id}, "
                f"not to this {config.algo.value} run on {config.env}"
            )
        dims = ("obs_dim", "goal_dim", "action_dim", "horizon")
        if any(self.spec.get(name) != getattr(spec, name) for name in dims):
            raise CheckpointError(f"checkpoint {path} was written for an environment of other dimensions")

    def check_resumable(self, path: Path) -> None:
        """Refuse to continue training from a snapshot or from an older format."""
        if not self.whole:
            raise CheckpointError(f"{path} is an agent-only snapshot; training continues from latest.pt")
        if self.format_version != FORMAT_VERSION:
            raise CheckpointError(
                f"checkpoint {path} was written by an older dtd (format "
                f"{self.format_version}); it can be evaluated but not resumed"
            )

    def to_dict(self) -> dict[str, Any]:
        """The plain data saved (the file's keys since format 2)."""
        data: dict[str, Any] = {
            "env_id": self.env_id,
            "algo": self.algo,
            "spec": dict(self.spec),
            "state": dict(self.counters),
            "agent": dict(self.agent),
        }
        if self.whole:
            data |= {"config": self.config, "worker": self.worker, "rng": dict(self.rng or {})}
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], path: Path) -> Checkpoint:
        """Read what :meth:`to_dict` wrote (and the format version); a file lacking a part is a
        :class:`CheckpointError` naming ``path``."""
        try:
            return cls(
                env_id=data["env_id"],
                algo=data["algo"],
                spec=data.get("spec") or {},
                counters=data["state"],
                agent=data["agent"],
                config=data.get("config"),
                rng=data.get("rng"),
                worker=int(data.get("worker", 0)),
                format_version=int(data["format_version"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"checkpoint {path} lacks a part of a dtd checkpoint ({exc})") from exc

    def save(self, path: Path) -> None:
        """Write it to ``path`` atomically."""
        save_atomic(path, self.to_dict())

    @classmethod
    def read(cls, path: Path) -> Checkpoint:
        """The checkpoint at ``path``, or a :class:`CheckpointError` saying why it cannot be read."""
        return cls.from_dict(load_checkpoint(path), path)


def save_atomic(path: Path, state: Mapping[str, Any]) -> None:
    """Write ``state`` (plus the format version) to ``path`` atomically."""
    write_atomic(path, lambda file: torch.save({"format_version": FORMAT_VERSION, **state}, file))


def load_checkpoint(path: Path) -> dict[str, Any]:
    """The plain data :func:`save_atomic` wrote, or a :class:`CheckpointError`."""
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
