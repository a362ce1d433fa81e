"""How ``dtd explore`` holds up under load: N clients at once ask for an episode and give up
after a few seconds, while a plain ``GET /api/run`` is timed again and again.

Prints how the episode requests were answered (by status), how many episodes were played (those
beyond the answered ones were played for clients that had gone) and the median and p95 of
``/api/run`` meanwhile.

    python benchmarks/explore_load.py RUN_DIR [--episodes 30] [--give-up-s 5]
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import json
import re
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--episodes", type=int, default=30, help="episode requests sent at once")
    parser.add_argument("--give-up-s", type=float, default=5.0, help="each episode client's timeout")
    parser.add_argument("--settle-s", type=float, default=20.0, help="time /api/run for this long")
    args = parser.parse_args()

    server = subprocess.Popen(
        [sys.executable, "-m", "dtd", "explore", str(args.run_dir), "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert server.stdout is not None
        url = re.search(r"http://\S+/", server.stdout.readline()).group(0)
        epoch = json.loads(urllib.request.urlopen(url + "api/run", timeout=60).read())["epochs"][-1]
        body = json.dumps({"epoch": epoch}).encode()

        def episode(_: int) -> str:
            request = urllib.request.Request(
                url + "api/episode", data=body, headers={"Content-Type": "application/json"}, method="POST"
            )
            try:
                with urllib.request.urlopen(request, timeout=args.give_up_s) as response:
                    return str(response.status)
            except urllib.error.HTTPError as error:
                return str(error.code)
            except (TimeoutError, urllib.error.URLError):
                return "gave up"

        run_times: list[float] = []
        stop = threading.Event()

        def time_run() -> None:
            while not stop.is_set():
                began = time.perf_counter()
                urllib.request.urlopen(url + "api/run", timeout=300).read()
                run_times.append(time.perf_counter() - began)
                time.sleep(0.1)

        timer = threading.Thread(target=time_run)
        timer.start()
        with concurrent.futures.ThreadPoolExecutor(args.episodes) as pool:
            answers = collections.Counter(pool.map(episode, range(args.episodes)))
        time.sleep(args.settle_s)
        stop.set()
        timer.join()
        # Videos are numbered as they are made: the next one tells how many episodes were played.
        request = urllib.request.Request(
            url + "api/episode", data=body, headers={"Content-Type": "application/json"}, method="POST"
        )
        video = json.loads(urllib.request.urlopen(request, timeout=300).read())["video"]
        played = int(re.search(r"[0-9]+", video).group(0)) - 1
        times_ms = np.asarray(run_times) * 1000
        print(f"{args.episodes} episode requests at once, clients giving up after {args.give_up_s:.0f} s:")
        print("  answers: " + ", ".join(f"{name} {count}" for name, count in sorted(answers.items())))
        print(f"  episodes played: {played} (answered 200: {answers.get('200', 0)})")
        print(
            f"  GET /api/run meanwhile ({len(times_ms)} requests over the next {args.settle_s:.0f} s too): "
            f"median {np.median(times_ms):.1f} ms, p95 {np.percentile(times_ms, 95):.1f} ms, "
            f"max {times_ms.max():.1f} ms"
        )
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
