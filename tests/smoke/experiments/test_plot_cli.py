"""``dtd plot`` from the command line with a run it cannot read among those it can."""

from __future__ import annotations

import json
import shutil

import pytest

from tests.helpers import TINY, dtd

pytestmark = pytest.mark.smoke


def test_plot_draws_the_readable_runs_and_names_the_others(tmp_path, reach_run):
    shutil.copytree(reach_run, tmp_path / "runs" / "good")
    broken = shutil.copytree(reach_run, tmp_path / "runs" / "broken")
    (broken / "metrics.csv").write_bytes(b"\x00\xff\xfe binary \x00" * 50)
    (tmp_path / "runs" / "other").mkdir()
    shutil.copy(reach_run / "config.json", tmp_path / "runs" / "other" / "config.json")
    (tmp_path / "runs" / "other" / "metrics.csv").write_text(
        "epoch,env_steps,wall_s,eval_success\n1,200,1.0,0.5\n2,40"
    )

    result = dtd("plot", tmp_path / "runs", "--out", tmp_path / "figures")
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning: skipped")]
    assert len(warnings) == 2, result.stderr
    assert any(str(broken) in line and "not a dtd metrics file" in line for line in warnings)
    assert any("line 3 has 2 fields" in line for line in warnings)
    assert (tmp_path / "figures" / "FetchReach-v4.png").is_file()
    assert "Traceback" not in result.stderr

    strict = dtd("plot", tmp_path / "runs", "--out", tmp_path / "figures", "--strict")
    assert strict.returncode == 1 and (tmp_path / "figures" / "summary.csv").is_file()


def test_a_saved_evaluation_is_the_final_plot_stats_takes(tmp_path, reach_run):
    pytest.importorskip("rliable", reason="dtd plot --stats needs the [stats] extra")
    run = shutil.copytree(reach_run, tmp_path / "runs" / "reach")
    result = dtd("eval", run, "--episodes", "4", "--save")
    assert result.returncode == 0, result.stderr
    saved = json.loads((run / "eval-latest.json").read_text())
    assert saved["episodes"] == 4 and saved["epoch"] == 3
    printed = json.loads(result.stdout.splitlines()[-1])
    assert printed["checkpoint"] == str(run / "checkpoints" / "latest.pt")
    # What the run keeps names its own files relative to itself: it reads the same when copied.
    assert saved["checkpoint"] == "checkpoints/latest.pt" and "run_dir" not in saved
    assert saved == {k: v for k, v in printed.items() if k not in ("plans", "run_dir", "checkpoint")} | {
        "checkpoint": "checkpoints/latest.pt"
    }
    # One run gives no interval: refused in one line, nothing written.
    result = dtd("plot", tmp_path / "runs", "--stats", "--out", tmp_path / "figures")
    assert result.returncode == 2 and "one run" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (tmp_path / "figures").exists()
    another_seed = ["--env", "FetchReach-v4", "--epochs", "3", "--seed", "8", *TINY]
    assert dtd("train", *another_seed, "--run-dir", tmp_path / "runs" / "reach-8").returncode == 0
    result = dtd("plot", tmp_path / "runs", "--stats", "--out", tmp_path / "figures")
    assert result.returncode == 0, result.stderr
    assert "4 episodes" in result.stdout and "IQM" in result.stdout
    assert not [line for line in result.stderr.splitlines() if line.startswith("warning")]
    assert (tmp_path / "figures" / "FetchReach-v4-stats.png").is_file()
