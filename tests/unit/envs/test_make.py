"""Making environments from several threads at once (as ``dtd explore``'s workers do)."""

from __future__ import annotations

import sys
import threading

from dtd.envs.make import make_env


def test_threads_making_environments_at_once_leave_stderr_as_it_was():
    before = sys.stderr
    start = threading.Barrier(4)
    made = []

    def make() -> None:
        start.wait()
        for _ in range(3):
            env = make_env("FetchReach-v4")
            made.append(env)
            env.close()

    threads = [threading.Thread(target=make) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(made) == 12
    assert sys.stderr is before
