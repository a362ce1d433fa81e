"""Starting the data-parallel workers of one run on this machine (``dtd train --workers N``),
as torchrun would: one ``dtd train`` process per worker, the rendezvous in their environment,
and the job stopped as a whole when one of them fails. Light enough for the command line to
import before torch."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence

LOCAL_LAUNCH = "DTD_LOCAL_WORKERS"
"""Set in the environment of workers ``dtd train --workers N`` started on this machine: their
launcher reports a lost worker or an interruption, so they stay quiet about it."""

LOST_WORKER_EXIT = 75
"""Exit status of a locally launched worker that lost contact with the others (EX_TEMPFAIL)."""

INTERRUPTED_EXIT = 130


def launched_workers() -> int | None:
    """The number of workers of the job this process belongs to (torchrun's or dtd's own
    launch: ``WORLD_SIZE`` is set), else None."""
    value = os.environ.get("WORLD_SIZE", "").strip()
    return int(value) if value.isdigit() else None


def local_workers() -> int:
    """Workers of this job on this machine (1 outside a job)."""
    value = os.environ.get("LOCAL_WORLD_SIZE", "").strip()
    return int(value) if value.isdigit() and int(value) > 0 else 1


def is_worker_zero() -> bool:
    """Whether this process is a run of its own or worker 0 of a job (the one that reports)."""
    return os.environ.get("RANK", "0").strip() in ("", "0")


def reports_for_itself() -> bool:
    """Whether this process reports an interruption or a lost worker itself: a run of its own,
    or worker 0 of a torchrun job; locally launched workers leave it to their launcher."""
    return LOCAL_LAUNCH not in os.environ and is_worker_zero()


@dataclasses.dataclass(frozen=True)
class WorkerEnd:
    """How one worker process ended."""

    rank: int
    pid: int
    returncode: int

    def describe(self) -> str:
        if self.returncode < 0:
            try:
                name = signal.Signals(-self.returncode).name
            except ValueError:
                name = f"signal {-self.returncode}"
            return f"worker {self.rank} (pid {self.pid}) was killed by {name}"
        return f"worker {self.rank} (pid {self.pid}) exited with status {self.returncode}"


def job_environment(workers: int, port: int, threads: int) -> dict[str, str]:
    """What torchrun's agent sets for every worker of a one-machine job of ``workers``, less the
    worker's rank: the group's size, its rendezvous store on ``port`` (held by the launcher),
    and ``threads`` torch threads each."""
    return {
        "WORLD_SIZE": str(workers),
        "LOCAL_WORLD_SIZE": str(workers),
        "MASTER_ADDR": "127.0.0.1",
        "MASTER_PORT": str(port),
        "TORCHELASTIC_USE_AGENT_STORE": "True",
        "OMP_NUM_THREADS": str(threads),
    }


def launch_local(args: Sequence[str], workers: int, threads: int, poll_s: float = 0.2) -> list[WorkerEnd]:
    """Run ``dtd`` with ``args`` as ``workers`` processes on this machine, each a worker of one
    job with ``threads`` torch threads; return how they ended. When one ends badly the others
    are stopped (SIGTERM, then SIGKILL after 10 s); the first to fail comes first.

    The launcher holds the job's rendezvous store, as torchrun's agent does, on a port the
    system chose when it was bound: jobs started side by side cannot meet on one port."""
    store = _rendezvous_store()
    env = {**os.environ, **job_environment(workers, store.port, threads), LOCAL_LAUNCH: "1"}
    processes = [
        subprocess.Popen(
            [sys.executable, "-m", "dtd", *args],
            env={**env, "RANK": str(rank), "LOCAL_RANK": str(rank)},
        )
        for rank in range(workers)
    ]
    ends: list[WorkerEnd] = []
    try:
        while len(ends) < workers:
            for rank, process in enumerate(processes):
                if process.returncode is None and process.poll() is not None:
                    ends.append(WorkerEnd(rank, process.pid, process.returncode))
            if any(end.returncode != 0 for end in ends):
                break
            time.sleep(poll_s)
    finally:
        _stop(processes)
    for rank, process in enumerate(processes):
        if all(end.rank != rank for end in ends):
            ends.append(WorkerEnd(rank, process.pid, process.returncode))
    return _first_failure_first(ends)


def _rendezvous_store():
    """A rendezvous store on a loopback port of the system's choosing, for workers to join."""
    import torch.distributed as dist

    return dist.TCPStore("127.0.0.1", 0, is_master=True, wait_for_workers=False)


def _stop(processes: Sequence[subprocess.Popen], grace_s: float = 10.0) -> None:
    running = [process for process in processes if process.poll() is None]
    for process in running:
        process.terminate()
    deadline = time.monotonic() + grace_s
    for process in running:
        try:
            process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _first_failure_first(ends: list[WorkerEnd]) -> list[WorkerEnd]:
    """A worker killed by a signal, then one that failed on its own, then one that lost the
    others or was stopped, then the rest, each group in the order they ended."""

    def kind(end: WorkerEnd) -> int:
        if end.returncode < 0 and end.returncode != -signal.SIGTERM:
            return 0
        if end.returncode not in (0, LOST_WORKER_EXIT, -signal.SIGTERM, INTERRUPTED_EXIT):
            return 1
        return 2 if end.returncode != 0 else 3

    return sorted(ends, key=kind)
