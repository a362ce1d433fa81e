"""``dtd explore``: the server answers what ``subgoal_values`` says, refuses bad requests in
one line and stays up, serves nothing outside its own files, follows a run still training,
and its page works in a real browser (Debian's chromium driven by Playwright)."""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import http.client
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from dtd.config import Algo, Preset, preset_config
from dtd.explain.explore.server import WAITING_MAPS
from dtd.explain.heatmap import place_block_and_goal
from dtd.training.checkpoint import Checkpoint
from dtd.training.components import build_acting
from dtd.training.run_dir import RunDir, read_config, write_config
from tests.helpers import TINY, dtd

pytestmark = pytest.mark.smoke

pytest.importorskip("fastapi", reason="dtd explore needs the [explore] extra")

BLOCK = (1.15, 0.55)
GOAL = (1.45, 0.95)


@contextlib.contextmanager
def explorer(run_dir: Path, *options: str) -> Iterator[tuple[str, subprocess.Popen[str]]]:
    """``dtd explore RUN_DIR --port 0`` in a process of its own; its URL and the process."""
    process = subprocess.Popen(
        [sys.executable, "-m", "dtd", "explore", str(run_dir), "--port", "0", *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        found = re.search(r"http://\S+/", line)
        assert found, (
            f"no URL in {line!r}; stderr: {process.stderr.read() if process.poll() is not None else ''}"
        )
        yield found.group(0), process
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=30)


def get(url: str, body: bytes | None = None) -> tuple[int, dict]:
    """(status, JSON answer) of a GET, or of a POST of ``body`` as JSON."""
    headers = {"Content-Type": "application/json"} if body is not None else {}
    request = urllib.request.Request(url, data=body, headers=headers, method="POST" if body else "GET")
    try:
        with urllib.request.urlopen(request, timeout=120) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read() or b"{}")


def map_url(base: str, epoch: int, block=BLOCK, goal=GOAL, **extra: float) -> str:
    query = {"epoch": epoch, "block_x": block[0], "block_y": block[1], "goal_x": goal[0], "goal_y": goal[1]}
    return base + "api/map?" + "&".join(f"{k}={v}" for k, v in {**query, **extra}.items())


class HighLevel:
    """The run's agent at an epoch's snapshot, queried directly (not through the server)."""

    def __init__(self, run_dir: Path) -> None:
        self.run = RunDir(run_dir)
        config = read_config(self.run)
        self.acting = build_acting(config, eval_seed=0, eval_envs=1)
        self.env, self.agent = self.acting.envs[0], self.acting.agent

    def at(self, epoch: int) -> HighLevel:
        path = self.run.epoch_snapshot(epoch)
        Checkpoint.read(path).load_agent(self.agent, path)
        return self

    def values(self, block, goal, xs, ys, z) -> np.ndarray:
        """Q1 of the sub-goals at the cells (xs x ys at height z), the block and goal placed."""
        observation = place_block_and_goal(self.env, block, goal)
        grid_x, grid_y = np.meshgrid(xs, ys)
        cells = np.stack([grid_x.ravel(), grid_y.ravel(), np.full(grid_x.size, z)], axis=1)
        values = self.agent.subgoal_values(observation, np.asarray(observation["desired_goal"]), cells)
        return values.reshape(len(ys), len(xs))

    def choice(self, block, goal) -> np.ndarray:
        """The sub-goal the high level's actor chooses with the block and the goal placed."""
        observation = place_block_and_goal(self.env, block, goal)
        return self.agent.propose_subgoals(
            observation["observation"][None],
            observation["achieved_goal"][None],
            observation["desired_goal"][None],
        )[0]

    def close(self) -> None:
        self.acting.close()


@pytest.fixture(scope="module")
def served(push_dtd_run) -> Iterator[str]:
    with explorer(push_dtd_run) as (url, _):
        yield url


@pytest.fixture(scope="module")
def high_level(push_dtd_run) -> Iterator[HighLevel]:
    queried = HighLevel(push_dtd_run)
    yield queried
    queried.close()


def test_a_run_keeps_an_agent_only_snapshot_of_each_epoch(push_dtd_run):
    snapshots = RunDir(push_dtd_run).epoch_snapshots()
    assert list(snapshots) == [1, 2]
    stored = Checkpoint.read(snapshots[2])
    assert stored.epoch == 2 and not stored.whole and "buffer" not in stored.agent
    assert "critic" in stored.agent["high"] and "critic" not in stored.agent["low"]
    # Smaller than the checkpoint kept after the first epoch, which can resume training.
    assert snapshots[1].stat().st_size < RunDir(push_dtd_run).first.stat().st_size / 3


def test_the_map_is_the_high_levels_values_for_that_state(served, high_level):
    status, run = get(served + "api/run")
    assert status == 200 and run["epochs"] == [1, 2] and run["map"] and run["algo"] == "dtd"
    assert run["progress"] == {"epoch": 2, "env_steps": 400}  # read from metrics.csv
    for epoch in (1, 2):
        status, answer = get(map_url(served, epoch))
        assert status == 200, answer
        assert len(answer["xs"]) == len(answer["ys"]) == 50
        values = high_level.at(epoch).values(BLOCK, GOAL, answer["xs"], answer["ys"], answer["z"])
        choice = high_level.choice(BLOCK, GOAL)
        np.testing.assert_allclose(answer["values"], values, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(answer["subgoal"], choice, atol=1e-6)
        row, column = np.unravel_index(np.argmax(values), values.shape)
        assert answer["highest"][:2] == [answer["xs"][column], answer["ys"][row]]
    first, last = (get(map_url(served, epoch))[1]["values"] for epoch in (1, 2))
    assert first != last


def test_bad_requests_get_a_4xx_with_a_reason_and_the_server_stays_up(served):
    cases = [
        (map_url(served, 2, block=(3.0, 0.5)), None, 422, "off the table"),
        (map_url(served, 2, goal=(1.3, -2.0)), None, 422, "off the table"),
        (map_url(served, 7), None, 404, "no snapshot of epoch 7"),
        (map_url(served, 2, resolution=1), None, 422, "resolution"),
        (map_url(served, 2, z=5.0), None, 422, "z 5.000"),
        (served + "api/map?epoch=two&block_x=1.2", None, 422, "epoch"),
        (served + "api/episode", b"{not json", 400, "not valid JSON"),
        (served + "api/episode", b'{"epoch": 2, "block": [1.2]}', 422, "block"),
        (
            served + "api/episode",
            b'{"epoch": 2, "block": [1.2, 0.6], "goal": [9, 0.9]}',
            422,
            "off the table",
        ),
        (served + "api/episode", b'{"epoch": 99}', 404, "no snapshot of epoch 99"),
        (served + "api/episode", b'{"epoch": true}', 422, "epoch"),
        (served + "api/episode", b'{"epoch": "1"}', 422, "epoch"),
    ]
    for url, body, status, reason in cases:
        answered, answer = get(url, body)
        assert answered == status and reason in answer["error"], (url, body, answered, answer)
    assert get(served + "api/run")[0] == 200


def test_a_page_elsewhere_cannot_use_the_explorer(served):
    host, port = served.removeprefix("http://").rstrip("/").rsplit(":", 1)

    def ask(method: str, path: str, headers: dict[str, str], body: bytes | None = None) -> tuple[int, bytes]:
        connection = http.client.HTTPConnection(host, int(port), timeout=120)
        connection.request(method, path, body=body, headers={"Content-Type": "application/json", **headers})
        response = connection.getresponse()
        return response.status, response.read()

    # DNS rebinding: the attacker's name resolves to this machine, the Host header still says it.
    status, body = ask("GET", "/api/run", {"Host": "attacker.example"})
    assert status == 400 and b"push-dtd" not in body
    episode = b'{"epoch": 1}'
    rebound = {"Host": "attacker.example", "Origin": "http://attacker.example"}
    assert ask("POST", "/api/episode", rebound, episode)[0] == 400
    # A page elsewhere posting to the right address.
    elsewhere = {"Host": f"{host}:{port}", "Origin": "http://attacker.example"}
    assert ask("POST", "/api/episode", elsewhere, episode)[0] == 403
    assert ask("GET", map_url("/", 1), {"Host": f"{host}:{port}", "Sec-Fetch-Site": "cross-site"})[0] == 403
    assert ask("GET", "/api/run", {"Host": f"localhost:{port}"})[0] == 200


@pytest.mark.parametrize(
    "path",
    [
        "/static/../config.json",
        "/static/..%2Fconfig.json",
        "/static/..%2F..%2F..%2Fetc%2Fpasswd",
        "/static/%2e%2e/%2e%2e/config.json",
        "/static/explore.js/../../config.json",
        "/videos/..%2Fconfig.json",
        "/videos/..%2F..%2Fconfig.json",
        "/videos/episode-1.mp4%2F..%2F..%2Fconfig.json",
        "/static/index.html",
        "/static/__init__.py",
        "/config.json",
        "/metrics.csv",
        "/checkpoints/latest.pt",
    ],
)
def test_no_file_outside_the_page_and_its_videos_can_be_read(served, push_dtd_run, path):
    host = served.removeprefix("http://").rstrip("/")
    name, port = host.rsplit(":", 1)
    connection = http.client.HTTPConnection(name, int(port), timeout=30)
    connection.request("GET", path)  # sent as written: no client-side normalisation
    response = connection.getresponse()
    body = response.read()
    assert response.status == 404, (path, response.status, body[:200])
    secrets = [(push_dtd_run / "config.json").read_bytes()[:40], b"root:x:0:0", b"epoch,env_steps"]
    assert not any(secret in body for secret in secrets)


def test_twenty_requests_at_once_are_each_answered_for_their_own_placement_or_refused(served):
    blocks = [(1.1 + 0.02 * i, 0.5 + 0.025 * i) for i in range(20)]
    urls = [map_url(served, 1 + i % 2, block=block) for i, block in enumerate(blocks)]
    with concurrent.futures.ThreadPoolExecutor(max_workers=20) as pool:
        together = list(pool.map(get, urls))
    one_by_one = [get(url) for url in urls]
    # A few wait their turn; beyond those the server says at once that it is busy.
    answered = [status for status, _ in together if status == 200]
    assert len(answered) >= 1 + WAITING_MAPS
    for (status, answer), (_, alone), block, url in zip(together, one_by_one, blocks, urls, strict=True):
        if status == 503:
            assert "busy" in answer["error"]
            continue
        assert status == 200, answer
        np.testing.assert_allclose(answer["block"][:2], block, atol=1e-9)
        assert answer["epoch"] == int(url.split("epoch=")[1].split("&")[0])
        assert answer["values"] == alone["values"] and answer["subgoal"] == alone["subgoal"]


def test_snapshots_appear_while_the_page_is_open_and_ctrl_c_stops_it(push_dtd_run, tmp_path):
    # A run still training: its config is written, no epoch has finished yet.
    run_dir = tmp_path / "training"
    run_dir.mkdir()
    shutil.copy(push_dtd_run / "config.json", run_dir / "config.json")
    with explorer(run_dir) as (url, process):
        status, run = get(url + "api/run")
        assert status == 200 and run["epochs"] == [] and "no epoch has finished yet" in run["waiting"]
        status, answer = get(map_url(url, 1))
        assert status == 404 and "none yet" in answer["error"]
        snapshots = RunDir(run_dir).epoch_snapshots_dir
        snapshots.mkdir(parents=True)
        for epoch in (1, 2):
            written = snapshots / f"epoch-{epoch}.pt.partial"
            shutil.copy(RunDir(push_dtd_run).epoch_snapshot(epoch), written)
            written.rename(RunDir(run_dir).epoch_snapshot(epoch))
            assert get(url + "api/run")[1]["epochs"] == list(range(1, epoch + 1))
            assert get(map_url(url, epoch))[0] == 200
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=60)
        assert process.returncode == 0, err
        assert "stopped" in out and "Traceback" not in err


def test_the_command_refuses_what_cannot_work_in_one_line(push_dtd_run, tmp_path):
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = str(busy.getsockname()[1])
    try:
        result = subprocess.run(
            [sys.executable, "-m", "dtd", "explore", str(push_dtd_run), "--port", port],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        busy.close()
    assert result.returncode == 2 and "in use" in result.stderr and "Traceback" not in result.stderr
    result = subprocess.run(
        [sys.executable, "-m", "dtd", "explore", str(tmp_path / "nothing")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert result.returncode == 2 and "config.json is missing" in result.stderr
    for options, message in [
        (["--port", "70000"], "--port must lie in 0..65535"),
        (["--port", "-1"], "--port must lie in 0..65535"),
        (["--host", "999.1.1.1"], "not an address or a known name"),
    ]:
        result = dtd("explore", push_dtd_run, *options)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and message in lines[0], result.stderr


def test_a_hand_run_has_no_map_and_says_why(tmp_path):
    run_dir = tmp_path / "hand"
    run_dir.mkdir()
    config = dataclasses.replace(
        preset_config(Preset.tuned), env="HandManipulateBlockRotateZ-v1", algo=Algo.dtd
    )
    write_config(RunDir(run_dir), config, {})
    with explorer(run_dir, "--host", "0.0.0.0") as (url, process):
        status, run = get(url.replace("0.0.0.0", "127.0.0.1") + "api/run")
        assert status == 200 and not run["map"] and not run["placeable"]
        assert "orientation" in run["no_map_reason"]
        status, answer = get(map_url(url.replace("0.0.0.0", "127.0.0.1"), 1))
        assert status == 409 and "no value map" in answer["error"]
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=60)
    assert "warning" in err and "no login" in err


@pytest.mark.skipif(shutil.which("chromium") is None, reason="needs Debian's chromium (.ci/run installs it)")
def test_the_page_follows_a_dragged_block_the_epoch_slider_and_plays_an_episode(served, high_level):
    playwright = pytest.importorskip("playwright.sync_api", reason="the browser test needs Playwright")
    errors: list[str] = []
    with playwright.sync_playwright() as driver:
        browser = driver.chromium.launch(executable_path=shutil.which("chromium"), args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1300, "height": 950})
            page.on(
                "console", lambda message: errors.append(message.text) if message.type == "error" else None
            )
            page.on("pageerror", lambda error: errors.append(str(error)))
            page.goto(served)
            settled = (
                "v => { const s = window.dtdExplore.state; const c = document.getElementById('table');"
                " return Number(c.dataset.version) > v && !s.inFlight && !s.pending && !s.dragging; }"
            )
            page.wait_for_function(settled, arg=0)
            canvas = page.locator("#table")
            assert canvas.get_attribute("data-epoch") == "2"
            before = page.evaluate("JSON.stringify(window.dtdExplore.state.map.values)")
            image_before = page.evaluate("document.getElementById('table').toDataURL()")
            version = int(canvas.get_attribute("data-version"))

            # Drag the block 0.2 m along x and 0.15 m along y.
            box = canvas.bounding_box()
            start = page.evaluate("window.dtdExplore.toPixels(window.dtdExplore.state.block)")
            target = page.evaluate("p => window.dtdExplore.toPixels(p)", [BLOCK[0] + 0.2, BLOCK[1] + 0.15])
            scale = box["width"] / page.evaluate("document.getElementById('table').width")
            page.mouse.move(box["x"] + start[0] * scale, box["y"] + start[1] * scale)
            page.mouse.down()
            page.mouse.move(box["x"] + target[0] * scale, box["y"] + target[1] * scale, steps=8)
            page.mouse.up()
            page.wait_for_function(settled, arg=version)
            block = json.loads(canvas.get_attribute("data-block"))
            assert abs(block[0] - (BLOCK[0] + 0.2)) < 0.01 and abs(block[1] - (BLOCK[1] + 0.15)) < 0.01
            assert page.evaluate("JSON.stringify(window.dtdExplore.state.map.values)") != before
            assert page.evaluate("document.getElementById('table').toDataURL()") != image_before
            shown = json.loads(canvas.get_attribute("data-subgoal"))
            goal = json.loads(canvas.get_attribute("data-goal"))
            choice = high_level.at(2).choice(block[:2], goal[:2])
            np.testing.assert_allclose(shown, choice, atol=1e-5)
            assert (
                page.locator("#subgoal-at").inner_text() == "(" + ", ".join(f"{v:.3f}" for v in choice) + ")"
            )

            # The epoch slider shows the map after epoch 1, with that epoch's choice.
            version = int(canvas.get_attribute("data-version"))
            page.locator("#epoch").fill("0")
            page.wait_for_function(settled, arg=version)
            assert canvas.get_attribute("data-epoch") == "1"
            choice = high_level.at(1).choice(block[:2], goal[:2])
            np.testing.assert_allclose(json.loads(canvas.get_attribute("data-subgoal")), choice, atol=1e-5)

            # An episode from this placement plays, with its plan in numbers.
            page.locator("#play").click()
            page.wait_for_function(
                "() => { const v = document.getElementById('video');"
                " return !v.hidden && v.readyState >= 2 && v.currentTime > 0; }",
                timeout=120_000,
            )
            plan = page.locator("#plan").inner_text()
            assert "Epoch 1" in plan and "segment 1" in plan and f"{block[0]:.3f}" in plan
        finally:
            browser.close()
    assert errors == []


def test_pick_and_place_maps_a_slice_at_any_height_with_the_goal_in_the_air(tmp_path):
    run_dir = tmp_path / "pick"
    args = ["train", "--env", "FetchPickAndPlace-v4", "--algo", "dtd", "--epochs", "1", *TINY]
    assert dtd(*args, "--run-dir", run_dir).returncode == 0
    with explorer(run_dir) as (url, _):
        status, run = get(url + "api/run")
        assert status == 200 and run["goal_in_air"] and run["map"]
        table_z = run["table"]["block_z"]
        _, low = get(map_url(url, 1, goal_z=table_z + 0.2))
        _, high = get(map_url(url, 1, goal_z=table_z + 0.2, z=table_z + 0.3))
        assert low["z"] == pytest.approx(table_z) and high["z"] == pytest.approx(table_z + 0.3)
        assert low["goal"][2] == pytest.approx(table_z + 0.2)
        assert low["values"] != high["values"]
        status, answer = get(map_url(url, 1, goal_z=table_z + 0.9))
        assert status == 422 and "goal's z" in answer["error"]
