"""The web side of ``dtd explore``: a FastAPI app over a run's :class:`Explorer`, served by uvicorn.

Episodes and value maps each have an :class:`Explorer` of their own on a worker thread of its
own (an Explorer is not thread-safe, and an EGL context belongs to the thread that made it), so a
map is drawn while an episode plays, and ``/api/run`` (files only) waits for neither. Each worker
takes one call at a time and keeps a short line (:class:`Gate`): what comes beyond it is answered
503 at once, and a waiting call whose client has gone is dropped.

Only requests for this server are answered: a Host header that names it (the address it listens
on, or this machine by localhost / 127.0.0.1 / ::1), and, where a browser says where a request
comes from (Origin, Sec-Fetch-Site), from the page's own origin; so a page elsewhere cannot use
the explorer, not even through DNS rebinding. Files are served from two fixed places only: the
page's own files, named in ``PAGE_FILES``, and the videos the explorer wrote, by a name of the
form ``episode-N.mp4``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import errno
import ipaddress
import re
import socket
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar
from urllib.parse import urlsplit

import uvicorn
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from pydantic import BaseModel, Field, StrictFloat, StrictInt
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException as StarletteHTTPException

from dtd.errors import DtdError
from dtd.explain.explore.session import MAP_RESOLUTION, ExploreError, Explorer

PAGE_FILES = {
    "explore.js": "text/javascript; charset=utf-8",
    "explore.css": "text/css; charset=utf-8",
}
"""The page's files besides index.html; nothing else is served from the package."""
VIDEO_NAME = re.compile(r"episode-[0-9]{1,9}\.mp4")

Result = TypeVar("Result")


class EpisodeRequest(BaseModel):
    """What ``POST /api/episode`` takes: the epoch, and for the Fetch block tasks where the
    block (x, y) and the goal (x, y, or x, y, z) start."""

    # Strict: true and "1" are not epoch 1; a coordinate is a JSON number.
    epoch: StrictInt
    block: list[StrictFloat | StrictInt] | None = Field(default=None, min_length=2, max_length=2)
    goal: list[StrictFloat | StrictInt] | None = Field(default=None, min_length=2, max_length=3)


WAITING_EPISODES = 1
"""Episode requests that may wait while one plays; more are answered 503 at once."""
WAITING_MAPS = 4
"""Value-map requests that may wait while one is computed (a page asks for one at a time)."""
CLIENT_CHECK_S = 0.25
"""How often a waiting request checks that its client is still there."""


class Gate:
    """The calls of one worker thread: one runs, at most ``waiting`` more wait their turn (first
    come, first served), and anything beyond is refused at once with a reason. A waiting call
    whose client has gone is dropped before it starts."""

    def __init__(self, worker: concurrent.futures.Executor, what: str, waiting: int) -> None:
        self.worker = worker
        self.what = what
        self.waiting = waiting
        self.admitted = 0
        self.turn = asyncio.Lock()

    async def run(self, request: Request, call: Callable[[], Result]) -> Result:
        if self.admitted > self.waiting:
            raise ExploreError(503, f"busy with {self.admitted} {self.what} requests; try again shortly")
        self.admitted += 1
        try:
            await self._wait_turn(request)
            try:
                return await asyncio.wrap_future(self.worker.submit(call))
            finally:
                self.turn.release()
        finally:
            self.admitted -= 1

    async def _wait_turn(self, request: Request) -> None:
        """Hold the turn, or raise (499) once the client has gone."""
        acquiring = asyncio.ensure_future(self.turn.acquire())
        try:
            while True:
                await asyncio.wait({acquiring}, timeout=CLIENT_CHECK_S)
                if await request.is_disconnected():
                    raise ExploreError(499, "the client has gone")
                if acquiring.done():
                    return
        except BaseException:
            if acquiring.done() and not acquiring.cancelled() and acquiring.exception() is None:
                self.turn.release()
            else:
                acquiring.cancel()
            raise


def allowed_hosts(host: str) -> frozenset[str]:
    """The names a Host header may give for a server listening on ``host``: that address, and
    this machine by loopback; for a wildcard address (0.0.0.0, ::) also this machine's names
    and their addresses."""
    names = {host.strip("[]").lower(), "localhost", "127.0.0.1", "::1"}
    if host in ("0.0.0.0", "::", ""):
        for name in {socket.gethostname(), socket.getfqdn()}:
            names.add(name.lower())
            with contextlib.suppress(OSError):
                names.update(info[4][0] for info in socket.getaddrinfo(name, None))
    return frozenset(names)


def create_app(
    episodes: Explorer,
    maps: Explorer,
    episode_worker: concurrent.futures.Executor,
    map_worker: concurrent.futures.Executor,
    hosts: frozenset[str] = frozenset({"localhost", "127.0.0.1", "::1"}),
) -> FastAPI:
    """The app: the page, its files, the videos, and the API under /api; ``episodes`` lives on
    ``episode_worker``'s one thread and ``maps`` on ``map_worker``'s; only requests whose Host
    is one of ``hosts`` are answered (:func:`allowed_hosts`)."""
    app = FastAPI(title="dtd explore", docs_url=None, redoc_url=None, openapi_url=None)
    static = resources.files("dtd.explain.explore") / "static"
    episode_gate = Gate(episode_worker, "episode", WAITING_EPISODES)
    map_gate = Gate(map_worker, "value map", WAITING_MAPS)
    app.state.gates = {"episode": episode_gate, "map": map_gate}

    app.add_middleware(OnlyThisServer, hosts=hosts)

    @app.exception_handler(ExploreError)
    async def explore_error(_: Request, exc: ExploreError) -> JSONResponse:
        return JSONResponse({"error": str(exc)}, status_code=exc.status)

    @app.exception_handler(DtdError)
    async def dtd_error(_: Request, exc: DtdError) -> JSONResponse:
        # A snapshot that cannot be read (e.g. caught half-written by another tool).
        return JSONResponse({"error": str(exc)}, status_code=409)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        return JSONResponse({"error": str(exc.detail)}, status_code=exc.status_code)

    @app.exception_handler(RequestValidationError)
    async def invalid_request(_: Request, exc: RequestValidationError) -> JSONResponse:
        problems = []
        for error in exc.errors():
            if error.get("type") == "json_invalid":
                return JSONResponse({"error": "the request body is not valid JSON"}, status_code=400)
            where = ".".join(str(part) for part in error.get("loc", ()) if part not in ("body", "query"))
            problems.append(f"{where}: {error.get('msg', 'invalid')}" if where else error.get("msg", ""))
        return JSONResponse({"error": "; ".join(problems) or "invalid request"}, status_code=422)

    @app.get("/", response_class=HTMLResponse)
    async def page() -> HTMLResponse:
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"))

    @app.get("/static/{name}")
    async def page_file(name: str) -> Response:
        if name not in PAGE_FILES:
            return JSONResponse({"error": f"no page file named {name!r}"}, status_code=404)
        return Response((static / name).read_bytes(), media_type=PAGE_FILES[name])

    @app.get("/videos/{name}")
    async def video(name: str) -> Response:
        path = episodes.videos / name
        if not VIDEO_NAME.fullmatch(name) or not path.is_file():
            return JSONResponse({"error": f"no video named {name!r}"}, status_code=404)
        return FileResponse(path, media_type="video/mp4")

    @app.get("/api/run")
    async def run() -> dict[str, Any]:
        # Files and fixed facts only: on a thread of its own, never behind an episode.
        return await asyncio.to_thread(maps.describe)

    @app.get("/api/map")
    async def value_map(
        request: Request,
        epoch: int,
        block_x: float,
        block_y: float,
        goal_x: float,
        goal_y: float,
        goal_z: float | None = None,
        z: float | None = None,
        resolution: int = MAP_RESOLUTION,
    ) -> dict[str, Any]:
        block, goal = (block_x, block_y), (goal_x, goal_y, goal_z)
        return await map_gate.run(request, lambda: maps.value_map(epoch, block, goal, z, resolution))

    @app.post("/api/episode")
    async def episode(request: Request, asked: EpisodeRequest) -> dict[str, Any]:
        block = (float(asked.block[0]), float(asked.block[1])) if asked.block is not None else None
        goal = [float(value) for value in asked.goal] if asked.goal is not None else None
        placed_goal = (goal[0], goal[1], goal[2] if len(goal) > 2 else None) if goal is not None else None
        return await episode_gate.run(request, lambda: episodes.play(asked.epoch, block, placed_goal))

    return app


class OnlyThisServer:
    """ASGI middleware that answers a request not meant for this server (:func:`foreign_request`)
    itself. Plain ASGI, not Starlette's BaseHTTPMiddleware: under that, an endpoint cannot tell
    that its client has gone."""

    def __init__(self, app: Any, hosts: frozenset[str]) -> None:
        self.app = app
        self.hosts = hosts

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] == "http":
            refusal = foreign_request(scope["path"], Headers(scope=scope), self.hosts)
            if refusal is not None:
                status, reason = refusal
                await JSONResponse({"error": reason}, status_code=status)(scope, receive, send)
                return
        await self.app(scope, receive, send)


def foreign_request(path: str, headers: Any, hosts: frozenset[str]) -> tuple[int, str] | None:
    """(status, reason) where a request for ``path`` with these headers is not one for this
    server: its Host is not one of ``hosts`` (400), or a browser says a call of the API or a
    video comes from another origin (403); None where it is. The page itself may be opened from
    a link anywhere."""
    host = headers.get("host", "")
    try:
        name = urlsplit(f"//{host}").hostname if host else None
    except ValueError:
        name = None
    if name is None or name.lower() not in hosts:
        return 400, f"Host {host!r} is not this server; open the page at the address dtd explore printed"
    if not path.startswith(("/api/", "/videos/")):
        return None
    origin = headers.get("origin")
    if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
        return 403, f"requests from {origin} are refused: only the explorer's own page may use it"
    if headers.get("sec-fetch-site") not in (None, "same-origin", "none"):
        return 403, "requests from other sites are refused: only the explorer's own page may use it"
    return None


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (127.0.0.0/8, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on ``host``:``port`` (0: any free port), or a :class:`DtdError`."""
    try:
        info = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except (OSError, UnicodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise DtdError(f"cannot listen on {host}: not an address or a known name ({reason})") from exc
    try:
        sock = socket.socket(info[0], socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(info[4])
        sock.listen(128)
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            reason = "it is in use; give another --port (0 picks a free one)"
        elif exc.errno == errno.EADDRNOTAVAIL:
            reason = f"{host} is not an address of this machine"
        elif exc.errno == errno.EACCES:
            reason = "permission denied (ports below 1024 need privileges); give another --port"
        else:
            reason = exc.strerror or str(exc)
        raise DtdError(f"cannot listen on {host}:{port}: {reason}") from exc
    sock.set_inheritable(True)
    return sock


def url_of(sock: socket.socket) -> str:
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/"


class AnnouncingServer(uvicorn.Server):
    """A uvicorn server that says it is ready once it serves: by then it has taken over SIGINT
    and SIGTERM, so a stop at any moment after the announcement shuts it down cleanly."""

    def __init__(self, config: uvicorn.Config, announce: Callable[[], None]) -> None:
        super().__init__(config)
        self.announce = announce

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=sockets)
        if self.started:
            self.announce()


def serve(run_dir: Path, host: str, port: int, videos: Path, ready: Callable[[str], None]) -> None:
    """Serve the explorer of ``run_dir`` until interrupted (Ctrl-C stops it cleanly);
    ``ready`` is told the page's URL once the server listens."""
    sock = bind(host, port)
    episode_worker = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="episodes")
    map_worker = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="maps")
    starting = [worker.submit(Explorer, run_dir, videos) for worker in (episode_worker, map_worker)]
    concurrent.futures.wait(starting)
    explorers = [started.result() for started in starting if started.exception() is None]
    try:
        if len(explorers) < len(starting):  # one could not start: the others are closed below
            raise next(started.exception() for started in starting if started.exception() is not None)
        app = create_app(*explorers, episode_worker, map_worker, allowed_hosts(host))
        config = uvicorn.Config(app, log_level="warning", access_log=False)
        AnnouncingServer(config, lambda: ready(url_of(sock))).run(sockets=[sock])
    finally:
        for worker, started in zip((episode_worker, map_worker), starting, strict=True):
            if started.exception() is None:
                worker.submit(started.result().close).result()
        for worker in (episode_worker, map_worker):
            worker.shutdown(cancel_futures=True)
        sock.close()
