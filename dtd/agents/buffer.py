"""Replay storage shaped as whole episodes, so that relabelling is one vectorised index."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from dtd.agents.records import Episodes

_FIELDS = Episodes._fields


class EpisodeBuffer:
    """A ring of whole episodes; when full, the oldest episode is overwritten first.

    Each slot holds up to T steps (an episode the task ended sooner fills the rest with
    padding, which its ``length`` keeps out of sampling), so ``capacity`` episodes take the
    memory of ``capacity * T`` transitions whatever their lengths."""

    def __init__(self, capacity: int, horizon: int, obs_dim: int, goal_dim: int, action_dim: int) -> None:
        if capacity < 1:
            raise ValueError("an episode buffer holds at least one episode")
        self.capacity = capacity
        self.horizon = horizon
        self._data = Episodes(
            obs=np.zeros((capacity, horizon + 1, obs_dim), dtype=np.float32),
            achieved_goal=np.zeros((capacity, horizon + 1, goal_dim), dtype=np.float32),
            action=np.zeros((capacity, horizon, action_dim), dtype=np.float32),
            step_goal=np.zeros((capacity, horizon, goal_dim), dtype=np.float32),
            desired_goal=np.zeros((capacity, goal_dim), dtype=np.float32),
            success=np.zeros((capacity,), dtype=np.float32),
            length=np.zeros((capacity,), dtype=np.int64),
        )
        self.size = 0
        self.next_index = 0
        self.episodes_added = 0

    @classmethod
    def for_transitions(
        cls, transitions: int, horizon: int, obs_dim: int, goal_dim: int, action_dim: int
    ) -> EpisodeBuffer:
        """A buffer holding ``transitions`` steps' worth of whole episodes (``transitions`` holds
        one at least)."""
        return cls(transitions // horizon, horizon, obs_dim, goal_dim, action_dim)

    def add(self, episodes: Episodes) -> None:
        """Store a batch of episodes, wrapping around when full."""
        count = episodes.count
        slots = (self.next_index + np.arange(count)) % self.capacity
        for name in _FIELDS:
            getattr(self._data, name)[slots] = getattr(episodes, name)
        self.next_index = int((self.next_index + count) % self.capacity)
        self.size = min(self.capacity, self.size + count)
        self.episodes_added += count

    def stored(self) -> Episodes:
        """Views of the stored episodes (in slot order, not age order)."""
        return Episodes(*(array[: self.size] for array in self._data))

    @property
    def nbytes(self) -> int:
        """Bytes of the buffer's arrays (allocated whole when it is made)."""
        return sum(array.nbytes for array in self._data)

    def oldest_first(self) -> np.ndarray:
        """Indices into :meth:`stored` in the order the episodes were added."""
        return slots_oldest_first(self.size, self.episodes_added, self.next_index)

    def state_dict(self) -> dict[str, Any]:
        """Plain data: the stored episodes and the ring's position."""
        return {
            "capacity": self.capacity,
            "size": self.size,
            "next_index": self.next_index,
            "episodes_added": self.episodes_added,
            "data": {
                name: torch.from_numpy(array.copy())
                for name, array in zip(_FIELDS, self.stored(), strict=True)
            },
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned, into a buffer of the same shape."""
        if state["capacity"] != self.capacity:
            raise ValueError(f"buffer capacity {state['capacity']} differs from {self.capacity}")
        size = int(state["size"])
        for name in _FIELDS:
            if name in state["data"]:
                getattr(self._data, name)[:size] = state["data"][name].numpy()
        if "length" not in state["data"]:  # written when every episode ran to the time limit
            self._data.length[:size] = self.horizon
        self.size = size
        self.next_index = int(state["next_index"])
        self.episodes_added = int(state["episodes_added"])


def slots_oldest_first(size: int, episodes_added: int, next_index: int) -> np.ndarray:
    """The slots of a ring of ``size`` stored episodes in the order they were added: in slot
    order until it wraps, then from ``next_index`` (the next to be overwritten, the oldest)."""
    slots = np.arange(size)
    return slots if episodes_added <= size else np.roll(slots, -next_index)
