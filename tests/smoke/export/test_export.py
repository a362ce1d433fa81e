"""``dtd export``: ONNX Runtime's outputs equal the torch agent's on recorded observations, an
episode driven by the exported models alone (no dtd in that process) ends where the torch
agent's does, and bad input is refused in one line."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dtd.agents.dot_to_dot import DotToDotAgent
from dtd.agents.segments import high_level_input
from dtd.envs.make import make_env
from dtd.envs.time_feature import TimeFeature
from dtd.training.rollout import run_many
from tests.helpers import TINY, dtd

pytestmark = pytest.mark.smoke

onnxruntime = pytest.importorskip("onnxruntime", reason="dtd export needs the [export] extra")

RECORDED = 1_000


@pytest.fixture(scope="module")
def exported(push_dtd_run, reach_run, tmp_path_factory) -> dict[str, Path]:
    folders = {}
    for name, run in (("dtd", push_dtd_run), ("her", reach_run)):
        out = tmp_path_factory.mktemp("export") / name
        result = dtd("export", run, "--out", out)
        assert result.returncode == 0, result.stderr
        assert "largest difference from the torch agent" in result.stdout
        folders[name] = out
    return folders


def recorded(run_dir: Path) -> tuple[object, dict[str, np.ndarray]]:
    """The run's agent and the observations of deterministic episodes (at least RECORDED steps)."""
    from dtd.training.trained_run import load_run

    with load_run(run_dir, "latest", seed=5, envs=10) as loaded:
        spec = loaded.spec
        episodes = run_many(loaded.envs, loaded.agent, spec, -(-RECORDED // 50), False, loaded.rng)
    steps = {
        "observation": episodes.obs[:, :-1].reshape(-1, spec.obs_dim)[:RECORDED],
        "achieved_goal": episodes.achieved_goal[:, :-1].reshape(-1, spec.goal_dim)[:RECORDED],
        "goal": np.repeat(episodes.desired_goal, spec.horizon, axis=0)[:RECORDED],
        "step_goal": episodes.step_goal.reshape(-1, spec.goal_dim)[:RECORDED],
    }
    return loaded.agent, steps


def session(folder: Path, role: str):
    policy = json.loads((folder / "policy.json").read_text())
    return onnxruntime.InferenceSession(str(folder / policy["models"][role]["file"]))


def test_policy_json_says_what_a_program_needs(exported, push_dtd_run):
    dtd_policy = json.loads((exported["dtd"] / "policy.json").read_text())
    assert dtd_policy["env_id"] == "FetchPush-v4" and dtd_policy["algo"] == "dtd"
    assert set(dtd_policy["models"]) == {"low_level", "high_level", "high_level_value"}
    assert dtd_policy["segments"]["bounds"][0] == 0 and dtd_policy["segments"]["bounds"][-1] == 50
    assert dtd_policy["checkpoint"]["epoch"] == 2 and dtd_policy["opset"] >= 13
    assert dtd_policy["checkpoint"]["path"] == "checkpoints/latest.pt"
    assert dtd_policy["checkpoint"]["run"] == push_dtd_run.name
    assert {"dtd", "torch", "onnx", "onnxruntime"} <= set(dtd_policy["versions"])
    assert len(dtd_policy["goal_box"]["low"]) == 3
    her_policy = json.loads((exported["her"] / "policy.json").read_text())
    assert set(her_policy["models"]) == {"policy"} and "segments" not in her_policy
    low = session(exported["dtd"], "low_level")
    assert [i.name for i in low.get_inputs()] == ["observation", "subgoal"]
    assert [o.name for o in low.get_outputs()] == ["action"]
    assert low.get_inputs()[0].shape[0] == "batch"


def test_onnx_outputs_equal_the_torch_agents_on_recorded_observations(exported, push_dtd_run, reach_run):
    agent, steps = recorded(push_dtd_run)
    assert isinstance(agent, DotToDotAgent) and len(steps["observation"]) == RECORDED
    obs, achieved, goal = steps["observation"], steps["achieved_goal"], steps["goal"]
    folder = exported["dtd"]
    (actions,) = session(folder, "low_level").run(None, {"observation": obs, "subgoal": steps["step_goal"]})
    np.testing.assert_allclose(actions, agent.low.act(obs, steps["step_goal"]), atol=1e-5)
    feeds = {"observation": obs, "achieved_goal": achieved, "goal": goal}
    (subgoals,) = session(folder, "high_level").run(None, feeds)
    np.testing.assert_allclose(subgoals, agent.propose_subgoals(obs, achieved, goal), atol=1e-5)
    candidates = (achieved + np.random.default_rng(0).normal(0, 0.1, achieved.shape)).astype(np.float32)
    (values,) = session(folder, "high_level_value").run(None, {**feeds, "subgoal": candidates})
    expected = agent.high.q_values(high_level_input(obs, achieved), goal, candidates)
    np.testing.assert_allclose(values, expected, atol=1e-5, rtol=1e-6)

    agent, steps = recorded(reach_run)
    (actions,) = session(exported["her"], "policy").run(
        None, {"observation": steps["observation"], "goal": steps["goal"]}
    )
    np.testing.assert_allclose(actions, agent.learner.act(steps["observation"], steps["goal"]), atol=1e-5)


def torch_episode(run_dir: Path, seed: int) -> np.ndarray:
    """The final achieved goal of the torch agent's deterministic episode from env.reset(seed)."""
    from dtd.training.trained_run import load_run

    with load_run(run_dir) as loaded:
        agent, spec = loaded.agent, loaded.spec
    env = make_env(spec.env_id)
    if loaded.config.time_feature:
        env = TimeFeature(env)
    o, _ = env.reset(seed=seed)
    rng = np.random.default_rng(0)
    for t in range(spec.horizon):
        goal = agent.step_goal(
            o["observation"][None], o["achieved_goal"][None], o["desired_goal"][None], t, False, rng
        )
        action = agent.act(o["observation"][None].astype(np.float32), goal.astype(np.float32), False, rng)
        o, *_ = env.step(action[0])
    env.close()
    return o["achieved_goal"]


def run_readme_example(folder: Path) -> list[float]:
    """The final achieved goal of the README's example episode, run where dtd cannot be imported."""
    code = re.search(r"```python\n(.*?)```", (folder / "README.md").read_text(), re.S).group(1)
    assert len(code.strip().splitlines()) <= 19
    blocked = "import sys\nsys.modules['dtd'] = None  # importing dtd would fail here\n"
    result = subprocess.run(
        [sys.executable, "-c", blocked + code], capture_output=True, text=True, timeout=300, cwd=folder
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])["achieved_goal"]


def test_a_run_with_the_time_feature_exports_it_and_the_example_appends_it(tmp_path):
    run, out = tmp_path / "run", tmp_path / "onnx"
    args = ["--env", "FetchReach-v4", "--algo", "dtd", "--time-feature", "--epochs", "1", *TINY]
    assert dtd("train", *args, "--run-dir", run).returncode == 0
    result = dtd("export", run, "--out", out)
    assert result.returncode == 0, result.stderr
    policy = json.loads((out / "policy.json").read_text())
    assert policy["time_feature"] is True and policy["obs_dim"] == 11  # FetchReach's 10, and the time left
    np.testing.assert_allclose(run_readme_example(out), torch_episode(run, seed=0), atol=1e-4)


@pytest.mark.parametrize("name", ["dtd", "her"])
def test_the_readme_example_drives_an_episode_without_dtd(exported, push_dtd_run, reach_run, name):
    expected = torch_episode(push_dtd_run if name == "dtd" else reach_run, seed=0)
    np.testing.assert_allclose(run_readme_example(exported[name]), expected, atol=1e-4)


def test_bad_input_is_one_line(push_dtd_run, tmp_path, exported):
    config_only = tmp_path / "untrained"
    config_only.mkdir()
    (config_only / "config.json").write_text((push_dtd_run / "config.json").read_text())
    a_file = tmp_path / "a-file"
    a_file.write_text("kept")
    cases = [
        (["export", config_only, "--out", tmp_path / "a"], "no checkpoint"),
        (["export", push_dtd_run, "--checkpoint", "newest", "--out", tmp_path / "b"], "no checkpoint named"),
        (["export", push_dtd_run, "--out", exported["dtd"]], "already exists"),
        (["export", push_dtd_run, "--out", a_file], "is a file"),
        (["export", push_dtd_run, "--out", a_file, "--force"], "is a file"),
    ]
    for args, message in cases:
        result = dtd(*args)
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
    assert a_file.read_text() == "kept"
    missing = subprocess.run(
        [sys.executable, "-c", "import sys; sys.modules['onnxruntime'] = None\nfrom dtd.cli import main\n"
         f"main(['export', {str(push_dtd_run)!r}, '--out', {str(tmp_path / 'c')!r}])"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert missing.returncode == 2 and "pip install 'dtd[export]'" in missing.stderr


def test_a_hand_runs_exported_sub_goals_are_poses_in_the_goal_box(tmp_path):
    run_dir = tmp_path / "hand"
    args = ["train", "--env", "HandManipulateBlockRotateZ-v1", "--algo", "dtd", "--epochs", "1", *TINY]
    assert dtd(*args, "--run-dir", run_dir).returncode == 0
    result = dtd("export", run_dir, "--out", tmp_path / "onnx")
    assert result.returncode == 0, result.stderr
    policy = json.loads((tmp_path / "onnx" / "policy.json").read_text())
    start, stop = policy["goal_quaternion"]
    rng = np.random.default_rng(0)
    feeds = {
        name: rng.normal(0.0, 3.0, (500, width)).astype(np.float32)
        for name, width in (("observation", policy["obs_dim"]), ("achieved_goal", 7), ("goal", 7))
    }
    (subgoals,) = session(tmp_path / "onnx", "high_level").run(None, feeds)
    np.testing.assert_allclose(np.linalg.norm(subgoals[:, start:stop], axis=1), 1.0, atol=1e-5)
    low, high = np.array(policy["goal_box"]["low"]), np.array(policy["goal_box"]["high"])
    assert np.all(subgoals[:, :start] >= low[:start] - 1e-6) and np.all(
        subgoals[:, :start] <= high[:start] + 1e-6
    )
