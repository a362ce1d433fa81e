"""The web side of ``dtd explore``: a FastAPI app over one :class:`Explorer`, served by uvicorn.

Every call that touches the simulator, the agent or the renderer runs on one worker thread
(:class:`Explorer` is not thread-safe and an EGL context belongs to the thread that made it);
the event loop only waits for it, so many requests at once are answered one after another.
Files are served from two fixed places only: the page's own files, named in ``PAGE_FILES``,
and the videos the explorer wrote, by a name of the form ``episode-N.mp4``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import ipaddress
import re
import socket
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

import uvicorn
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from pydantic import BaseModel, Field
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

    epoch: int
    block: list[float] | None = Field(default=None, min_length=2, max_length=2)
    goal: list[float] | None = Field(default=None, min_length=2, max_length=3)


def create_app(explorer: Explorer, worker: concurrent.futures.Executor) -> FastAPI:
    """The app: the page, its files, the videos, and the API under /api."""
    app = FastAPI(title="dtd explore", docs_url=None, redoc_url=None, openapi_url=None)
    static = resources.files("dtd.explain.explore") / "static"

    async def on_worker(call: Callable[[], Result]) -> Result:
        return await asyncio.wrap_future(worker.submit(call))

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
        path = explorer.videos / name
        if not VIDEO_NAME.fullmatch(name) or not path.is_file():
            return JSONResponse({"error": f"no video named {name!r}"}, status_code=404)
        return FileResponse(path, media_type="video/mp4")

    @app.get("/api/run")
    async def run() -> dict[str, Any]:
        return await on_worker(explorer.describe)

    @app.get("/api/map")
    async def value_map(
        epoch: int,
        block_x: float,
        block_y: float,
        goal_x: float,
        goal_y: float,
        goal_z: float | None = None,
        z: float | None = None,
        resolution: int = MAP_RESOLUTION,
    ) -> dict[str, Any]:
        return await on_worker(
            lambda: explorer.value_map(epoch, (block_x, block_y), (goal_x, goal_y, goal_z), z, resolution)
        )

    @app.post("/api/episode")
    async def episode(asked: EpisodeRequest) -> dict[str, Any]:
        block = tuple(asked.block) if asked.block is not None else None
        goal = asked.goal
        placed_goal = (goal[0], goal[1], goal[2] if len(goal) > 2 else None) if goal is not None else None
        return await on_worker(lambda: explorer.play(asked.epoch, block, placed_goal))

    return app


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
        sock = socket.socket(info[0], socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(info[4])
        sock.listen(128)
    except OSError as exc:
        reason = "it is in use; give another --port (0 picks a free one)" if port else str(exc)
        raise DtdError(f"cannot listen on {host}:{port}: {reason}") from exc
    sock.set_inheritable(True)
    return sock


def url_of(sock: socket.socket) -> str:
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/"


def serve(run_dir: Path, host: str, port: int, videos: Path, ready: Callable[[str], None]) -> None:
    """Serve the explorer of ``run_dir`` until interrupted (Ctrl-C stops it cleanly);
    ``ready`` is told the page's URL once the server listens."""
    sock = bind(host, port)
    worker = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="explorer")
    explorer = worker.submit(Explorer, run_dir, videos).result()
    try:
        app = create_app(explorer, worker)
        server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False))
        ready(url_of(sock))
        server.run(sockets=[sock])
    finally:
        worker.submit(explorer.close).result()
        worker.shutdown()
        sock.close()
