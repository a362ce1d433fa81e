"""The episode ring: capacity, wrap-around, and whole episodes kept together."""

import numpy as np
import pytest

from dtd.agents.buffer import EpisodeBuffer
from dtd.agents.records import Episodes

T, OBS, GOAL, ACT = 4, 3, 2, 2


def episodes_numbered(first: int, count: int) -> Episodes:
    """Episodes whose every entry holds the episode's number, of mixed lengths (number % T + 1)."""
    ids = np.arange(first, first + count, dtype=np.float32)

    def filled(*shape: int) -> np.ndarray:
        return np.broadcast_to(ids.reshape(-1, *([1] * len(shape))), (count, *shape)).copy()

    return Episodes(
        filled(T + 1, OBS),
        filled(T + 1, GOAL),
        filled(T, ACT),
        filled(T, GOAL),
        filled(GOAL),
        ids.copy(),
        (ids.astype(np.int64) % T) + 1,
    )


def test_capacity_in_whole_episodes():
    assert EpisodeBuffer.for_transitions(1_000_000, 50, OBS, GOAL, ACT).capacity == 20_000
    assert EpisodeBuffer.for_transitions(149, 50, OBS, GOAL, ACT).capacity == 2
    with pytest.raises(ValueError, match="at least one episode"):
        EpisodeBuffer.for_transitions(10, 50, OBS, GOAL, ACT)


def test_wraps_around_overwriting_the_oldest_episodes():
    buffer = EpisodeBuffer(5, T, OBS, GOAL, ACT)
    buffer.add(episodes_numbered(0, 3))
    assert buffer.size == 3
    buffer.add(episodes_numbered(3, 4))  # 7 episodes into 5 slots: 0 and 1 are gone
    assert buffer.size == 5 and buffer.next_index == 2 and buffer.episodes_added == 7
    stored = buffer.stored()
    assert sorted(stored.success.tolist()) == [2, 3, 4, 5, 6]
    assert stored.success.tolist() == [5, 6, 2, 3, 4]


def test_every_field_of_a_slot_belongs_to_one_episode():
    buffer = EpisodeBuffer(4, T, OBS, GOAL, ACT)
    for first in range(0, 11, 3):
        buffer.add(episodes_numbered(first, 3))
    stored = buffer.stored()
    for slot, number in enumerate(stored.success):
        for field in stored._replace(length=stored.success):
            assert np.all(field[slot] == number)
        assert stored.length[slot] == int(number) % T + 1


def test_state_round_trip():
    buffer = EpisodeBuffer(4, T, OBS, GOAL, ACT)
    buffer.add(episodes_numbered(0, 6))
    restored = EpisodeBuffer(4, T, OBS, GOAL, ACT)
    restored.load_state_dict(buffer.state_dict())
    for a, b in zip(buffer.stored(), restored.stored(), strict=True):
        assert np.array_equal(a, b)
    assert (restored.size, restored.next_index, restored.episodes_added) == (4, 2, 6)


def test_oldest_first_orders_a_wrapped_ring_by_age():
    buffer = EpisodeBuffer(4, 2, 1, 1, 1)
    assert buffer.oldest_first().tolist() == []
    for number in range(6):  # episodes 0..5 into 4 slots: 4, 5 overwrite 0, 1
        buffer.add(
            Episodes(
                obs=np.full((1, 3, 1), number, np.float32),
                achieved_goal=np.zeros((1, 3, 1), np.float32),
                action=np.zeros((1, 2, 1), np.float32),
                step_goal=np.zeros((1, 2, 1), np.float32),
                desired_goal=np.zeros((1, 1), np.float32),
                success=np.zeros(1, np.float32),
                length=np.full(1, 2),
            )
        )
        added = buffer.stored().obs[buffer.oldest_first(), 0, 0].tolist()
        assert added == list(range(max(0, number - 3), number + 1))
