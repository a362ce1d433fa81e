"""Run directories written by an earlier layout of the package still evaluate and resume."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

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
