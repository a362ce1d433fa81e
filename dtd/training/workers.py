"""Data-parallel workers of one run on torch.distributed (gloo): joining the group that torchrun
or ``dtd train --workers N`` (:mod:`dtd.training.launch`) started, and combining per-epoch figures.

Each worker is one process running ``dtd train``: it collects its own episodes into its own
replay, and every update's gradients and the input statistics are combined with the others'
(:mod:`dtd.agents.collective`). Worker 0 writes the run's files.
"""

from __future__ import annotations

import dataclasses
import datetime
import importlib
import math
from collections.abc import Mapping, Sequence

import numpy as np

from dtd.agents.collective import ALONE, Collective, ProcessGroup
from dtd.errors import ConfigError, WorkerLost
from dtd.training.launch import JobPlace

WORKER_TIMEOUT_S = 300.0
"""How long a worker waits for the others at any collective step before giving up (a worker
that dies is noticed at once; this bounds a worker that hangs or a machine cut off)."""


GROUP_HOLDING_MODULE = "torch.distributed.nn.functional"
"""A module of torch whose functions keep the process group that exists when it is imported."""


@dataclasses.dataclass(frozen=True)
class WorkerGroup:
    """This process's place among the run's workers."""

    rank: int = 0
    workers: int = 1
    collective: Collective = ALONE

    @property
    def writes(self) -> bool:
        """Whether this worker writes the run's files (worker 0)."""
        return self.rank == 0

    def mean(self, figures: Mapping[str, float]) -> dict[str, float]:
        """Each figure's mean over the workers that have a finite value of it (NaN where none
        has); every worker passes the same names."""
        if self.workers == 1:
            return dict(figures)
        names = sorted(figures)
        values = np.array([figures[name] for name in names], dtype=np.float64)
        finite = np.isfinite(values)
        totals = self.collective.sum(np.concatenate([np.where(finite, values, 0.0), finite]))
        sums, counts = totals[: len(names)], totals[len(names) :]
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(counts > 0, sums / np.maximum(counts, 1), math.nan)
        return {name: float(mean) for name, mean in zip(names, means, strict=True)}

    def total(self, count: int) -> int:
        """The sum of ``count`` over the workers."""
        if self.workers == 1:
            return count
        return round(float(self.collective.sum(np.array([count], dtype=np.float64))[0]))

    def barrier(self) -> None:
        """Wait until every worker has come here."""
        if self.workers > 1:
            self.collective.sum(np.zeros(1))


def join_group(workers: int, place: JobPlace) -> WorkerGroup:
    """Join the process group of the job ``place`` is in (torch.distributed reads the
    rendezvous from the environment torchrun's agent set); a job of another size than
    ``workers`` is a :class:`ConfigError`."""
    import torch.distributed as dist

    if place.workers != workers:
        raise ConfigError(f"the run has {workers} workers; this job started {place.workers}")
    if not dist.is_initialized():
        # Imported before the group exists: its functions take the world group as a default
        # argument, so imported after it (torch's optimisers import them on first use, through
        # torch._dynamo) they would hold it past leave_group, and gloo's threads would run into
        # the interpreter's exit, which they can abort (SIGABRT, about one run in ten).
        importlib.import_module(GROUP_HOLDING_MODULE)
        dist.init_process_group("gloo", timeout=datetime.timedelta(seconds=WORKER_TIMEOUT_S))
    return WorkerGroup(dist.get_rank(), workers, _Reporting(ProcessGroup(), dist.get_rank(), workers))


def leave_group() -> None:
    """Leave the process group, if this process joined one."""
    import torch.distributed as dist

    if dist.is_initialized():
        dist.destroy_process_group()


class _Reporting:
    """A collective whose failures say which worker lost the others."""

    def __init__(self, inner: ProcessGroup, rank: int, workers: int) -> None:
        self.inner = inner
        self.rank = rank
        self.workers = workers

    def _lost(self, exc: Exception) -> WorkerLost:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return WorkerLost(f"worker {self.rank} of {self.workers} lost contact with the others ({reason})")

    def average_gradients(self, parameters: Sequence) -> None:
        try:
            self.inner.average_gradients(parameters)
        except RuntimeError as exc:
            raise self._lost(exc) from exc

    def sum(self, values: np.ndarray) -> np.ndarray:
        try:
            return self.inner.sum(values)
        except RuntimeError as exc:
            raise self._lost(exc) from exc
