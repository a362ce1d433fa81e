"""The learners from the command line: every algorithm trains on each, resumes the same, is
evaluated and exported to ONNX; --device cuda is refused in one line where there is no GPU, and a run
made for a GPU is looked at (and resumed with --device cpu) on a machine without one."""

from __future__ import annotations

import json

import pytest
import torch

from tests.helpers import TINY, dtd

pytestmark = pytest.mark.smoke


@pytest.mark.parametrize(("algo", "learner"), [("her", "td3"), ("dtd", "sac"), ("dtd", "tqc")])
def test_a_learner_trains_resumes_like_a_longer_run_and_is_evaluated(tmp_path, algo, learner):
    high = ["--high.learner", learner] if algo == "dtd" else []  # her has no high level, and refuses it
    args = ["--env", "FetchReach-v4", "--algo", algo, "--learner", learner, *high, *TINY]
    longer, split = tmp_path / "longer", tmp_path / "split"
    assert dtd("train", *args, "--epochs", "2", "--run-dir", longer).returncode == 0
    assert dtd("train", *args, "--epochs", "1", "--run-dir", split).returncode == 0
    result = dtd("train", "--resume", split, "--epochs", "2")
    assert result.returncode == 0, result.stderr
    rows = [
        (longer / "metrics.csv").read_text().splitlines(),
        (split / "metrics.csv").read_text().splitlines(),
    ]
    # Every figure but the wall time is the same: the learner's state (a temperature, a delayed
    # actor's count) and its random draws survive the checkpoint.
    drop_wall = [[line.split(",")[:4] + line.split(",")[5:] for line in lines] for lines in rows]
    assert drop_wall[0] == drop_wall[1]
    config = json.loads((longer / "config.json").read_text())["config"]
    assert config["learner"]["learner"] == learner
    evaluated = dtd("eval", longer, "--episodes", "2")
    assert evaluated.returncode == 0, evaluated.stderr
    assert 0.0 <= json.loads(evaluated.stdout)["success_rate"] <= 1.0
    # The ONNX files compute what the agent does (a Gaussian actor's mean, an ensemble's value).
    exported = dtd("export", longer, "--out", tmp_path / "onnx")
    assert exported.returncode == 0, exported.stderr
    assert "largest difference from the torch agent" in exported.stdout


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA GPU")
def test_a_gpu_is_refused_in_one_line_where_there_is_none_and_its_runs_still_load(tmp_path):
    result = dtd("train", "--env", "FetchReach-v4", "--device", "cuda", *TINY, "--run-dir", tmp_path / "gpu")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "dtd: error: --device cuda: torch finds no CUDA GPU on this machine; use --device cpu or auto"
    ]
    assert not (tmp_path / "gpu").exists()
    # A run whose config says cuda (as one trained on a GPU machine): looked at on the CPU, and
    # trained on with --device cpu.
    run = tmp_path / "run"
    assert (
        dtd(
            "train", "--env", "FetchReach-v4", "--learner", "tqc", "--epochs", "1", *TINY, "--run-dir", run
        ).returncode
        == 0
    )
    written = json.loads((run / "config.json").read_text())
    written["config"]["device"] = "cuda"
    (run / "config.json").write_text(json.dumps(written))
    assert dtd("eval", run, "--episodes", "2").returncode == 0
    resumed = dtd("train", "--resume", run, "--epochs", "2", "--device", "cpu")
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads((run / "config.json").read_text())["config"]["device"] == "cpu"
    auto = dtd(
        "train",
        "--env",
        "FetchReach-v4",
        "--device",
        "auto",
        "--epochs",
        "1",
        *TINY,
        "--run-dir",
        tmp_path / "auto",
    )
    assert auto.returncode == 0, auto.stderr
