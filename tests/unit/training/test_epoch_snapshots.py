"""Which epochs a run keeps an agent-only snapshot of, for dtd explore."""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from dtd.config import TrainConfig
from dtd.training.trainer import keeps_epoch_snapshot


def kept(epochs: int, most: int) -> list[int]:
    config = dataclasses.replace(TrainConfig(env="FetchPush-v4"), epochs=epochs, explore_snapshots=most)
    return [epoch for epoch in range(1, epochs + 1) if keeps_epoch_snapshot(epoch, config)]


def test_every_epoch_of_a_short_run():
    assert kept(40, 100) == list(range(1, 41))


@pytest.mark.parametrize(("epochs", "most"), [(200, 100), (250, 100), (1000, 100), (7, 3)])
def test_long_runs_keep_about_as_many_as_asked_with_the_first_and_the_last(epochs, most):
    epochs_kept = kept(epochs, most)
    assert epochs_kept[0] == 1 and epochs_kept[-1] == epochs
    assert len(epochs_kept) <= most + 2
    gaps = {after - before for before, after in itertools.pairwise(epochs_kept[1:-1])}
    assert len(gaps) <= 1  # evenly spaced between the first and the last


def test_none_when_asked_for_none():
    assert kept(50, 0) == []
