"""dtd render, dtd heatmap and dtd report on tiny trained runs."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from dtd.agents.dot_to_dot import DotToDotAgent
from dtd.envs.make import make_env
from dtd.envs.spec import env_spec
from dtd.explain.heatmap import place_block_and_goal, run_heatmaps, table_of
from dtd.explain.render import (
    DOT_RADIUS,
    GHOST_BESIDE,
    GOAL_RGBA,
    SUBGOAL_RGBA,
    Marker,
    SceneRenderer,
    camera_for,
    goal_markers,
    render_episode,
)
from dtd.training.trained_run import load_run
from tests.helpers import dtd

pytestmark = pytest.mark.smoke


def is_red(pixel: np.ndarray) -> bool:
    return pixel[0] > 150 and pixel[1] < 110 and pixel[2] < 110


def is_green(pixel: np.ndarray) -> bool:
    return pixel[1] > 150 and pixel[0] < 90 and pixel[2] < 90


def colour_near(frame: np.ndarray, pixel: tuple[float, float], test) -> bool:
    """Whether a pixel within 1 of ``pixel`` (column, row) passes ``test``."""
    column, row = round(pixel[0]), round(pixel[1])
    patch = frame[max(row - 1, 0) : row + 2, max(column - 1, 0) : column + 2].reshape(-1, 3)
    return any(test(value) for value in patch)


def test_a_run_keeps_its_first_epoch_checkpoint(push_dtd_run):
    loaded = load_run(push_dtd_run, "first")
    loaded.close()
    assert loaded.checkpoint.epoch == 1 and loaded.checkpoint.whole
    assert "buffer" not in loaded.checkpoint.agent


def test_rendered_frames_show_goal_and_subgoal_where_they_project(push_dtd_run):
    loaded = load_run(push_dtd_run, "latest", seed=5)
    env, agent, spec = loaded.envs[0], loaded.agent, loaded.spec
    assert isinstance(agent, DotToDotAgent)
    renderer = SceneRenderer(env, width=320, height=240, camera=camera_for(spec.env_id))
    try:
        rendered = render_episode(env, agent, spec, renderer, loaded.rng, agent.bounds)
    finally:
        renderer.close()
        loaded.close()
    assert len(rendered.frames) == spec.horizon + 1
    assert all(frame.shape == (240, 320, 3) and frame.dtype == np.uint8 for frame in rendered.frames)

    # The sub-goal shown is the one in force: constant within a segment, changed at its start.
    step_goals = rendered.episode.step_goal[0]
    boundary = int(agent.bounds[1])
    pixels = rendered.subgoal_pixels
    assert all(pixels[t] == pixels[0] for t in range(boundary))
    last_segment = range(boundary, spec.horizon + 1)
    assert all(np.allclose(pixels[t], rendered.goal_pixels[t], atol=0.05) for t in last_segment)
    assert not np.allclose(pixels[0], rendered.goal_pixels[0], atol=1.0)
    goal = rendered.episode.desired_goal[0]
    np.testing.assert_allclose(step_goals[boundary:], np.broadcast_to(goal, step_goals[boundary:].shape))

    # Where the markers project, their colours are in the image (in frames where the arm, which
    # may stand between them and the camera, leaves them in view).
    first_segment = range(boundary)
    assert any(
        colour_near(rendered.frames[t], rendered.goal_pixels[t], is_red) for t in range(spec.horizon + 1)
    )
    assert any(colour_near(rendered.frames[t], pixels[t], is_green) for t in first_segment)


def test_markers_are_drawn_where_they_project():
    env = make_env("FetchPush-v4")
    env.reset(seed=0)
    renderer = SceneRenderer(env, width=320, height=240, camera=camera_for("FetchPush-v4"))
    try:
        # Points on the front half of the table, which the arm at rest does not hide.
        red_points = [np.array([1.45, 0.55, 0.43]), np.array([1.2, 1.0, 0.43])]
        green_points = [np.array([1.5, 0.8, 0.43]), np.array([1.25, 0.45, 0.43])]
        markers = [Marker(p, GOAL_RGBA, DOT_RADIUS) for p in red_points]
        markers += [Marker(p, SUBGOAL_RGBA, DOT_RADIUS) for p in green_points]
        frame = renderer.render(markers)
        bare = renderer.render([])
        assert frame.shape == (240, 320, 3)
        for point in red_points:
            pixel = renderer.project(point)
            assert colour_near(frame, pixel, is_red) and not colour_near(bare, pixel, is_red), pixel
        for point in green_points:
            pixel = renderer.project(point)
            assert colour_near(frame, pixel, is_green) and not colour_near(bare, pixel, is_green), pixel
    finally:
        renderer.close()
        env.close()


def test_render_command_writes_videos_strips_and_plans(reach_run, tmp_path):
    size = ["--width", "128", "--height", "96"]
    result = dtd("render", reach_run, "--episodes", "2", "--out", tmp_path / "frames", *size)
    assert result.returncode == 0, result.stderr
    for number in (1, 2):
        video = tmp_path / "frames" / f"episode-{number}.mp4"
        assert video.stat().st_size > 1000
        assert (tmp_path / "frames" / f"episode-{number}-keyframes.png").read_bytes()[:4] == b"\x89PNG"
    plans = json.loads((tmp_path / "frames" / "plans.json").read_text())
    assert [plan["episode"] for plan in plans] == [1, 2]
    assert plans[0]["subgoals"] == []  # a her run has no sub-goals


def test_heatmap_values_are_the_high_levels_values(push_dtd_run, tmp_path):
    path, columns = run_heatmaps(push_dtd_run, tmp_path / "heat.png", ["first", "latest"], resolution=7)
    assert path.read_bytes()[:4] == b"\x89PNG"
    assert [label for label, _ in columns] == ["after epoch 1 (first)", "after epoch 2 (latest)"]
    heat = columns[1][1][0]
    assert heat.values.shape == (7, 7)
    loaded = load_run(push_dtd_run, "latest")
    try:
        env, agent = loaded.envs[0], loaded.agent
        table = table_of(env)
        observation = place_block_and_goal(env, (1.15, 0.55), (1.45, 0.95))
        np.testing.assert_allclose(observation["achieved_goal"], [1.15, 0.55, table.block_z], atol=1e-6)
        for row, column in [(0, 0), (3, 5), (6, 2)]:
            cell = np.array([[heat.xs[column], heat.ys[row], heat.z]])
            direct = agent.subgoal_values(observation, observation["desired_goal"], cell)[0]
            assert heat.values[row, column] == pytest.approx(direct, abs=1e-6)
    finally:
        loaded.close()
    assert table.x[0] < heat.xs[0] < heat.xs[-1] < table.x[1]
    # The first epoch's critic is another function than the last one's.
    assert not np.allclose(columns[0][1][0].values, heat.values)


def test_heatmap_refuses_runs_without_a_high_level_and_points_off_the_table(reach_run, push_dtd_run):
    result = dtd("heatmap", reach_run)
    assert result.returncode == 2 and "her run" in result.stderr
    result = dtd("heatmap", push_dtd_run, "--start", "2.0,0.5")
    assert result.returncode == 2 and "off the table" in result.stderr


@pytest.mark.skipif(shutil.which("chromium") is None, reason="needs Debian's chromium (.ci/run installs it)")
def test_report_opens_in_a_browser_with_every_image_and_video_loaded(push_dtd_run, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(push_dtd_run, run_dir)
    last_epoch = len((run_dir / "metrics.csv").read_text().strip().splitlines()) - 1
    saved = {"epoch": last_epoch, "episodes": 100, "success_rate": 0.37}
    (run_dir / "eval-latest.json").write_text(json.dumps(saved))
    result = dtd("report", run_dir, "--episodes", "2", "--resolution", "8")
    assert result.returncode == 0, result.stderr
    page = run_dir / "report.html"
    browser = subprocess.run(
        ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000",
         "--dump-dom", page.resolve().as_uri()],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    media = re.findall(r"<(img|video)\b[^>]*>", browser.stdout)
    tags = re.findall(r"<(?:img|video)\b[^>]*>", browser.stdout)
    assert media.count("img") == 4 and media.count("video") == 2, tags  # curves, heatmaps, 2 strips
    assert all('data-status="loaded"' in tag for tag in tags), tags
    text = page.read_text()
    assert "Configuration" in text and "Plans" in text and "--segments" in text
    assert f"dtd explore {run_dir}" in text
    assert "0.37 over 100 episodes (eval-latest.json)" in text  # the final of record, not the last epoch's


def test_a_hand_subgoal_is_a_green_ghost_block_beside_the_goals():
    name = "HandManipulateBlockRotateXYZ-v1"
    env = make_env(name)
    env.reset(seed=0)
    spec = env_spec(env, name)
    goal = np.array(env.unwrapped.goal)
    subgoal = goal.copy()
    subgoal[3:] = [0.5, 0.5, 0.5, 0.5]
    (marker,) = goal_markers(env, spec, goal, subgoal)
    np.testing.assert_allclose(marker.quaternion, [0.5, 0.5, 0.5, 0.5])
    # The environment shows the goal's ghost 15 cm beside the hand; the sub-goal's sits next to it.
    np.testing.assert_allclose(marker.position, goal[:3] + np.array([0.15, 0.0, 0.0]) + GHOST_BESIDE)
    renderer = SceneRenderer(env, width=240, height=240, camera=camera_for(name))
    try:
        with_ghost, without = renderer.render([marker]), renderer.render([])
        column, row = map(round, renderer.project(marker.position))
        assert with_ghost[row, column, 1] > with_ghost[row, column, 0] + 50  # green over the ghost
        assert not np.array_equal(with_ghost[row, column], without[row, column])
    finally:
        renderer.close()
        env.close()
