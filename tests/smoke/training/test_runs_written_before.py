"""Run directories written by an earlier layout of the package still evaluate and resume."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import ANOTHER_MACHINE, dtd, read_metrics

pytestmark = pytest.mark.smoke

EARLIER_RUNS = Path(__file__).parents[2] / "data" / "flat-layout-runs"


@pytest.mark.parametrize("algo", ["dtd", "her"])
def test_an_earlier_run_evaluates_as_it_did(algo, tmp_path):
    run = shutil.copytree(EARLIER_RUNS / f"reach-{algo}", tmp_path / f"reach-{algo}")
    result = dtd("eval", run, "--episodes", "3", "--seed", "11")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    expected = json.loads((run / "eval-seed-11.json").read_text())
    numbers = {name for name, value in expected.items() if isinstance(value, float)}
    # Written on another machine: the same to float32 rounding (tests.helpers.ANOTHER_MACHINE).
    assert {name: figures[name] for name in numbers} == pytest.approx(
        {name: expected[name] for name in numbers}, **ANOTHER_MACHINE
    )
    assert {name: figures[name] for name in expected.keys() - numbers} == {
        name: expected[name] for name in expected.keys() - numbers
    }


@pytest.mark.parametrize("algo", ["dtd", "her"])
def test_an_earlier_run_resumes(algo, tmp_path):
    run = shutil.copytree(EARLIER_RUNS / f"reach-{algo}", tmp_path / f"reach-{algo}")
    before = read_metrics(run)
    result = dtd("train", "--resume", run, "--epochs", "2", "--no-progress")
    assert result.returncode == 0, result.stderr
    after = read_metrics(run)
    # The earlier epoch keeps its figures; figures added to the package since are blank in it.
    assert [{name: row[name] for name in before[0]} for row in after[:1]] == before
    assert [int(row["env_steps"]) for row in after] == [100, 200]


ANOTHER_MACHINE_ALLCLOSE = {"rtol": ANOTHER_MACHINE["rel"], "atol": ANOTHER_MACHINE["abs"]}
SNAPSHOT_RUN = Path(__file__).parents[2] / "data" / "dtd-run-with-snapshots" / "reach-dtd-snapshots"


@pytest.fixture
def snapshot_run(tmp_path):
    return shutil.copytree(SNAPSHOT_RUN, tmp_path / "reach-dtd-snapshots")


def test_an_earlier_dtd_run_evaluates_and_shows_its_plans_as_it_did(snapshot_run):
    result = dtd("eval", snapshot_run, "--episodes", "3", "--seed", "11", "--show-subgoals")
    assert result.returncode == 0, result.stderr
    *plans, line = result.stdout.splitlines()
    figures = json.loads(line)
    expected = json.loads((snapshot_run / "eval-seed-11.json").read_text())
    assert expected["subgoal_placement"] and "subgoal_reached" in expected
    numbers = {name for name, value in expected.items() if isinstance(value, float)}
    assert {name: figures[name] for name in numbers} == pytest.approx(
        {name: expected[name] for name in numbers}, **ANOTHER_MACHINE
    )
    assert figures["subgoal_placement"] == expected["subgoal_placement"]
    assert {"epoch": figures["epoch"], "env_steps": figures["env_steps"]} == {"epoch": 2, "env_steps": 200}
    assert "\n".join(plans) + "\n" == (snapshot_run / "plans-seed-11.txt").read_text()


def test_an_earlier_dtd_run_resumes_keeping_its_sub_goal_figures_and_snapshots(snapshot_run):
    before = read_metrics(snapshot_run)
    result = dtd("train", "--resume", snapshot_run, "--epochs", "3", "--no-progress")
    assert result.returncode == 0, result.stderr
    after = read_metrics(snapshot_run)
    assert [{name: row[name] for name in before[0]} for row in after[:2]] == before
    assert [int(row["env_steps"]) for row in after] == [100, 200, 300]
    assert float(after[2]["subgoal_eps"]) >= 0.0
    snapshots = sorted(path.name for path in (snapshot_run / "checkpoints" / "epochs").iterdir())
    assert snapshots == ["epoch-1.pt", "epoch-2.pt", "epoch-3.pt"]


def test_an_earlier_dtd_runs_epoch_snapshots_play_in_the_explorer_as_they_did(snapshot_run, tmp_path):
    from dtd.explain.explore.session import Explorer

    expected = json.loads((snapshot_run / "explore-plans.json").read_text())
    explorer = Explorer(snapshot_run, tmp_path / "videos")
    try:
        assert explorer.describe()["epochs"] == expected["epochs"] == [1, 2]
        for epoch in (1, 2):
            played = explorer.play(epoch)
            assert (tmp_path / "videos" / played["video"]).stat().st_size > 0
            plan = json.loads(json.dumps(played["plan"]))
            wanted = expected["plans"][str(epoch)]
            assert plan["reached"] == wanted["reached"]
            for name in ("subgoals", "segment_ends"):
                assert np.allclose(plan[name], wanted[name], **ANOTHER_MACHINE_ALLCLOSE), name
    finally:
        explorer.close()


def test_an_earlier_saved_evaluation_naming_its_old_paths_is_taken_as_it_is(snapshot_run):
    from dtd.training.trained_run import final_evaluation

    saved = snapshot_run / "eval-latest.json"
    written = saved.read_bytes()
    assert json.loads(written)["run_dir"] == "reach-dtd-snapshots"  # the layout of the time
    assert final_evaluation(snapshot_run, episodes=3) == saved
    assert saved.read_bytes() == written


def test_loading_a_run_to_act_makes_its_evaluation_environments_only(snapshot_run, monkeypatch):
    from dtd.training import components, trained_run

    made = []
    real = components.make_task_envs

    def counted(config, count):
        made.append(count)
        return real(config, count)

    def no_collector(*args, **kwargs):
        raise AssertionError("a collector was made to act")

    monkeypatch.setattr(components, "make_task_envs", counted)
    monkeypatch.setattr(components, "InlineCollector", no_collector)
    monkeypatch.setattr(components, "ProcessCollector", no_collector)
    with trained_run.load_run(snapshot_run, "latest", envs=3) as loaded:
        assert len(loaded.envs) == 3 and loaded.checkpoint.whole and loaded.checkpoint.epoch == 2
    assert made == [3]
    result = trained_run.evaluate_run(snapshot_run, episodes=2)
    assert result["epoch"] == 2 and made == [3, 2]
