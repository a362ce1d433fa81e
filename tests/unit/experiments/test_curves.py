"""Learning curves read from metrics.csv: smoothing and when a level is first reached."""

import numpy as np
import pytest

from dtd.errors import RunDirError
from dtd.experiments.curves import Curve, read_curve
from dtd.experiments.run_curves import env_order


def curve(success):
    n = len(success)
    epochs = np.arange(1, n + 1, dtype=float)
    return Curve(epochs, epochs * 5000, epochs * 30.0, np.array(success, dtype=float))


def test_smoothing_averages_the_last_epochs_and_fewer_at_the_start():
    c = curve([0.0, 0.6, 0.3, 0.9, 0.9])
    np.testing.assert_allclose(c.smoothed(3), [0.0, 0.3, 0.3, 0.6, 0.7])
    np.testing.assert_allclose(c.smoothed(1), c.eval_success)


def test_first_reaching_a_level_ignores_a_lucky_epoch():
    c = curve([0.0, 0.6, 0.3, 0.9, 0.9, 1.0])
    assert c.first_reaching(0.5, window=1) == (10_000, 60.0)
    assert c.first_reaching(0.5, window=3) == (20_000, 120.0)
    assert c.first_reaching(0.9, window=3) == (30_000, 180.0)
    assert c.first_reaching(0.99, window=3) is None
    assert c.final_success == 1.0


def test_a_curve_cut_at_a_budget_is_the_run_as_it_was_then():
    c = curve([0.0, 0.6, 0.3, 0.9])  # 5,000 env steps per epoch
    early = c.up_to(12_000)
    np.testing.assert_array_equal(early.epoch, [1, 2])
    assert early.final_success == 0.6
    assert len(c.up_to(20_000)) == 4 and len(c.up_to(1e9)) == 4
    assert len(c.up_to(4_999)) == 0


def test_read_curve_from_a_metrics_file(tmp_path):
    (tmp_path / "config.json").write_text("{}")
    assert len(read_curve(tmp_path)) == 0
    (tmp_path / "metrics.csv").write_text(
        "epoch,env_steps,wall_s,eval_success,train_success\n1,5000,20.5,0.1,0.0\n2,10000,41.0,0.4,0.2\n"
    )
    c = read_curve(tmp_path)
    np.testing.assert_allclose(c.env_steps, [5000, 10000])
    np.testing.assert_allclose(c.eval_success, [0.1, 0.4])
    with pytest.raises(RunDirError):
        read_curve(tmp_path / "absent")


def test_a_level_met_exactly_counts_after_a_long_history():
    # 57 epochs of history, then 1.0, 0.8, 0.9: the mean is 0.9 and meets 0.9.
    history = [0.1, 0.3, 0.7] * 19
    c = curve([*history, 1.0, 0.8, 0.9])
    assert c.smoothed(3)[-1] == pytest.approx(0.9)
    assert c.first_reaching(0.9, window=3) == (60 * 5000, 60 * 30.0)


def test_tasks_are_ordered_as_in_the_paper_then_by_name():
    envs = [
        "Reacher-v5",
        "HandManipulateBlockRotateZ-v1",
        "FetchPickAndPlace-v4",
        "FetchReach-v4",
        "gymnasium_robotics:FetchPush-v4",
        "Ant-v5",
    ]
    assert sorted(envs, key=env_order) == [
        "gymnasium_robotics:FetchPush-v4",
        "FetchPickAndPlace-v4",
        "HandManipulateBlockRotateZ-v1",
        "Ant-v5",
        "FetchReach-v4",
        "Reacher-v5",
    ]
