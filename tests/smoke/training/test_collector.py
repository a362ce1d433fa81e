"""The collecting process: same episodes as inline collection, and its failures reported."""

import numpy as np
import pytest

from dtd.config import Algo, Collection, TrainConfig
from dtd.training.collector import CollectorProcessError, InlineCollector, ProcessCollector
from dtd.training.components import build

pytestmark = pytest.mark.smoke


def failing_side():
    raise ValueError("no such robot")


def test_a_failure_to_build_the_collecting_side_is_reported_with_its_cause():
    with pytest.raises(CollectorProcessError, match="no such robot"):
        ProcessCollector(failing_side, agent=None)  # type: ignore[arg-type]


@pytest.mark.parametrize("algo", [Algo.her, Algo.dtd])
def test_process_and_inline_collection_give_the_same_episodes(algo):
    base = TrainConfig(env="FetchReach-v4", algo=algo, seed=3, threads=1)
    runs = []
    for collection in (Collection.inline, Collection.process):
        components = build(base, collection=collection)
        assert isinstance(components.collector, InlineCollector) == (collection is Collection.inline)
        try:
            batches = []
            for _ in range(2):
                components.collector.submit()
                episodes = components.collector.result()
                components.agent.store(episodes, components.rng)
                components.agent.train(2, components.rng)  # the policy changes between batches
                batches.append(episodes)
            state = components.collector.state_dict()
        finally:
            components.close()
        runs.append((batches, state))
    (inline, inline_state), (process, process_state) = runs
    for a, b in zip(inline, process, strict=True):
        for x, y in zip(a, b, strict=True):
            assert np.array_equal(x, y)
    assert inline_state == process_state
