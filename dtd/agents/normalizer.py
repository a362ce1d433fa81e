"""Running mean / standard deviation normalisation of network inputs."""

from __future__ import annotations

import numpy as np
import torch

from dtd.agents.collective import ALONE, Collective


class RunningNormalizer:
    """Normalises vectors by the mean and std of everything it has been shown.

    Statistics are kept in float64 sums so that long runs do not drift; the float32
    tensors used by the networks are refreshed after every :meth:`update`. With fellow
    workers (``collective``), every update adds what all of them were shown.
    """

    def __init__(
        self,
        size: int,
        eps: float = 0.01,
        clip: float = 5.0,
        collective: Collective = ALONE,
        device: torch.device | str = "cpu",
    ) -> None:
        self.size = size
        self.device = torch.device(device)
        self.collective = collective
        self.eps = eps
        self.clip = clip
        self.sum = np.zeros(size, dtype=np.float64)
        self.sum_sq = np.zeros(size, dtype=np.float64)
        self.count = 0
        self.mean = torch.zeros(size, device=self.device)
        self.std = torch.ones(size, device=self.device)

    def update(self, values: np.ndarray) -> None:
        """Add a batch of vectors (any leading shape, last dimension ``size``)."""
        flat = np.asarray(values, dtype=np.float64).reshape(-1, self.size)
        if self.collective.workers == 1:
            self.sum += flat.sum(axis=0)
            self.sum_sq += np.square(flat).sum(axis=0)
            self.count += flat.shape[0]
        else:
            added = np.concatenate([flat.sum(axis=0), np.square(flat).sum(axis=0), [flat.shape[0]]])
            added = self.collective.sum(added)
            self.sum += added[: self.size]
            self.sum_sq += added[self.size : 2 * self.size]
            self.count += int(added[-1])
        self._refresh()

    def _refresh(self) -> None:
        if self.count == 0:
            return
        mean = self.sum / self.count
        var = np.maximum(self.sum_sq / self.count - np.square(mean), 0.0)
        self.mean = torch.as_tensor(mean, dtype=torch.float32, device=self.device)
        std = np.maximum(np.sqrt(var), self.eps)
        self.std = torch.as_tensor(std, dtype=torch.float32, device=self.device)

    def normalize(self, values: torch.Tensor) -> torch.Tensor:
        """(values - mean) / std, clipped to [-clip, clip]."""
        return torch.clamp((values - self.mean) / self.std, -self.clip, self.clip)

    def state_dict(self) -> dict[str, object]:
        """Plain data: the sums and the count."""
        return {
            "sum": torch.from_numpy(self.sum.copy()),
            "sum_sq": torch.from_numpy(self.sum_sq.copy()),
            "count": self.count,
        }

    def load_state_dict(self, state: dict[str, object]) -> None:
        """Restore what :meth:`state_dict` returned."""
        self.sum = _float64(state["sum"])
        self.sum_sq = _float64(state["sum_sq"])
        self.count = int(state["count"])  # type: ignore[arg-type]
        self._refresh()


def _float64(values: object) -> np.ndarray:
    if isinstance(values, torch.Tensor):
        values = values.cpu().numpy()
    return np.asarray(values, dtype=np.float64).copy()
