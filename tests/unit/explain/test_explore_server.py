"""The explorer's server without a simulator: its bounded line of work (one call running, a
few waiting, the rest refused at once, waiting calls of clients that have gone dropped), ``/api/run``
answered while an episode plays, the Host and Origin it answers, and strict request types."""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import http.client
import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("fastapi", reason="dtd explore needs the [explore] extra")

import uvicorn

from dtd.explain.explore.server import (
    WAITING_EPISODES,
    Gate,
    allowed_hosts,
    create_app,
    foreign_request,
)

HOSTS = allowed_hosts("127.0.0.1")


class HeldExplorer:
    """Stands in for an Explorer: each episode waits until the test lets it end."""

    def __init__(self, videos: Path) -> None:
        self.videos = videos
        self.release = threading.Event()
        self.played: list[int] = []

    def describe(self) -> dict:
        return {"epochs": [1, 2]}

    def play(self, epoch, block, goal) -> dict:
        self.played.append(epoch)
        assert self.release.wait(timeout=60)
        return {"epoch": epoch, "video": "episode-1.mp4", "block": block, "goal": goal}

    def value_map(self, epoch, block, goal, z, resolution) -> dict:
        return {"epoch": epoch}


@contextlib.contextmanager
def serving(tmp_path: Path) -> Iterator[tuple[int, HeldExplorer, dict]]:
    explorer = HeldExplorer(tmp_path)
    workers = [concurrent.futures.ThreadPoolExecutor(max_workers=1) for _ in range(2)]
    app = create_app(explorer, explorer, *workers, hosts=HOSTS)
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(64)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    wait_until(lambda: server.started or not thread.is_alive(), "the server did not start")
    assert server.started, "the server stopped before it listened"
    try:
        yield sock.getsockname()[1], explorer, app.state.gates
    finally:
        explorer.release.set()
        server.should_exit = True
        thread.join(timeout=30)
        for worker in workers:
            worker.shutdown()
        sock.close()


def ask(port: int, method: str, path: str, body: object = None, **headers: str) -> tuple[int, dict]:
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    data = json.dumps(body).encode() if body is not None else None
    sent = {"Content-Type": "application/json", **{k.replace("_", "-"): v for k, v in headers.items()}}
    connection.request(method, path, body=data, headers=sent)
    response = connection.getresponse()
    return response.status, json.loads(response.read() or b"{}")


def send_episode(port: int) -> socket.socket:
    """An episode request sent on a raw socket, its answer not read."""
    client = socket.create_connection(("127.0.0.1", port))
    body = b'{"epoch": 1}'
    client.sendall(
        b"POST /api/episode HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        + f"Content-Length: {len(body)}\r\n\r\n".encode()
        + body
    )
    return client


def wait_until(condition, what: str) -> None:
    deadline = time.monotonic() + 30  # a guard against a hang, not a measure of speed
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


def test_while_an_episode_plays_one_waits_the_rest_are_refused_and_run_is_answered(tmp_path):
    with serving(tmp_path) as (port, explorer, gates):
        with concurrent.futures.ThreadPoolExecutor(4) as pool:
            first = pool.submit(ask, port, "POST", "/api/episode", {"epoch": 1})
            wait_until(lambda: explorer.played == [1], "the first episode did not start")
            second = pool.submit(ask, port, "POST", "/api/episode", {"epoch": 2})
            wait_until(lambda: gates["episode"].admitted == 1 + WAITING_EPISODES, "the second did not queue")
            for _ in range(5):
                status, answer = ask(port, "POST", "/api/episode", {"epoch": 2})
                assert status == 503 and "busy" in answer["error"], answer
            # The run's facts and the value maps do not wait for the episode.
            assert ask(port, "GET", "/api/run") == (200, {"epochs": [1, 2]})
            status, _ = ask(port, "GET", "/api/map?epoch=1&block_x=1&block_y=1&goal_x=1&goal_y=1")
            assert status == 200
            assert not first.done() and explorer.played == [1]
            explorer.release.set()
            assert first.result(timeout=60)[0] == 200 and second.result(timeout=60)[0] == 200
        assert explorer.played == [1, 2] and gates["episode"].admitted == 0


def test_a_waiting_episode_whose_client_has_gone_is_not_played(tmp_path):
    with serving(tmp_path) as (port, explorer, gates):
        first = send_episode(port)
        wait_until(lambda: explorer.played == [1], "the first episode did not start")
        gone = send_episode(port)
        wait_until(lambda: gates["episode"].admitted == 2, "the second did not queue")
        gone.close()
        wait_until(lambda: gates["episode"].admitted == 1, "the gone client's request kept its place")
        explorer.release.set()
        assert first.recv(4096).startswith(b"HTTP/1.1 200")
        first.close()
        assert explorer.played == [1]


@pytest.mark.parametrize(
    "body", [{"epoch": True}, {"epoch": "1"}, {"epoch": 1.0}, {"epoch": 1, "block": [True, 1]}]
)
def test_an_epoch_or_coordinate_of_another_type_is_refused(tmp_path, body):
    with serving(tmp_path) as (port, explorer, _):
        status, answer = ask(port, "POST", "/api/episode", body)
        assert status == 422, answer
        assert explorer.played == []


def test_requests_for_another_host_or_from_another_origin_are_refused(tmp_path):
    with serving(tmp_path) as (port, explorer, _):
        status, answer = ask(port, "GET", "/api/run", Host="attacker.example")
        assert status == 400 and "attacker.example" in answer["error"] and "run" not in answer
        status, answer = ask(
            port,
            "POST",
            "/api/episode",
            {"epoch": 1},
            Host=f"127.0.0.1:{port}",
            Origin="http://attacker.example",
        )
        assert status == 403 and "attacker.example" in answer["error"]
        status, _ = ask(port, "GET", "/api/run", Host=f"localhost:{port}", Sec_Fetch_Site="cross-site")
        assert status == 403
        assert explorer.played == []
        # The page's own requests, and a client that names no origin (curl, scripts).
        own = {
            "Host": f"127.0.0.1:{port}",
            "Origin": f"http://127.0.0.1:{port}",
            "Sec_Fetch_Site": "same-origin",
        }
        assert ask(port, "GET", "/api/run", **own)[0] == 200
        assert ask(port, "GET", "/api/run", Host=f"localhost:{port}")[0] == 200


@pytest.mark.parametrize(
    ("path", "headers", "refused"),
    [
        ("/api/run", {"host": "127.0.0.1:8000"}, None),
        ("/api/run", {"host": "[::1]:8000"}, None),
        ("/api/run", {"host": "LOCALHOST:8000"}, None),
        ("/api/run", {}, 400),
        ("/api/run", {"host": "127.0.0.1.attacker.example:8000"}, 400),
        ("/api/run", {"host": "[::1"}, 400),
        ("/", {"host": "attacker.example"}, 400),
        # The page may be opened from a link on another site; its API may not be used from there.
        ("/", {"host": "127.0.0.1:8000", "sec-fetch-site": "cross-site"}, None),
        ("/videos/episode-1.mp4", {"host": "127.0.0.1:8000", "sec-fetch-site": "cross-site"}, 403),
        ("/api/map", {"host": "127.0.0.1:8000", "origin": "http://127.0.0.1:8001"}, 403),
        ("/api/map", {"host": "127.0.0.1:8000", "origin": "null"}, 403),
        ("/api/map", {"host": "127.0.0.1:8000", "sec-fetch-site": "same-site"}, 403),
        ("/api/map", {"host": "127.0.0.1:8000", "sec-fetch-site": "none"}, None),
    ],
)
def test_which_requests_are_for_this_server(path, headers, refused):
    answer = foreign_request(path, headers, HOSTS)
    assert (answer[0] if answer else None) == refused, answer


def test_a_wildcard_address_also_answers_to_this_machines_name():
    assert socket.gethostname().lower() in allowed_hosts("0.0.0.0")
    assert (
        socket.gethostname().lower() not in allowed_hosts("127.0.0.1") or socket.gethostname() == "localhost"
    )


def test_the_gate_drops_a_call_whose_client_went_while_it_waited():
    class Client:
        def __init__(self, gone: bool) -> None:
            self.gone = gone

        async def is_disconnected(self) -> bool:
            return self.gone

    async def scenario() -> list[str]:
        with concurrent.futures.ThreadPoolExecutor(max_workers=1) as worker:
            gate = Gate(worker, "episode", waiting=1)
            calls: list[str] = []
            release = threading.Event()
            running = asyncio.ensure_future(
                gate.run(Client(False), lambda: (calls.append("a"), release.wait(30)))
            )
            while not calls:
                await asyncio.sleep(0.01)
            waiting = asyncio.ensure_future(gate.run(Client(True), lambda: calls.append("b")))
            with pytest.raises(Exception, match="client has gone"):
                await waiting
            release.set()
            await running
            assert gate.admitted == 0 and not gate.turn.locked()
            return calls

    assert asyncio.run(scenario()) == ["a"]
