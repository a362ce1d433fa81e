"""The run directory: a contract between training and every tool that reads its results.

config.json            the settings as given (Dot-to-Dot's under "dtd"), what follows from them
                       and the task ("derived": the task's spec, the batch and n-step the
                       algorithm chose), package versions
metrics.csv            one row per finished epoch
eval-latest.json       the latest checkpoint's evaluation over many episodes, once saved
                       (dtd eval --save, dtd sweep --final-episodes): the run's final of record
tensorboard/           TensorBoard event files with the same figures
checkpoints/latest.pt  everything needed to resume, after the last finished epoch
checkpoints/best.pt    the agent with the best evaluation success (no replay)
checkpoints/first.pt   the agent after the first epoch (no replay), to compare with the last
checkpoints/epochs/    the agent alone (no replay, no optimiser) after epoch E
                       (epoch-E.pt), for dtd explore; see TrainConfig.explore_snapshots
checkpoints/workers/   with data-parallel workers: worker k's replay and random state after
                       epoch E (worker-k-epoch-E.pt); latest.pt is worker 0's
.replaced/             while a run started with --force has not finished its first epoch: the
                       run it replaces, put back if the new one stops before then
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
from collections.abc import Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

from dtd.config import CONFIG_FORMAT, TrainConfig, read_settings
from dtd.errors import ConfigError, RunDirError
from dtd.training.atomic import write_text_atomic

CHECKPOINT_NAMES = ("latest", "best", "first")
"""Checkpoints every run keeps: after the last epoch, of the best evaluation (the highest of
noisy evaluations over a few test episodes each: it flatters the agent), after the first."""

FINAL_EVALUATION = "eval-latest.json"
"""The saved evaluation of a run's latest checkpoint (``dtd eval --save``), its final of record."""

_VERSIONED = ("dtd", "torch", "numpy", "mujoco", "gymnasium", "gymnasium-robotics")


@dataclasses.dataclass(frozen=True)
class RunDir:
    """Paths inside one run directory."""

    root: Path

    @property
    def config(self) -> Path:
        return self.root / "config.json"

    @property
    def metrics(self) -> Path:
        return self.root / "metrics.csv"

    @property
    def final_evaluation(self) -> Path:
        return self.root / FINAL_EVALUATION

    @property
    def tensorboard(self) -> Path:
        return self.root / "tensorboard"

    @property
    def checkpoints(self) -> Path:
        return self.root / "checkpoints"

    @property
    def latest(self) -> Path:
        return self.checkpoints / "latest.pt"

    @property
    def best(self) -> Path:
        return self.checkpoints / "best.pt"

    @property
    def first(self) -> Path:
        return self.checkpoints / "first.pt"

    @property
    def epoch_snapshots_dir(self) -> Path:
        return self.checkpoints / "epochs"

    def epoch_snapshot(self, epoch: int) -> Path:
        """The agent-only snapshot kept after ``epoch``."""
        return self.epoch_snapshots_dir / f"epoch-{epoch}.pt"

    def epoch_snapshots(self) -> dict[int, Path]:
        """The agent-only snapshots there are now, by epoch (in order)."""
        found = {}
        for path in self.epoch_snapshots_dir.glob("epoch-*.pt"):
            number = path.stem.removeprefix("epoch-")
            if number.isdigit():
                found[int(number)] = path
        return dict(sorted(found.items()))

    def worker_shard(self, worker: int, epoch: int) -> Path:
        """Where data-parallel worker ``worker`` (> 0) keeps its state after ``epoch``."""
        return self.checkpoints / "workers" / f"worker-{worker}-epoch-{epoch}.pt"

    def remove_worker_shards(self, worker: int, keep_epoch: int) -> None:
        """Remove worker ``worker``'s shards of every epoch but ``keep_epoch``."""
        keep = self.worker_shard(worker, keep_epoch)
        for path in self.worker_shard(worker, 0).parent.glob(f"worker-{worker}-epoch-*.pt"):
            if path != keep:
                path.unlink(missing_ok=True)

    def holds_run(self) -> bool:
        """Whether a run has already started here."""
        return self.config.exists() or self.metrics.exists() or self.checkpoints.exists()

    @property
    def set_aside(self) -> Path:
        """Where a run replaced by a new one waits until the new one has finished an epoch."""
        return self.root / ".replaced"

    def run_files(self) -> tuple[Path, ...]:
        """The files and folders a run writes (not what commands make from it: report, render)."""
        return (self.config, self.metrics, self.final_evaluation, self.checkpoints, self.tensorboard)

    def clear(self) -> None:
        """Remove a run's files (only those a run writes)."""
        for path in self.run_files():
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)

    @contextlib.contextmanager
    def starting(self, replace: bool) -> Iterator[None]:
        """A new run's start here, the run directory held by this process: a run already here
        is set aside first where ``replace`` (``--force``), and removed once the block ends with
        the new run's first checkpoint written. Should the block fail before that (a task
        refused at its first episode, a full disk, Ctrl-C), the new run's files are removed and
        the run set aside is put back: a start that does not get through its first epoch leaves
        the directory as it found it."""
        if self.set_aside.exists():  # left by a start that was killed before its first epoch
            if replace and not self.latest.exists():
                self.clear()  # that start's files; the run it replaced stays aside
            else:
                shutil.rmtree(self.set_aside)
        if replace and self.holds_run():
            self.set_aside.mkdir()
            for path in self.run_files():
                if path.exists():
                    os.replace(path, self.set_aside / path.name)
        try:
            yield
        except BaseException:
            if not self.latest.exists():
                self.clear()
                if self.set_aside.exists():
                    for path in self.set_aside.iterdir():
                        os.replace(path, self.root / path.name)
                    self.set_aside.rmdir()
            raise
        finally:
            shutil.rmtree(self.set_aside, ignore_errors=True)

    def named(self, path: Path | str) -> str:
        """``path`` as a run's own files name it: relative to the run (``checkpoints/latest.pt``)
        where it lies inside, so that what the run writes reads the same on any machine; else
        as given."""
        try:
            return Path(path).resolve().relative_to(self.root.resolve()).as_posix()
        except ValueError:
            return str(path)

    def checkpoint(self, name: str) -> Path:
        """``latest``, ``best``, ``first``, or a path to a checkpoint file; a bare name that is
        none of these is a :class:`RunDirError` listing what may be given."""
        if name in CHECKPOINT_NAMES:
            return self.checkpoints / f"{name}.pt"
        path = Path(name)
        if not path.is_file() and len(path.parts) == 1 and not path.suffix:
            raise RunDirError(
                f"no checkpoint named {name!r}: give latest, best, first or the path of a checkpoint file"
            )
        return path


def package_versions() -> dict[str, str]:
    """Versions of this package and of the libraries that decide its numbers."""
    versions = {}
    for name in _VERSIONED:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def write_config(run: RunDir, config: TrainConfig, derived: dict[str, Any]) -> None:
    """Write config.json atomically: the settings, facts derived from them and the task, versions."""
    payload = {
        "format": CONFIG_FORMAT,
        "config": config.to_dict(),
        "derived": derived,
        "versions": package_versions(),
    }
    write_text_atomic(run.config, json.dumps(payload, indent=2) + "\n")


def read_config(run: RunDir) -> TrainConfig:
    """The configuration a run was started with, checked as a new run's is, or
    :class:`RunDirError`."""
    if not run.config.is_file():
        raise RunDirError(f"no run in {run.root} (config.json is missing)")
    try:
        payload = json.loads(run.config.read_text())
        return read_settings(payload["config"], payload.get("format", 1))
    except (json.JSONDecodeError, KeyError, TypeError, ConfigError) as exc:
        raise RunDirError(f"{run.config} is unreadable ({exc})") from exc
