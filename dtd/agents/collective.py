"""How a learner combines its numbers with the other data-parallel workers of one run: every
update's gradients averaged and the input statistics summed, so that every worker holds the
same parameters and normalises alike (OpenAI baselines' MPI workers, on torch.distributed)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
import torch


class Collective(Protocol):
    """The operations a learner needs from its fellow workers."""

    @property
    def workers(self) -> int:
        """Workers in the run (1: a run of its own)."""
        ...

    def average_gradients(self, parameters: Sequence[torch.Tensor]) -> None:
        """Replace each parameter's gradient by its mean over the workers."""
        ...

    def sum(self, values: np.ndarray) -> np.ndarray:
        """The elementwise sum of ``values`` (float64, same shape on every worker)."""
        ...


class Alone:
    """A single worker: nothing to combine."""

    workers = 1

    def average_gradients(self, parameters: Sequence[torch.Tensor]) -> None:
        pass

    def sum(self, values: np.ndarray) -> np.ndarray:
        return values


ALONE = Alone()


class ProcessGroup:
    """The workers of torch.distributed's default process group (gloo on CPU). Every worker
    must make the same calls in the same order: each is a collective operation."""

    def __init__(self) -> None:
        import torch.distributed as dist

        self._dist = dist
        self._workers = dist.get_world_size()

    @property
    def workers(self) -> int:
        return self._workers

    def average_gradients(self, parameters: Sequence[torch.Tensor]) -> None:
        # One all-reduce of all gradients flattened; a parameter without one counts as zero.
        grads = [p.grad if p.grad is not None else torch.zeros_like(p) for p in parameters]
        flat = torch.cat([grad.reshape(-1) for grad in grads])
        self._dist.all_reduce(flat)
        flat /= self._workers
        offset = 0
        for param, grad in zip(parameters, grads, strict=True):
            param.grad = flat[offset : offset + grad.numel()].view_as(grad).clone()
            offset += grad.numel()

    def sum(self, values: np.ndarray) -> np.ndarray:
        tensor = torch.from_numpy(np.ascontiguousarray(values, dtype=np.float64).copy())
        self._dist.all_reduce(tensor)
        return tensor.numpy()
