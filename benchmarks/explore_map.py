"""How fast ``dtd explore`` answers a value map: a ``dtd explore`` server on a run, asked for
maps as a page asks while the block is dragged (a new block position each time, one request
after another), and then 20 at once.

Prints, per resolution, the round trip of ``GET /api/map`` (median, 95th percentile, worst)
and the time the server spent on it (placing the block, reading the observation back, one
critic pass over every cell and the actor's choice).

    python benchmarks/explore_map.py runs/push-dtd-0
    python benchmarks/explore_map.py runs/push-dtd-0 --resolutions 50 100 --requests 100
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np


def ask(url: str) -> tuple[float, dict]:
    """Round trip in ms and the answer (a refusal's body, {"error": ...}, for a busy server)."""
    began = time.perf_counter()
    try:
        with urllib.request.urlopen(url, timeout=120) as response:
            answer = json.loads(response.read())
    except urllib.error.HTTPError as refused:
        answer = {"status": refused.code, **json.loads(refused.read() or b"{}")}
    return (time.perf_counter() - began) * 1000, answer


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run_dir", type=Path, help="a dtd run on FetchPush or FetchPickAndPlace")
    parser.add_argument("--resolutions", type=int, nargs="+", default=[50])
    parser.add_argument("--requests", type=int, default=60, help="maps asked one after another")
    parser.add_argument("--threads", type=int, default=1, help="torch threads of the server")
    args = parser.parse_args()

    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dtd",
            "explore",
            str(args.run_dir),
            "--port",
            "0",
            "--threads",
            str(args.threads),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    try:
        assert server.stdout is not None
        found = re.search(r"http://\S+/", server.stdout.readline())
        if not found:
            raise SystemExit("dtd explore did not start")
        base = found.group(0)
        with urllib.request.urlopen(base + "api/run") as response:
            run = json.loads(response.read())
        if not run["map"]:
            raise SystemExit(f"no value map for this run: {run['no_map_reason']}")
        epoch, table = run["epochs"][-1], run["table"]
        facts = f"torch threads {args.threads}; {os.cpu_count()} cores"
        print(f"{run['algo']} on {run['env']}, epoch {epoch}; {facts}")
        rng = np.random.default_rng(0)
        for resolution in args.resolutions:

            def url(rng: np.random.Generator = rng, resolution: int = resolution) -> str:
                x = rng.uniform(*table["x"])
                y = rng.uniform(*table["y"])
                return (
                    f"{base}api/map?epoch={epoch}&block_x={x}&block_y={y}&goal_x=1.45&goal_y=0.95"
                    f"&resolution={resolution}"
                )

            ask(url())  # the first request loads the epoch's weights
            trips, computed = [], []
            for _ in range(args.requests):
                elapsed, answer = ask(url())
                trips.append(elapsed)
                computed.append(answer["compute_ms"])
            trips_ms, computed_ms = np.array(trips), np.array(computed)
            print(
                f"{resolution}x{resolution}: round trip median {np.median(trips_ms):.0f} ms, "
                f"95th percentile {np.percentile(trips_ms, 95):.0f} ms, worst {trips_ms.max():.0f} ms; "
                f"server {np.median(computed_ms):.0f} ms median ({args.requests} requests)"
            )
            urls = [url() for _ in range(20)]
            began = time.perf_counter()
            with concurrent.futures.ThreadPoolExecutor(max_workers=20) as pool:
                together = list(pool.map(ask, urls))
            busy = sum("error" in answer for _, answer in together)
            print(
                f"  20 at once: all answered in {(time.perf_counter() - began) * 1000:.0f} ms, "
                f"{busy} of them 503 busy (the server draws one map at a time and lets a few wait; "
                f"slowest round trip {max(t for t, _ in together):.0f} ms)"
            )
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
