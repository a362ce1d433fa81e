"""Learning: HER and DtD must solve FetchReach on a small, fixed budget and seed."""

from __future__ import annotations

import pytest

from dtd.config import Algo, TrainConfig
from dtd.training.lifecycle import train
from dtd.training.trained_run import evaluate_run

pytestmark = pytest.mark.learning


def test_her_reaches_90_percent_on_fetch_reach(tmp_path):
    config = TrainConfig(env="FetchReach-v4", algo=Algo.her, seed=0, epochs=5, n_cycles=10, threads=1)
    state = train(config, run_dir=tmp_path / "run", show_progress=False)
    assert state.env_steps == 5_000
    figures = evaluate_run(tmp_path / "run", episodes=50, checkpoint="latest", seed=123)
    assert figures["success_rate"] >= 0.9, figures


def test_dtd_reaches_90_percent_on_fetch_reach(tmp_path):
    config = TrainConfig(env="FetchReach-v4", algo=Algo.dtd, seed=0, epochs=5, n_cycles=10, threads=1)
    train(config, run_dir=tmp_path / "run", show_progress=False)
    figures = evaluate_run(tmp_path / "run", episodes=50, checkpoint="latest", seed=123)
    assert figures["success_rate"] >= 0.9, figures
    assert figures["subgoal_reached"] >= 0.5, figures
