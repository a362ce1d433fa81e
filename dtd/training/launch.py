"""A process's place among the data-parallel workers of one run, read from its environment once
(:class:`JobPlace`), and starting the workers of a run on this machine (``dtd train --workers
N``) with torch.distributed's own launcher, the local agent torchrun runs: one ``dtd train``
process per worker, the rendezvous theirs, the job stopped as a whole when one of them fails or
the launcher is interrupted. Light enough for the command line to import before torch."""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import signal
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence

LOCAL_LAUNCH = "DTD_LOCAL_WORKERS"
"""Set in the environment of workers ``dtd train --workers N`` started on this machine, to the
process id of their launcher: it reports a lost worker or an interruption, so they stay quiet
about it, and they stop when it ends (:func:`watch_launcher`)."""

LOST_WORKER_EXIT = 75
"""Exit status of a locally launched worker that lost contact with the others (EX_TEMPFAIL)."""

INTERRUPTED_EXIT = 130


@dataclasses.dataclass(frozen=True)
class JobPlace:
    """Where this process stands: a run of its own, or worker ``rank`` of a job of ``workers``
    (started by torchrun or by ``dtd train --workers N``, which name them in the environment)."""

    workers: int | None = None
    """The job's size (``WORLD_SIZE``); None outside a job."""
    rank: int = 0
    local_workers: int = 1
    """Workers of the job on this machine (``LOCAL_WORLD_SIZE``), who share its cores."""
    launched_here: bool = False
    """Started by ``dtd train --workers N`` on this machine, whose launcher reports for it."""
    launcher: int | None = None
    """The process id of that launcher (:func:`watch_launcher`)."""

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] = os.environ) -> JobPlace:
        def number(name: str) -> int | None:
            value = environ.get(name, "").strip()
            return int(value) if value.isdigit() else None

        return cls(
            workers=number("WORLD_SIZE"),
            rank=number("RANK") or 0,
            local_workers=max(number("LOCAL_WORLD_SIZE") or 1, 1),
            launched_here=LOCAL_LAUNCH in environ,
            launcher=number(LOCAL_LAUNCH),
        )

    def launcher_gone(self) -> bool:
        """Whether this worker's launcher has ended (it is no longer this process's parent)."""
        return self.launched_here and self.launcher is not None and os.getppid() != self.launcher

    @property
    def in_job(self) -> bool:
        return self.workers is not None

    @property
    def reports(self) -> bool:
        """Whether this process reports the job's end (a run of its own, or worker 0)."""
        return self.rank == 0

    @property
    def reports_for_itself(self) -> bool:
        """Whether it reports an interruption or a lost worker itself: a run of its own, or
        worker 0 of a torchrun job; workers launched here leave it to their launcher."""
        return self.reports and not self.launched_here


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


def launch_local(args: Sequence[str], workers: int, threads: int, poll_s: float = 0.2) -> list[WorkerEnd]:
    """Run ``dtd`` with ``args`` as ``workers`` processes on this machine, each a worker of one
    job with ``threads`` torch threads, under torch.distributed's local elastic agent (no
    restarts); return how they ended, the first to fail first (all 0 when the job succeeded).
    When one ends badly the agent stops the others. An interrupt of the launcher (SIGINT or
    SIGTERM) stops them too and is raised here as :class:`KeyboardInterrupt`."""
    from torch.distributed.elastic.multiprocessing.api import SignalException
    from torch.distributed.elastic.multiprocessing.errors import ChildFailedError
    from torch.distributed.launcher.api import LaunchConfig, elastic_launch

    _quiet_agent()
    config = LaunchConfig(
        min_nodes=1,
        max_nodes=1,
        nproc_per_node=workers,
        run_id=uuid.uuid4().hex,
        rdzv_backend="c10d",
        rdzv_endpoint="127.0.0.1:0",  # a port of the system's choosing: jobs side by side never meet
        max_restarts=0,
        monitor_interval=poll_s,
    )
    try:
        with _worker_environment({LOCAL_LAUNCH: str(os.getpid()), "OMP_NUM_THREADS": str(threads)}):
            elastic_launch(config, sys.executable)("-m", "dtd", *args)
    except ChildFailedError as failed:
        by_time = sorted(failed.failures.items(), key=lambda item: item[1].timestamp)
        ends = [WorkerEnd(rank, failure.pid, failure.exitcode) for rank, failure in by_time]
        return _first_failure_first(ends)
    except SignalException as stop:
        raise KeyboardInterrupt(f"the launcher got {stop.sigval.name}") from None
    return [WorkerEnd(rank, 0, 0) for rank in range(workers)]


def on_parent_gone(parent: int, act: Callable[[], None], poll_s: float = 0.5) -> None:
    """Call ``act``, in a daemon thread, once this process's parent is no longer ``parent``
    (it ended, however: ``kill -9`` too, and this process was handed to another)."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        act()

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def watch_launcher(launcher: int, poll_s: float = 0.5, grace_s: float = 60.0) -> None:
    """Stop this worker when its launcher ``launcher`` (its parent) ends, however it ended
    (``kill -9`` too): the worker is sent SIGTERM, which stops it as Ctrl-C does, after its last
    finished epoch; one that has not ended ``grace_s`` seconds later exits at once."""

    def stop() -> None:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(grace_s)
        os._exit(INTERRUPTED_EXIT)

    on_parent_gone(launcher, stop, poll_s)


def _quiet_agent() -> None:
    """The agent logs each step and failure; the command reports the job's end in one line."""
    for name in list(logging.root.manager.loggerDict):
        if name.startswith("torch.distributed.elastic") or name.startswith("torch.distributed.launcher"):
            logging.getLogger(name).setLevel(logging.CRITICAL)


@contextlib.contextmanager
def _worker_environment(values: Mapping[str, str]) -> Iterator[None]:
    """This process's environment, which the agent hands its workers, with ``values`` set."""
    before = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _first_failure_first(ends: list[WorkerEnd]) -> list[WorkerEnd]:
    """A worker killed by a signal, then one that failed on its own, then one that lost the
    others or was stopped, then the rest, each group in the order given."""

    def kind(end: WorkerEnd) -> int:
        if end.returncode < 0 and end.returncode != -signal.SIGTERM:
            return 0
        if end.returncode not in (0, LOST_WORKER_EXIT, -signal.SIGTERM, INTERRUPTED_EXIT):
            return 1
        return 2 if end.returncode != 0 else 3

    return sorted(ends, key=kind)
